// The stability region as its proto (proto/drillbif/v1/region.proto).
#ifndef DRILLBIF_JOBS_REGION_OUTPUT_H_
#define DRILLBIF_JOBS_REGION_OUTPUT_H_

#include "drillbif/model/hybrid_model.h"
#include "drillbif/region/stability_region.h"
#include "drillbif/v1/region.pb.h"

namespace drillbif::jobs {

// Grid, signatures (named with `model`'s modes), polygons and counters.
void ToProto(const HybridModel& model, const StabilityRegion& region, v1::StabilityRegion* out);

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_REGION_OUTPUT_H_
