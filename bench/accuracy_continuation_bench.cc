// Accuracy against time, one-parameter continuation (docs/accuracy.md,
// scripts/accuracy.sh): the b-continuation of the reference period-1 orbit (MODEL.md; a = 0.3,
// omega = 0.1) from b = 0.15 down to b = 0 and up to the fold, at several
// ContinuationOptions::locate_tolerance and max_step settings, and at several corrector
// tolerances (the other options at their defaults), against the error of the located fold, period
// doubling and l1 grazing. Reference: the same branch at locate_tolerance 1e-13, default max_step
// and tolerance (MODEL.md's independent values, 8 digits, are reported too). The start orbit is
// solved once, outside the timing. Run:
//   build/bench/accuracy_continuation_bench --benchmark_format=json
// Counters:
//   seconds           wall time of the branch (both directions), s
//   fold_rel_err, pd_rel_err, graze_rel_err   |b - b_ref| / b_ref of each located point
//   max_rel_err       the largest of the three
//   model_abs_err     the largest |b - b_MODEL| from MODEL.md's 8-decimal values (<= 5e-9 when
//                     every digit agrees)
//   points            accepted points on the branch
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include "drillbif/continuation/continuation.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

// MODEL.md's independent values (8 digits).
constexpr double kModelFold = 0.16715050;
constexpr double kModelPd = 0.11001173;
constexpr double kModelGraze = 0.02772417;

// The longest-step settings, argument 1 indexes them: the default (2.0), then shorter (0.5 gives
// the same 330 points as 2.0 on this branch).
constexpr double kMaxSteps[] = {2.0, 0.1, 0.02};

const PeriodicOrbit& Start() {
  static const PeriodicOrbit start = [] {
    DriftingOscillator model;
    ExactPropagator prop(model);
    return *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  }();
  return start;
}

ContinuationOptions Options(double locate_tolerance, double max_step) {
  ContinuationOptions o;
  o.param = std::string("b");  // not = "b": GCC 12 -Wrestrict false positive
  o.min = 0.0;
  o.max = 0.2;
  o.stop_at = {SpecialPointKind::kFold};
  o.locate_tolerance = locate_tolerance;
  o.steps.max_step = max_step;
  return o;
}

struct Located {
  double fold = NAN, pd = NAN, graze = NAN;
};

Located Find(const ContinuationResult& r) {
  Located l;
  for (const SpecialPoint& s : r.special_points) {
    if (s.kind == SpecialPointKind::kFold) l.fold = s.point.value;
    if (s.kind == SpecialPointKind::kPeriodDoubling) l.pd = s.point.value;
    if (s.kind == SpecialPointKind::kGrazingL1) l.graze = s.point.value;
  }
  return l;
}

const Located& Reference() {
  static const Located ref = [] {
    DriftingOscillator model;
    ExactPropagator prop(model);
    return Find(Continue(model, prop, Start(), Options(1e-13, kMaxSteps[0])));
  }();
  return ref;
}

double RelErr(double x, double ref) { return std::abs(x - ref) / std::abs(ref); }

void Measure(benchmark::State& state, Propagator& prop, const ContinuationOptions& o) {
  DriftingOscillator model;
  ContinuationResult r;
  double seconds = 0.0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    r = Continue(model, prop, Start(), o);
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    benchmark::DoNotOptimize(r.points.data());
  }
  const Located l = Find(r);
  const Located& ref = Reference();
  if (r.summary.termination != Termination::kCompleted || std::isnan(l.fold) || std::isnan(l.pd) ||
      std::isnan(l.graze)) {
    state.SkipWithError("branch incomplete or a special point missing");
    return;
  }
  state.counters["seconds"] = seconds / double(state.iterations());
  state.counters["fold_rel_err"] = RelErr(l.fold, ref.fold);
  state.counters["pd_rel_err"] = RelErr(l.pd, ref.pd);
  state.counters["graze_rel_err"] = RelErr(l.graze, ref.graze);
  state.counters["max_rel_err"] =
      std::max({RelErr(l.fold, ref.fold), RelErr(l.pd, ref.pd), RelErr(l.graze, ref.graze)});
  state.counters["model_abs_err"] = std::max(
      {std::abs(l.fold - kModelFold), std::abs(l.pd - kModelPd), std::abs(l.graze - kModelGraze)});
  state.counters["points"] = static_cast<double>(r.points.size());
  state.counters["max_step"] = o.steps.max_step;
}

// Arguments: -log10(locate_tolerance), index into kMaxSteps.
void BM_BBranch(benchmark::State& state) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  Measure(state, prop,
          Options(std::pow(10.0, -static_cast<double>(state.range(0))), kMaxSteps[state.range(1)]));
}
BENCHMARK(BM_BBranch)
    ->ArgsProduct({{1, 2, 3, 4, 6, 8, 10, 12}, {0, 1, 2}})
    ->ArgNames({"locate", "max_step_index"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

// The corrector's tolerance (ContinuationOptions::tolerance), locate_tolerance and max_step at
// their defaults. Argument: -log10(tolerance).
void BM_BBranchCorrector(benchmark::State& state) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  ContinuationOptions o = Options(ContinuationOptions().locate_tolerance, kMaxSteps[0]);
  o.steps.tolerance = std::pow(10.0, -static_cast<double>(state.range(0)));
  Measure(state, prop, o);
}
BENCHMARK(BM_BBranchCorrector)
    ->DenseRange(6, 12)
    ->ArgName("tolerance")
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
