// Shared by the CvodePropagator tests on the forced linear oscillator (cvode_flow_map_test.cc,
// cvode_events_test.cc): the start state, the options and the error bound their tolerances use.
//
// Error model used by the tests' tolerances. Per internal step CVODE keeps the local error of every
// component below rtol |x| + atol (WRMS norm <= 1, applied to states, quadratures and
// sensitivities alike). The oscillator's homogeneous flow is non-expansive (the transient energy
// x^2 + v^2 does not grow: its derivative is -4 zeta v^2), so local errors are not amplified and
// the global error after N steps is at most N (rtol max|x| + atol). At the tolerances used here
// CVODE takes fewer than 50 steps per unit time with either method (the step is also capped at
// max_step_fraction * TimeScale = 0.5), hence the bound
//     GlobalBound(t) = 50 (1 + t) (rtol max|x| + atol).
// It is loose (Adams is ~1000 times better: ~0.1 rtol |x| per unit time) but derived, not tuned.
#ifndef DRILLBIF_TESTS_FLOW_CVODE_TEST_SUPPORT_H_
#define DRILLBIF_TESTS_FLOW_CVODE_TEST_SUPPORT_H_

#include "drillbif/flow/cvode_propagator.h"
#include "problems/forced_linear_oscillator.h"

namespace drillbif::testing {

inline const StateVector kStart = ForcedLinearOscillator::MakeState(0.3, -0.2, 0.4);

inline CvodeOptions Options(double rtol, bool bdf = false) {
  CvodeOptions o;
  o.rtol = rtol;
  o.atol = 1e-2 * rtol;
  o.bdf = bdf;
  return o;
}

// See the error model at the top; xmax bounds |x| and |v| along the trajectories used (R + the
// transient, below 3.5 for kStart and the default parameters) or the sensitivities (below 3).
inline double GlobalBound(const CvodeOptions& o, double t, double xmax = 3.5) {
  return 50.0 * (1.0 + t) * (o.rtol * xmax + o.atol);
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_FLOW_CVODE_TEST_SUPPORT_H_
