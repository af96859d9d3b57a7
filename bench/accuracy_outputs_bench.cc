// Accuracy against time, on-demand outputs (docs/accuracy.md, scripts/accuracy.sh): the
// same simulation (100 forcing periods from the reference period-1 orbit, no transient) asking for
// ROP only (the measures) versus every output (measures, Poincare samples, event log, modes of
// each period, trajectory every 0.1 time units). The answers' ROP must agree exactly. Run:
//   build/bench/accuracy_outputs_bench --benchmark_format=json
// Counters:
//   seconds_per_period  wall time per forcing period, s
//   rop                 ROP over the window
//   records             Poincare samples + events + trajectory points recorded
#include <benchmark/benchmark.h>

#include <chrono>
#include <memory>

#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/simulate/simulator.h"
#include "problems/drifting_reference.h"

namespace drillbif {
namespace {

constexpr int kPeriods = 100;

SimulationOptions Window(bool everything) {
  SimulationOptions o;
  o.transient_periods = 0;
  o.sample_periods = kPeriods;
  o.outputs.measures = true;
  o.outputs.poincare = everything;
  o.outputs.events = everything;
  o.outputs.modes = everything;
  o.outputs.trajectory_dt = everything ? 0.1 : 0.0;  // ~630 points per period at omega = 0.1
  return o;
}

// Arguments: propagator (0 exact, 1 CVODE with its default tolerances), outputs (0 ROP only,
// 1 everything).
void BM_Outputs(benchmark::State& state) {
  DriftingOscillator model;
  std::unique_ptr<Propagator> prop;
  if (state.range(0) == 0) {
    prop = std::make_unique<ExactPropagator>(model);
  } else {
    prop = std::make_unique<CvodePropagator>(model);
  }
  StateVector x0(4);
  x0 << testing::kRefFixedP, testing::kRefFixedY, testing::kRefFixedQ, 0.0;
  const SimulationOptions opt = Window(state.range(1) == 1);
  SimulationResult r;
  double seconds = 0.0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    r = Simulate(model, *prop, testing::ReferenceParams(), x0, opt);
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    benchmark::DoNotOptimize(r.measure_means.data());
  }
  if (r.summary.termination != Termination::kCompleted) {
    state.SkipWithError("simulation failed");
    return;
  }
  state.counters["seconds_per_period"] = seconds / (double(state.iterations()) * kPeriods);
  state.counters["rop"] = r.measure_means[0];
  state.counters["records"] =
      static_cast<double>(r.poincare.size() + r.events.size() + r.trajectory.size());
}
BENCHMARK(BM_Outputs)
    ->ArgsProduct({{0, 1}, {0, 1}})
    ->ArgNames({"cvode", "all"})
    ->MinTime(2.0)  // CVODE takes ~0.2 s per run: enough runs to compare two close times
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
