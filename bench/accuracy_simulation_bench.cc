// Accuracy against time, simulation stage (docs/accuracy.md, scripts/accuracy.sh): the
// exact propagator and CVODE at rtol 1e-3 ... 1e-12 (atol = rtol / 100), each simulating 100
// forcing periods from the reference period-1 orbit (MODEL.md's fixed point). Reference: the exact
// propagator (closed-form flows, events polished to rounding). Run:
//   build/bench/accuracy_simulation_bench --benchmark_format=json
// Counters:
//   seconds_per_period  wall time per forcing period, s
//   poincare_rel_err    max |x - x_ref| / max |x_ref| over the last Poincare point's (p, y, q)
//   rop_rel_err         |ROP - ROP_ref| / ROP_ref over the 100 periods
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <string>

#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/simulate/simulator.h"
#include "problems/drifting_reference.h"
#include "reference_window.h"

namespace drillbif {
namespace {

using bench::ExactReference;
using bench::kPeriods;
using bench::OrbitStart;
using bench::Window;

// Runs the simulation once per benchmark iteration; wall time per forcing period as a counter.
void Measure(benchmark::State& state, Propagator& prop) {
  DriftingOscillator model;
  SimulationResult r;
  double seconds = 0.0;
  for (auto _ : state) {
    const auto start = std::chrono::steady_clock::now();
    r = Simulate(model, prop, testing::ReferenceParams(), OrbitStart(), Window());
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    benchmark::DoNotOptimize(r.measure_means.data());
  }
  const SimulationResult& ref = ExactReference();
  if (r.summary.termination != Termination::kCompleted || r.poincare.empty()) {
    state.SkipWithError((std::string("simulation failed: ") + r.summary.status.ToString()).c_str());
    return;
  }
  double err = 0.0, scale = 0.0;
  for (int i = 0; i < 3; ++i) {
    err = std::max(err, std::abs(r.poincare.back().x[i] - ref.poincare.back().x[i]));
    scale = std::max(scale, std::abs(ref.poincare.back().x[i]));
  }
  state.counters["seconds_per_period"] = seconds / (double(state.iterations()) * kPeriods);
  state.counters["poincare_rel_err"] = err / scale;
  state.counters["rop_rel_err"] =
      std::abs(r.measure_means[0] - ref.measure_means[0]) / std::abs(ref.measure_means[0]);
}

void BM_Exact(benchmark::State& state) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  Measure(state, prop);
}
BENCHMARK(BM_Exact)->Unit(benchmark::kMillisecond)->UseRealTime();

// Argument: -log10(rtol); atol = rtol / 100 (the ratio of CvodeOptions' defaults).
void BM_Cvode(benchmark::State& state) {
  DriftingOscillator model;
  CvodeOptions opt;
  opt.rtol = std::pow(10.0, -static_cast<double>(state.range(0)));
  opt.atol = opt.rtol * 1e-2;
  CvodePropagator prop(model, opt);
  Measure(state, prop);
}
BENCHMARK(BM_Cvode)->DenseRange(3, 12)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
