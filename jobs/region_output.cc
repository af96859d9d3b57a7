#include "jobs/region_output.h"

#include "drillbif/orbit/signature.h"

namespace drillbif::jobs {

void ToProto(const HybridModel& model, const StabilityRegion& region, v1::StabilityRegion* out) {
  out->add_params(region.param1);
  out->add_params(region.param2);
  out->add_min(region.min1);
  out->add_min(region.min2);
  out->add_max(region.max1);
  out->add_max(region.max2);
  for (const Signature& s : region.signatures) out->add_signatures(SignatureString(model, s));
  const RegionGrid& g = region.grid;
  out->mutable_values1()->Add(g.values1.begin(), g.values1.end());
  out->mutable_values2()->Add(g.values2.begin(), g.values2.end());
  out->mutable_label()->Add(g.label.begin(), g.label.end());
  out->mutable_rop()->Add(g.rop.begin(), g.rop.end());
  for (const RegionPolygon& ring : region.polygons) {
    v1::RegionPolygon* p = out->add_polygons();
    p->set_signature(ring.signature);
    for (const RegionVertex& v : ring.vertices) {
      v1::RegionVertex* pv = p->add_vertices();
      pv->set_value1(v.value1);
      pv->set_value2(v.value2);
      pv->set_curve(v.curve);
    }
  }
  out->set_solves(region.summary.solves);
  out->set_boundary_edges(region.summary.boundary_edges);
  out->set_untraced_edges(region.summary.untraced_edges);
  out->set_seam_edges(region.summary.seam_edges);
  out->set_message(region.summary.message);
}

}  // namespace drillbif::jobs
