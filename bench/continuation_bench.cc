// One-parameter continuation cost: the b-continuation of the reference period-1 orbit (MODEL.md)
// from the start orbit down to b = 0 and up to the fold, with every special point on the way
// located (docs/performance.md), and its parts. Run (medians of 5):
//   build/bench/continuation_bench --benchmark_repetitions=5
//   --benchmark_report_aggregates_only=true
// Counters: points (accepted points), specials (located special points), and for the start
// orbit the Newton iterations of its solve.
#include <benchmark/benchmark.h>

#include "drillbif/continuation/continuation.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

PeriodicOrbit FindStartOrbit(const DriftingOscillator& model, Propagator& prop) {
  return *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
}

ContinuationOptions ToZeroAndFold() {
  ContinuationOptions o;
  o.param = std::string("b");  // not = "b": GCC 12 warns falsely (-Wrestrict, GCC bug 105329)
  o.min = 0.0;
  o.max = 0.2;
  o.stop_at = {SpecialPointKind::kFold};
  return o;
}

// The start orbit: 500 transient periods from rest, the signature read off one more period, and
// the Newton solve of its boundary-value problem.
void BM_StartOrbit(benchmark::State& state) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  for (auto _ : state) benchmark::DoNotOptimize(FindStartOrbit(model, prop).durations.data());
}
BENCHMARK(BM_StartOrbit)->Unit(benchmark::kMillisecond);

// Start orbit plus both directions: down to b = 0 (through PD and the l1 grazing), up to the fold
// (through the ROP maximum).
void BM_BContinuationToZeroAndFold(benchmark::State& state) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  ContinuationResult r;
  for (auto _ : state) {
    r = Continue(model, prop, FindStartOrbit(model, prop), ToZeroAndFold());
    benchmark::DoNotOptimize(r.points.data());
  }
  state.counters["points"] = static_cast<double>(r.points.size());
  state.counters["specials"] = static_cast<double>(r.special_points.size());
  if (r.summary.termination != Termination::kCompleted) state.SkipWithError("not completed");
}
BENCHMARK(BM_BContinuationToZeroAndFold)->Unit(benchmark::kMillisecond);

// Both directions over the whole range [0, 0.2], through the fold onto the unstable branch.
void BM_BContinuationWholeRange(benchmark::State& state) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const PeriodicOrbit start = FindStartOrbit(model, prop);
  ContinuationOptions o = ToZeroAndFold();
  o.stop_at.clear();
  ContinuationResult r;
  for (auto _ : state) {
    r = Continue(model, prop, start, o);
    benchmark::DoNotOptimize(r.points.data());
  }
  state.counters["points"] = static_cast<double>(r.points.size());
  state.counters["specials"] = static_cast<double>(r.special_points.size());
}
BENCHMARK(BM_BContinuationWholeRange)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
