// Two-parameter curve cost (docs/performance.md): tracing every fold, PD and grazing curve
// through the reference orbit's branches in the reference (omega, a) box (omega in [0.05, 2], a in
// [0.01, 8] at b = 0.15, problems/reference_box.h), with their codimension-2 points, on 1 and 2
// threads; the same with the period-2 curves (minutes: run alone with
// --benchmark_filter=BM_TracePeriodTwoBox); and one curve alone. Run (medians of 3; the trace
// takes seconds):
//   build/bench/curve_bench --benchmark_filter='BM_TraceReferenceBox|BM_GrazingCurveL1'
//     --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
// Counters: curves, points (on all curves), codim2 (codimension-2 points found); for the period-2
// box also peak_rss_mb (the process' VmHWM after the trace, curves streamed and dropped).
#include <benchmark/benchmark.h>

#include <fstream>
#include <string>

#include "drillbif/continuation/trace.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_box.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

// How the correctors solve their Newton systems (ContinuationOptions / CurveOptions::steps'
// condensed_solve).
enum class Solves {
  kDefaults,   // as TraceOptions has them: the curves condensed, the branches dense
  kDense,      // every corrector dense
  kCondensed,  // every corrector condensed
};

// The whole trace: both one-parameter branches and every curve (the start orbit excluded), with
// the corrector aiming at state.range(0) Newton iterations per curve step (3: the FINE curve
// steps of a trace request; 4: COARSE, the default) on state.range(1) threads.
void TraceReferenceBox(benchmark::State& state, Solves solves) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const PeriodicOrbit start =
      *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  TraceOptions options = testing::ReferenceBox();
  options.curve.steps.target_iterations = static_cast<int>(state.range(0));
  options.threads = static_cast<int>(state.range(1));
  if (solves != Solves::kDefaults) {
    options.curve.steps.condensed_solve = solves == Solves::kCondensed;
    options.branch.steps.condensed_solve = solves == Solves::kCondensed;
  }
  TraceResult r;
  for (auto _ : state) {
    r = TraceCurves(model, prop, start, options);
    benchmark::DoNotOptimize(r.curves.data());
  }
  double points = 0.0, codim2 = 0.0;
  for (const TracedCurve& c : r.curves) {
    points += static_cast<double>(c.curve.points.size());
    codim2 += static_cast<double>(c.curve.codim2.size());
  }
  state.counters["curves"] = static_cast<double>(r.curves.size());
  state.counters["points"] = points;
  state.counters["codim2"] = codim2;
  if (!r.summary.completed()) state.SkipWithError(r.summary.BriefReport().c_str());
}
// Args: target iterations (3: FINE, 4: COARSE), threads.
void BM_TraceReferenceBox(benchmark::State& state) { TraceReferenceBox(state, Solves::kDefaults); }
BENCHMARK(BM_TraceReferenceBox)
    ->Args({3, 1})
    ->Args({3, 2})
    ->Args({4, 1})
    ->Args({4, 2})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->UseRealTime();
// The same with every corrector dense, and with every one condensed (docs/performance.md compares
// them).
void BM_TraceReferenceBoxDense(benchmark::State& state) {
  TraceReferenceBox(state, Solves::kDense);
}
BENCHMARK(BM_TraceReferenceBoxDense)
    ->Args({3, 1})
    ->Args({4, 1})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->UseRealTime();
void BM_TraceReferenceBoxCondensed(benchmark::State& state) {
  TraceReferenceBox(state, Solves::kCondensed);
}
BENCHMARK(BM_TraceReferenceBoxCondensed)
    ->Args({3, 1})
    ->Args({4, 1})
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->UseRealTime();

// The process' peak resident set (VmHWM) in MB, 0 if unknown.
double PeakRssMb() {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);) {
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  }
  return 0.0;
}

// The reference box with max_period 2 (the period-2 branches' curves and the period-2 grazing
// curves leaving the flip-grazings), the curves handed to a callback that counts and drops them,
// as the trace job streams them, without the interior vertices' section states, as the trace job
// asks: the memory the trace itself holds. Arg: threads.
void BM_TracePeriodTwoBox(benchmark::State& state) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const PeriodicOrbit start =
      *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  TraceOptions options = testing::ReferenceBox();
  options.max_period = 2;
  options.threads = static_cast<int>(state.range(0));
  options.vertex_states = false;  // as the trace job asks
  double curves = 0.0, points = 0.0, codim2 = 0.0;
  bool ok = true;
  for (auto _ : state) {
    curves = points = codim2 = 0.0;
    const TraceResult r =
        TraceCurves(model, prop, start, options, {}, [&](int, const TracedCurve& c) {
          curves += 1.0;
          points += static_cast<double>(c.curve.points.size());
          codim2 += static_cast<double>(c.curve.codim2.size());
          return true;
        });
    ok = r.summary.completed();
  }
  state.counters["curves"] = curves;
  state.counters["points"] = points;
  state.counters["codim2"] = codim2;
  state.counters["peak_rss_mb"] = PeakRssMb();
  if (!ok) state.SkipWithError("trace failed");
}
BENCHMARK(BM_TracePeriodTwoBox)
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->UseRealTime();

// One curve: the l1 grazing curve from the omega-branch grazing at 0.5088 (a = 0.3), 688 points
// and four codimension-2 points (two flip-, one fold-, one double grazing); the cost per point of
// a grazing curve.
void BM_GrazingCurveL1(benchmark::State& state) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const PeriodicOrbit start =
      *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  ContinuationOptions branch;
  branch.param = std::string("omega");
  branch.min = 0.05, branch.max = 2.0;
  const ContinuationResult omega = Continue(model, prop, start, branch);
  const SpecialPoint* graze = nullptr;
  for (const SpecialPoint& s : omega.special_points) {
    if (s.kind == SpecialPointKind::kGrazingL1 && s.point.value > 0.4) graze = &s;
  }
  if (graze == nullptr) {
    state.SkipWithError("no l1 grazing on the omega-branch");
    return;
  }
  CurveOptions opt;
  opt.param1 = std::string("omega");
  opt.param2 = std::string("a");
  opt.min1 = 0.05, opt.max1 = 2.0, opt.min2 = 0.01, opt.max2 = 8.0;
  CurveResult c;
  for (auto _ : state) {
    c = ContinueCurve(model, prop, *graze, opt);
    benchmark::DoNotOptimize(c.points.data());
  }
  state.counters["points"] = static_cast<double>(c.points.size());
  state.counters["codim2"] = static_cast<double>(c.codim2.size());
}
BENCHMARK(BM_GrazingCurveL1)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
