// Direct simulation of a period-2 orbit from its section state (starts[0]): it must return after
// two forcing periods, to `tol`, and not after one, where its two passes differ by more than
// `split` (distances over the state without its phase). Shared by the branch-switching tests.
#ifndef DRILLBIF_TESTS_SUPPORT_PERIOD_TWO_H_
#define DRILLBIF_TESTS_SUPPORT_PERIOD_TWO_H_

#include <gtest/gtest.h>

#include <cmath>

#include "drillbif/orbit/periodic_orbit.h"
#include "drillbif/simulate/simulator.h"

namespace drillbif::testing {

inline double DistanceWithoutPhase(const HybridModel& model, const StateVector& x,
                                   const StateVector& y) {
  double sum = 0.0;
  for (int i = 0; i < model.state_dim(); ++i) {
    if (i != model.phase_index()) sum += (x[i] - y[i]) * (x[i] - y[i]);
  }
  return std::sqrt(sum);
}

inline void ExpectPeriodTwoBySimulation(const HybridModel& model, Propagator& prop,
                                        const PeriodicOrbit& orbit, double tol, double split) {
  SimulationOptions two;
  two.transient_periods = 0;
  two.sample_periods = 2;
  two.outputs = SimulationOutputs{false, true, false, false, 0.0};
  const SimulationResult s = Simulate(model, prop, orbit.params, orbit.starts[0], two);
  ASSERT_EQ(s.poincare.size(), 2u);
  EXPECT_LT(DistanceWithoutPhase(model, s.poincare[1].x, orbit.starts[0]), tol);
  EXPECT_GT(DistanceWithoutPhase(model, s.poincare[0].x, orbit.starts[0]), split);
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_PERIOD_TWO_H_
