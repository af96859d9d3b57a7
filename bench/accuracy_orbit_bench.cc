// Accuracy against time, periodic orbits (docs/accuracy.md, scripts/accuracy.sh): the
// Newton solve of the reference period-1 orbit's boundary-value problem (orbit/periodic_orbit.h)
// from a perturbed guess (below), at
// Newton tolerances 1e-4 ... 1e-12 with the exact flow (closed-form derivatives), and shooting with
// CVODES forward sensitivities at rtol 1e-6 ... 1e-12. Reference: the exact-flow solve at Newton
// tolerance 1e-13. Only the solve is timed (the guess is computed once). Run:
//   build/bench/accuracy_orbit_bench --benchmark_format=json
// Counters:
//   seconds           wall time of one solve, s
//   residual          max-norm of the conditions at the returned orbit (with the solving flow)
//   fixed_rel_err     max |z - z_ref| / max |z_ref| over the fixed point (p, y, q) at s = 0
//   iterations        Newton iterations
//   converged         1 when Newton reported convergence
#include <benchmark/benchmark.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>

#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/orbit/periodic_orbit.h"
#include "problems/drifting_reference.h"

namespace drillbif {
namespace {

// The guess: the orbit read off the simulation (already within ~1e-15 of the solution after 500
// periods, multiplier -0.087), every state component and duration then scaled by 1 + kOffset so
// that Newton has work to do, as from a continuation predictor or a shorter transient.
constexpr double kOffset = 1e-3;
const PeriodicOrbit& Guess() {
  static const PeriodicOrbit g = [] {
    DriftingOscillator model;
    ExactPropagator prop(model);
    PeriodicOrbit orbit =
        *OrbitFromSimulation(model, prop, testing::ReferenceParams(), DefaultInitialState(model));
    for (StateVector& x : orbit.starts) x.head(3) *= 1.0 + kOffset;
    for (double& tau : orbit.durations) tau *= 1.0 + kOffset;
    return orbit;
  }();
  return g;
}

const PeriodicOrbit& Reference() {
  static const PeriodicOrbit ref = [] {
    DriftingOscillator model;
    ExactPropagator prop(model);
    PeriodicOrbit orbit = Guess();
    OrbitSolverOptions o;
    o.tolerance = 1e-13;
    o.max_iterations = 50;
    SolveOrbit(model, prop, o, &orbit);
    return orbit;
  }();
  return ref;
}

void Measure(benchmark::State& state, Propagator& prop, const OrbitSolverOptions& options) {
  DriftingOscillator model;
  PeriodicOrbit orbit;
  OrbitSolveSummary s;
  double seconds = 0.0;
  for (auto _ : state) {
    orbit = Guess();
    const auto start = std::chrono::steady_clock::now();
    s = SolveOrbit(model, prop, options, &orbit);
    seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    benchmark::DoNotOptimize(orbit.durations.data());
  }
  const StateVector& z = orbit.starts[0];
  const StateVector& zr = Reference().starts[0];
  double err = 0.0, scale = 0.0;
  for (int i = 0; i < 3; ++i) {
    err = std::max(err, std::abs(z[i] - zr[i]));
    scale = std::max(scale, std::abs(zr[i]));
  }
  state.counters["seconds"] = seconds / double(state.iterations());
  state.counters["residual"] = s.residual;
  state.counters["fixed_rel_err"] = err / scale;
  state.counters["iterations"] = s.iterations;
  state.counters["converged"] = s.termination == Termination::kCompleted ? 1.0 : 0.0;
  state.SetLabel(TerminationName(s.termination));
}

// Argument: -log10(Newton tolerance).
void BM_ExactNewton(benchmark::State& state) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  OrbitSolverOptions o;
  o.tolerance = std::pow(10.0, -static_cast<double>(state.range(0)));
  Measure(state, prop, o);
}
BENCHMARK(BM_ExactNewton)->DenseRange(4, 12)->Unit(benchmark::kMillisecond)->UseRealTime();

// Argument: -log10(CVODE rtol); atol = rtol / 100; Newton tolerance 100 rtol (below that the
// scaled step is integration noise and Newton cannot converge).
void BM_CvodeShooting(benchmark::State& state) {
  DriftingOscillator model;
  CvodeOptions c;
  c.rtol = std::pow(10.0, -static_cast<double>(state.range(0)));
  c.atol = c.rtol * 1e-2;
  CvodePropagator prop(model, c);
  OrbitSolverOptions o;
  o.tolerance = 100.0 * c.rtol;
  Measure(state, prop, o);
}
BENCHMARK(BM_CvodeShooting)->DenseRange(6, 12, 2)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
