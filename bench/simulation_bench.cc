// Simulation cost and accuracy: time per forcing period of the exact propagator and of CVODE at
// several tolerances, each with its error against the exact propagator, and the wall time of the
// brute-force bifurcation diagram in b. Run (medians of 5):
//   build/bench/simulation_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
//
// Every run starts on the reference period-1 orbit (MODEL.md's fixed point) and simulates
// kPeriods forcing periods with the default outputs (ROP, Pc, Poincare samples). Counters:
//   us_per_period    wall time per forcing period, microseconds
//   poincare_err     max |x - x_exact| over the last Poincare point's (p, y, q)
//   rop_err          |ROP - ROP_exact|
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>

#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/simulate/sweep.h"
#include "problems/drifting_reference.h"
#include "reference_window.h"

namespace drillbif {
namespace {

using bench::ExactReference;
using bench::kPeriods;
using bench::OrbitStart;
using bench::Window;

// Runs the simulation once per benchmark iteration, timing each run on the wall clock.
template <typename Run>
SimulationResult TimePeriods(benchmark::State& state, const Run& run) {
  SimulationResult r;
  double seconds = 0.0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    r = run();
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    benchmark::DoNotOptimize(r.measure_means.data());
  }
  state.counters["us_per_period"] = 1e6 * seconds / (state.iterations() * double(kPeriods));
  return r;
}

void ReportErrors(benchmark::State& state, const SimulationResult& r) {
  const SimulationResult& ref = ExactReference();
  if (r.summary.termination != Termination::kCompleted || r.poincare.empty()) {
    state.SkipWithError(("simulation failed: " + r.summary.status.ToString()).c_str());
    return;
  }
  double err = 0.0;
  for (int i = 0; i < 3; ++i) {
    err = std::max(err, std::abs(r.poincare.back().x[i] - ref.poincare.back().x[i]));
  }
  state.counters["poincare_err"] = err;
  state.counters["rop_err"] = std::abs(r.measure_means[0] - ref.measure_means[0]);
}

void BM_ExactPerPeriod(benchmark::State& state) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const SimulationResult r = TimePeriods(state, [&] {
    return Simulate(model, prop, testing::ReferenceParams(), OrbitStart(), Window());
  });
  ReportErrors(state, r);
}
BENCHMARK(BM_ExactPerPeriod)->Unit(benchmark::kMillisecond)->UseRealTime();

// Argument: -log10(rtol); atol = rtol / 100.
void BM_CvodePerPeriod(benchmark::State& state) {
  DriftingOscillator model;
  CvodeOptions opt;
  opt.rtol = std::pow(10.0, -static_cast<double>(state.range(0)));
  opt.atol = opt.rtol * 1e-2;
  CvodePropagator prop(model, opt);
  const SimulationResult r = TimePeriods(state, [&] {
    return Simulate(model, prop, testing::ReferenceParams(), OrbitStart(), Window());
  });
  ReportErrors(state, r);
}
BENCHMARK(BM_CvodePerPeriod)->Arg(6)->Arg(9)->Arg(12)->Unit(benchmark::kMillisecond)->UseRealTime();

// The brute-force diagram of the report: 1000 values of b in [0, 0.2], 500 + 100 periods each,
// swept up on `threads` threads with the direction cut into `chunks` pieces (wall time).
void BM_SweepB(benchmark::State& state) {
  DriftingOscillator model;
  SweepOptions o;
  o.param = "b";
  o.min = 0.0;
  o.max = 0.2;
  o.steps = 1000;
  o.threads = static_cast<int>(state.range(0));
  o.chunks = static_cast<int>(state.range(1));
  SweepResult r;
  for (auto _ : state) {
    r = Sweep(
        model, [&model] { return std::make_unique<ExactPropagator>(model); },
        testing::ReferenceParams(), DefaultInitialState(model), o);
    benchmark::DoNotOptimize(r.up.data());
  }
  long long failed = 0;
  for (const SweepPoint& p : r.up) failed += p.summary.termination != Termination::kCompleted;
  state.counters["failed_values"] = static_cast<double>(failed);
  state.counters["periods"] = static_cast<double>(r.summary.periods);
}
BENCHMARK(BM_SweepB)
    ->ArgNames({"threads", "chunks"})
    ->Args({1, 1})
    ->Args({2, 1})
    ->Args({2, 2})
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
