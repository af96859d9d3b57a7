// Stability region and robust optimum cost (docs/performance.md) in the reference (omega, a) box,
// omega in [0.05, 2], a in [0.01, 8] at b = 0.15, once the curves are traced (the trace runs once,
// before the timings, and is measured by curve_bench). The grid is drillctl optimum's default for
// --margin 0.02: a spacing of half the margin, 196 x 800 nodes. Run:
//   build/bench/region_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
// Counters: inside (grid nodes inside), solves (Newton solves), candidates (nodes the query
// checked).
#include <benchmark/benchmark.h>

#include <string>

#include "drillbif/continuation/trace.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/region/robust_optimum.h"
#include "problems/drifting_reference.h"
#include "problems/reference_box.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

struct Setup {
  DriftingOscillator model;
  PeriodicOrbit start;
  std::vector<RegionCurve> curves;
  RegionOptions options;
};

const Setup& Shared() {
  static const Setup* setup = [] {
    auto* s = new Setup;
    ExactPropagator prop(s->model);
    s->start = *testing::SolvedOrbitFromRest(s->model, prop, testing::ReferenceParams());
    const TraceOptions box = testing::ReferenceBox();
    s->curves = RegionCurvesOf(TraceCurves(s->model, prop, s->start, box).curves);
    s->options.param1 = box.param1, s->options.param2 = box.param2;
    s->options.min1 = box.min1, s->options.max1 = box.max1;
    s->options.min2 = box.min2, s->options.max2 = box.max2;
    s->options.n1 = 196, s->options.n2 = 800;  // spacing 0.01 in both
    return s;
  }();
  return *setup;
}

void BM_StabilityRegionReferenceBox(benchmark::State& state) {
  const Setup& s = Shared();
  ExactPropagator prop(s.model);
  StabilityRegion r;
  for (auto _ : state) {
    r = ComputeStabilityRegion(s.model, prop, s.start, s.curves, s.options);
    benchmark::DoNotOptimize(r.grid.label.data());
  }
  state.counters["inside"] = r.summary.inside_nodes;
  state.counters["solves"] = r.summary.solves;
  if (!r.summary.completed()) state.SkipWithError(r.summary.BriefReport().c_str());
}
BENCHMARK(BM_StabilityRegionReferenceBox)->Unit(benchmark::kMillisecond);

// The query alone: drillctl optimum --margin 0.02 (per parameter) once curves and region exist.
void BM_RobustOptimumQuery(benchmark::State& state) {
  const Setup& s = Shared();
  ExactPropagator prop(s.model);
  const StabilityRegion r = ComputeStabilityRegion(s.model, prop, s.start, s.curves, s.options);
  OptimumOptions o;
  o.margin = {0.02};
  RobustOptimum best;
  for (auto _ : state) {
    best = FindRobustOptimum(r, o);
    benchmark::DoNotOptimize(best.rop);
  }
  state.counters["candidates"] = static_cast<double>(best.summary.candidates);
  if (!best.summary.completed()) state.SkipWithError(best.summary.BriefReport().c_str());
}
BENCHMARK(BM_RobustOptimumQuery)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
