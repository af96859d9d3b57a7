// Direct simulation of a period-2 orbit from its section state (starts[0]): it must return after
// two forcing periods, to `tol`, and not after one, where its two passes differ by more than
// `split` (distances over the state without its phase). Shared by the branch-switching tests.
#ifndef DRILLBIF_TESTS_SUPPORT_PERIOD_TWO_H_
#define DRILLBIF_TESTS_SUPPORT_PERIOD_TWO_H_

#include <gtest/gtest.h>

#include <cmath>
#include <vector>

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

// Distances from the orbit's section state of the Poincare samples of direct simulation from it
// over `periods` forcing periods (after 1, 2, ...).
inline std::vector<double> ReturnDistances(const HybridModel& model, Propagator& prop,
                                           const PeriodicOrbit& orbit, int periods) {
  SimulationOptions options;
  options.transient_periods = 0;
  options.sample_periods = periods;
  options.outputs = SimulationOutputs{false, true, false, false, 0.0};
  const SimulationResult s = Simulate(model, prop, orbit.params, orbit.starts[0], options);
  std::vector<double> d;
  for (const PoincareSample& p : s.poincare) {
    d.push_back(DistanceWithoutPhase(model, p.x, orbit.starts[0]));
  }
  return d;
}

inline void ExpectPeriodTwoBySimulation(const HybridModel& model, Propagator& prop,
                                        const PeriodicOrbit& orbit, double tol, double split) {
  const std::vector<double> d = ReturnDistances(model, prop, orbit, 2);
  ASSERT_EQ(d.size(), 2u);
  EXPECT_LT(d[1], tol);
  EXPECT_GT(d[0], split);
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_PERIOD_TWO_H_
