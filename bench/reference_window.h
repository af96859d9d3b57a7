// The measurement window shared by the simulation benchmarks: kPeriods forcing periods from the
// reference period-1 orbit's fixed point (MODEL.md), no transient, default outputs; and the exact
// propagator's run of it, the reference the CVODE runs are compared with.
#ifndef DRILLBIF_BENCH_REFERENCE_WINDOW_H_
#define DRILLBIF_BENCH_REFERENCE_WINDOW_H_

#include "drillbif/flow/exact_propagator.h"
#include "drillbif/simulate/simulator.h"
#include "problems/drifting_reference.h"

namespace drillbif::bench {

inline constexpr int kPeriods = 100;

inline StateVector OrbitStart() {
  StateVector x(4);
  x << testing::kRefFixedP, testing::kRefFixedY, testing::kRefFixedQ, 0.0;
  return x;
}

inline SimulationOptions Window() {
  SimulationOptions o;
  o.transient_periods = 0;
  o.sample_periods = kPeriods;
  return o;
}

inline const SimulationResult& ExactReference() {
  static const SimulationResult r = [] {
    DriftingOscillator model;
    ExactPropagator prop(model);
    return Simulate(model, prop, testing::ReferenceParams(), OrbitStart(), Window());
  }();
  return r;
}

}  // namespace drillbif::bench

#endif  // DRILLBIF_BENCH_REFERENCE_WINDOW_H_
