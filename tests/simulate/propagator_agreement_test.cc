// The two propagators check each other: simulations with the exact propagator and with CVODE give
// the same events in the same order and the same Poincare points, to a tolerance derived from
// CVODE's tolerances; the hard parameter sets simulate without NaN under both.
#include <gtest/gtest.h>

#include <cmath>

#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/simulate/simulator.h"
#include "problems/drifting_reference.h"
#include "problems/parameter_sets.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

// CVODE keeps its local error per step below rtol |x| + atol; on these smooth, non-stiff modes its
// global error over one forcing period stays within K = 100 times that (Adams' usual ratio of
// global to local tolerance; measured 5-15 on the forced linear oscillator), and on an attracting
// orbit (multiplier -0.087) errors of successive periods do not accumulate but contract: the
// error of a Poincare point stays below K (rtol |x| + atol) / (1 - 0.087). Event phases, located
// on the perturbed trajectory, inherit that error divided by the guard's rate (O(1) here).
constexpr double kRtol = 1e-10;
constexpr double kAtol = 1e-12;
double CvodeTolerance(double magnitude) {
  return 100.0 * (kRtol * magnitude + kAtol) / (1 - 0.087);
}

CvodeOptions TightCvode() {
  CvodeOptions o;
  o.rtol = kRtol;
  o.atol = kAtol;
  return o;
}

TEST(PropagatorAgreement, SameEventsAndPoincarePointsOverOneHundredPeriods) {
  DO model;
  ExactPropagator exact(model);
  CvodePropagator cvode(model, TightCvode());
  const Params prm = testing::ReferenceParams();
  StateVector x0(4);
  x0 << testing::kRefFixedP, testing::kRefFixedY, testing::kRefFixedQ, 0.0;
  SimulationOptions opt;
  opt.transient_periods = 0;
  opt.sample_periods = 100;
  opt.outputs.events = true;
  const SimulationResult a = Simulate(model, exact, prm, x0, opt);
  const SimulationResult b = Simulate(model, cvode, prm, x0, opt);
  ASSERT_EQ(a.summary.termination, Termination::kCompleted) << a.summary.status.ToString();
  ASSERT_EQ(b.summary.termination, Termination::kCompleted) << b.summary.status.ToString();
  ASSERT_EQ(a.events.size(), b.events.size());
  ASSERT_EQ(a.events.size(), 400u);
  for (size_t k = 0; k < a.events.size(); ++k) {
    const EventRecord& ea = a.events[k];
    const EventRecord& eb = b.events[k];
    ASSERT_EQ(ea.period, eb.period) << "event " << k;
    ASSERT_EQ(ea.from_mode, eb.from_mode) << "event " << k;
    ASSERT_EQ(ea.to_mode, eb.to_mode) << "event " << k;
    ASSERT_EQ(ea.guard, eb.guard) << "event " << k;
    // |p| ~ 60 at most along the orbit sets the state scale for the phase error.
    EXPECT_NEAR(ea.s, eb.s, CvodeTolerance(60.0)) << "event " << k;
  }
  ASSERT_EQ(a.poincare.size(), 100u);
  ASSERT_EQ(b.poincare.size(), 100u);
  for (size_t k = 0; k < a.poincare.size(); ++k) {
    for (int i = 0; i < 3; ++i) {
      EXPECT_NEAR(a.poincare[k].x[i], b.poincare[k].x[i],
                  CvodeTolerance(std::abs(a.poincare[k].x[i]) + 1.0))
          << "sample " << k << " component " << i;
    }
  }
  EXPECT_NEAR(a.measure_means[DO::kDrift], b.measure_means[DO::kDrift], CvodeTolerance(1.0));
  EXPECT_NEAR(a.measure_means[DO::kPower], b.measure_means[DO::kPower], CvodeTolerance(1.0));
}

// The hard parameter sets: a short run from rest under both propagators, with no NaN anywhere and
// the same event sequence and Poincare points. Over 3 periods from rest (a transient, not an
// attracting orbit yet) the tolerance allows a growth factor of 100 on top of the one above.
class HardCaseAgreementTest : public ::testing::TestWithParam<testing::NamedParams> {};

TEST_P(HardCaseAgreementTest, BothPropagatorsAgreeWithoutNaN) {
  DO model;
  ExactPropagator exact(model);
  CvodePropagator cvode(model, TightCvode());
  const Params& prm = GetParam().params;
  SimulationOptions opt;
  opt.transient_periods = 0;
  opt.sample_periods = 3;
  opt.outputs.events = true;
  const SimulationResult a = Simulate(model, exact, prm, DefaultInitialState(model), opt);
  const SimulationResult b = Simulate(model, cvode, prm, DefaultInitialState(model), opt);
  ASSERT_EQ(a.summary.termination, Termination::kCompleted) << a.summary.status.ToString();
  ASSERT_EQ(b.summary.termination, Termination::kCompleted) << b.summary.status.ToString();
  for (double v : a.measure_means) EXPECT_TRUE(std::isfinite(v));
  for (double v : b.measure_means) EXPECT_TRUE(std::isfinite(v));
  ASSERT_EQ(a.events.size(), b.events.size());
  for (size_t k = 0; k < a.events.size(); ++k) {
    ASSERT_EQ(a.events[k].from_mode, b.events[k].from_mode) << "event " << k;
    ASSERT_EQ(a.events[k].to_mode, b.events[k].to_mode) << "event " << k;
  }
  ASSERT_EQ(a.poincare.size(), b.poincare.size());
  for (size_t k = 0; k < a.poincare.size(); ++k) {
    for (int i = 0; i < 3; ++i) {
      ASSERT_TRUE(std::isfinite(a.poincare[k].x[i]));
      EXPECT_NEAR(a.poincare[k].x[i], b.poincare[k].x[i],
                  100.0 * CvodeTolerance(std::abs(a.poincare[k].x[i]) + 1.0))
          << "sample " << k << " component " << i;
    }
  }
}

INSTANTIATE_TEST_SUITE_P(HardParameters, HardCaseAgreementTest,
                         ::testing::ValuesIn(testing::HardParameterSets()),
                         [](const auto& test_info) { return test_info.param.name; });

}  // namespace
}  // namespace drillbif
