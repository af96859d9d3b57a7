// Cancellation of the stability region (its fill and the location of its boundary) and of the
// robust optimum's search: a stop is honoured within the bound (support/cancel_probe.h); the
// result says CANCELLED and keeps only what was computed before the stop.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <string>

#include "drillbif/flow/exact_propagator.h"
#include "drillbif/region/robust_optimum.h"
#include "drillbif/region/stability_region.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"
#include "support/cancel_probe.h"

namespace drillbif {
namespace {

using std::chrono::milliseconds;
using testing::CancelProbe;

constexpr milliseconds kDelay(200);  // as in simulation_cancel_test.cc

// The box of stability_region_test.cc around the reference orbit, without traced curves (every
// boundary crossing is then bisected).
RegionOptions Box(int n1, int n2) {
  RegionOptions o;
  o.param1 = std::string("omega");
  o.param2 = std::string("a");
  o.min1 = 0.05, o.max1 = 0.15;
  o.min2 = 0.25, o.max2 = 0.6;
  o.n1 = n1, o.n2 = n2;
  return o;
}

PeriodicOrbit Start(const DriftingOscillator& model, Propagator& prop) {
  const StatusOr<PeriodicOrbit> orbit =
      testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  EXPECT_TRUE(orbit.ok()) << orbit.status().ToString();
  return orbit.ok() ? *orbit : PeriodicOrbit{};
}

// 801 x 801 nodes (~10^5 solves inside: tens of seconds), stopped during the fill.
TEST(RegionCancel, FillStopsPromptly) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const PeriodicOrbit start = Start(model, prop);
  CancelProbe probe(kDelay);
  const StabilityRegion r =
      ComputeStabilityRegion(model, prop, start, {}, Box(801, 801), probe.Callback());
  probe.Returned();
  EXPECT_EQ(r.summary.termination, Termination::kCancelled) << r.summary.BriefReport();
  EXPECT_EQ(r.summary.status.code(), StatusCode::kCancelled);
  EXPECT_GT(r.summary.solves, 0);
  EXPECT_GT(r.summary.inside_nodes, 0);
  EXPECT_LT(r.summary.inside_nodes, 801 * 801);
  EXPECT_TRUE(r.polygons.empty());
  for (size_t k = 0; k < r.grid.rop.size(); ++k) ASSERT_TRUE(std::isfinite(r.grid.rop[k])) << k;
  probe.ExpectPrompt("stability region: fill");
}

// Stopped while the boundary is located: the fill reports fractions below kRegionFillShare, the
// boundary's bisections (50 per edge here, no traced curves) kRegionFillShare itself, so the first
// call at that fraction comes from there (a fraction repeated by the fill's throttle, when one
// node takes longer than the throttle's interval on a loaded machine, does not).
TEST(RegionCancel, BoundaryLocationStopsPromptly) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const PeriodicOrbit start = Start(model, prop);
  RegionOptions o = Box(41, 41);
  o.bisections = 50;
  CancelProbe probe([&](double fraction) { return fraction >= kRegionFillShare; });
  const StabilityRegion r = ComputeStabilityRegion(model, prop, start, {}, o, probe.Callback());
  probe.Returned();
  EXPECT_EQ(r.summary.termination, Termination::kCancelled) << r.summary.BriefReport();
  EXPECT_TRUE(r.polygons.empty());
  EXPECT_GT(r.summary.boundary_edges, 0);  // it was locating the boundary
  probe.ExpectPrompt("stability region: boundary");
}

// A region of 2001 x 2001 nodes all inside, and a boundary of 40000 short edges winding across
// the box in five rows 0.2 apart, with a margin (0.2 of the box) no node has: the search checks
// every node against the ~6000 edges near it (~10^10 distances) before it would measure every
// node's largest margin.
StabilityRegion Synthetic() {
  StabilityRegion r;
  r.param1 = std::string("omega");  // not = "omega": GCC 12 -Wrestrict false positive
  r.param2 = std::string("a");
  r.min1 = 0.0, r.max1 = 1.0, r.min2 = 0.0, r.max2 = 1.0;
  RegionGrid& g = r.grid;
  g.n1 = g.n2 = 2001;
  for (int i = 0; i < g.n1; ++i) g.values1.push_back(i / 2000.0);
  for (int j = 0; j < g.n2; ++j) g.values2.push_back(j / 2000.0);
  g.label.assign(static_cast<size_t>(g.n1) * g.n2, 0);
  g.rop.assign(g.label.size(), 0.0);
  for (size_t k = 0; k < g.rop.size(); ++k) g.rop[k] = static_cast<double>(k % 997);
  RegionPolygon ring;
  constexpr int kRows = 5, kPerRow = 8000;
  for (int row = 0; row < kRows; ++row) {
    for (int k = 0; k <= kPerRow; ++k) {
      const double f = static_cast<double>(k) / kPerRow;
      const double u = 0.05 + 0.9 * (row % 2 == 0 ? f : 1.0 - f);
      ring.vertices.push_back({u, 0.1 + 0.2 * row + 1e-4 * (k % 2), 0});
    }
  }
  r.polygons.push_back(ring);
  r.summary.Complete();
  return r;
}

// Stopped at its first report of a candidate checked (not after a delay: on a loaded machine the
// setup, building the heap of 4e6 nodes and the obstacles' index, outlasted kDelay and the stop
// came before the search).
TEST(OptimumCancel, SearchStopsPromptly) {
  const StabilityRegion region = Synthetic();
  OptimumOptions o;
  o.scaled = true;
  o.margin = {0.2};
  CancelProbe probe([](double fraction) { return fraction > 0.0; });
  const RobustOptimum best = FindRobustOptimum(region, o, probe.Callback());
  probe.Returned();
  EXPECT_EQ(best.summary.termination, Termination::kCancelled) << best.summary.BriefReport();
  EXPECT_EQ(best.summary.status.code(), StatusCode::kCancelled);
  EXPECT_GT(best.summary.candidates, 0);  // it was searching
  EXPECT_EQ(best.node, -1);
  probe.ExpectPrompt("robust optimum search");
}

}  // namespace
}  // namespace drillbif
