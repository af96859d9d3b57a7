// Accuracy against time, two-parameter curves (docs/accuracy.md, scripts/accuracy.sh):
// the period-doubling curve through the PD point of the reference b-branch (b = 0.11001, a = 0.3,
// omega = 0.1) traced in (b, a) over a in [0.25, 0.35], at several CurveOptions::tolerance and
// max_step settings (the rest at their defaults), against the error of its crossing of a = 0.28
// (CurveOptions::crossings2). Reference: the same curve at tolerance 1e-13. The b-branch and its
// PD point are computed once, outside the timing. Run:
//   build/bench/accuracy_curve_bench --benchmark_format=json
// Counters:
//   seconds       wall time of the curve (both directions), s
//   cross_rel_err |b - b_ref| / b_ref at the crossing a = 0.28
//   points        points on the curve
#include <benchmark/benchmark.h>

#include <chrono>
#include <cmath>
#include <string>

#include "drillbif/continuation/continuation.h"
#include "drillbif/continuation/curve.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

constexpr double kCrossA = 0.28;
// The longest-step settings, argument 1 indexes them: the default (1.0), then shorter.
constexpr double kMaxSteps[] = {1.0, 0.1, 0.02};

const SpecialPoint& PdPoint() {
  static const SpecialPoint pd = [] {
    DriftingOscillator model;
    ExactPropagator prop(model);
    const PeriodicOrbit start =
        *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
    ContinuationOptions o;
    o.param = std::string("b");  // not = "b": GCC 12 -Wrestrict false positive
    o.min = 0.0, o.max = 0.2;
    o.direction = ContinuationDirection::kDecreasing;
    o.stop_at = {SpecialPointKind::kPeriodDoubling};
    for (const SpecialPoint& s : Continue(model, prop, start, o).special_points) {
      if (s.kind == SpecialPointKind::kPeriodDoubling) return s;
    }
    return SpecialPoint{};
  }();
  return pd;
}

CurveOptions Options(double tolerance, double max_step) {
  CurveOptions o;
  o.param1 = std::string("b");
  o.param2 = std::string("a");
  o.min1 = 0.0, o.max1 = 1.0;
  o.min2 = 0.25, o.max2 = 0.35;
  o.steps.tolerance = tolerance;
  o.steps.max_step = max_step;
  o.crossings2 = {kCrossA};
  return o;
}

// The b of the curve's crossing of a = kCrossA; NaN when there is none.
double Crossing(const CurveResult& c) {
  for (const CurvePoint& p : c.crossings) {
    if (std::abs(p.value2 - kCrossA) < 1e-12) return p.value1;
  }
  return NAN;
}

double Reference() {
  static const double ref = [] {
    DriftingOscillator model;
    ExactPropagator prop(model);
    return Crossing(ContinueCurve(model, prop, PdPoint(), Options(1e-13, kMaxSteps[0])));
  }();
  return ref;
}

// Arguments: -log10(tolerance), index into kMaxSteps.
void BM_PdCurve(benchmark::State& state) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const CurveOptions o =
      Options(std::pow(10.0, -static_cast<double>(state.range(0))), kMaxSteps[state.range(1)]);
  if (PdPoint().kind != SpecialPointKind::kPeriodDoubling) {
    state.SkipWithError("no PD point on the b-branch");
    return;
  }
  CurveResult c;
  double seconds = 0.0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    c = ContinueCurve(model, prop, PdPoint(), o);
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    benchmark::DoNotOptimize(c.points.data());
  }
  const double b = Crossing(c);
  if (std::isnan(b) || std::isnan(Reference())) {
    state.SkipWithError("no crossing of a = 0.28");
    return;
  }
  state.counters["seconds"] = seconds / double(state.iterations());
  state.counters["cross_rel_err"] = std::abs(b - Reference()) / std::abs(Reference());
  state.counters["cross_b"] = b;
  state.counters["points"] = static_cast<double>(c.points.size());
  state.counters["max_step"] = o.steps.max_step;
}
BENCHMARK(BM_PdCurve)
    ->ArgsProduct({{4, 6, 8, 10, 12}, {0, 1, 2}})
    ->ArgNames({"tol", "max_step_index"})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
