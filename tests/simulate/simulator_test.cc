// Event-driven simulation with the exact propagator: the reference period-1 orbit of MODEL.md,
// invariants over 1e5 forcing periods, outputs on demand, and bad input.
#include "drillbif/simulate/simulator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "support/spy_propagator.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

TEST(ReferenceOrbit, SettlesOnThePublishedPeriodOneOrbit) {
  DO model;
  ExactPropagator prop(model);
  SimulationOptions opt;
  opt.outputs.events = true;
  opt.outputs.modes = true;
  const SimulationResult r =
      Simulate(model, prop, testing::ReferenceParams(), DefaultInitialState(model), opt);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.status.ToString();
  // Published to 10 decimals; the simulation after 500 periods has converged far below that
  // (the orbit's nontrivial multiplier is -0.087, so 500 periods contract by 1e-500).
  ASSERT_EQ(r.measure_means.size(), 2u);
  EXPECT_NEAR(r.measure_means[DO::kDrift], testing::kRefRop, testing::kRefMeasurePrecision);
  EXPECT_NEAR(r.measure_means[DO::kPower], testing::kRefPc, testing::kRefMeasurePrecision);
  ASSERT_EQ(r.poincare.size(), 100u);
  for (const PoincareSample& p : r.poincare) {
    EXPECT_EQ(p.mode, DO::kNoContact);
    EXPECT_NEAR(p.x[DO::kP], testing::kRefFixedP, testing::kRefFixedPrecision);
    EXPECT_NEAR(p.x[DO::kY], testing::kRefFixedY, testing::kRefFixedPrecision);
    EXPECT_NEAR(p.x[DO::kQ], testing::kRefFixedQ, testing::kRefFixedPrecision);
    EXPECT_EQ(p.x[DO::kS], 0.0);
  }
  // One period visits NC, CwoP, CwP, CwoP, NC.
  ASSERT_EQ(r.period_modes.size(), 100u);
  const std::vector<int> signature = {DO::kNoContact, DO::kContact, DO::kProgression, DO::kContact,
                                      DO::kNoContact};
  for (const std::vector<int>& modes : r.period_modes) EXPECT_EQ(modes, signature);
  // Four events per period at the published phases (5 decimals).
  ASSERT_EQ(r.events.size(), 400u);
  const double phases[4] = {testing::kRefImpactS, testing::kRefProgressionS, testing::kRefStickS,
                            testing::kRefSeparationS};
  for (size_t k = 0; k < r.events.size(); ++k) {
    EXPECT_NEAR(r.events[k].s, phases[k % 4], testing::kRefPhasePrecision) << "event " << k;
    EXPECT_FALSE(r.events[k].tangential);
  }
}

// 1e5 forcing periods: the invariant set 0 <= q <= 1, p <= q + g holds at every event and every
// section to 1e-12, s stays in [0, 2 pi), and the forcing phase does not drift: the impact phase
// of the last period equals that of the first sampled period to 1e-11 (the orbit is attracting,
// so any drift of s relative to the forcing would accumulate into a visible phase shift).
TEST(LongRun, KeepsTheInvariantSetAndThePhaseOverOneHundredThousandPeriods) {
  DO model;
  ExactPropagator prop(model);
  const Params prm = testing::ReferenceParams();
  SimulationOptions opt;
  opt.transient_periods = 100;
  opt.sample_periods = 100000;
  opt.outputs.events = true;
  const SimulationResult r = Simulate(model, prop, prm, DefaultInitialState(model), opt);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.status.ToString();
  ASSERT_EQ(r.poincare.size(), 100000u);
  ASSERT_EQ(r.events.size(), 400000u);
  auto check = [&](const StateVector& x) {
    ASSERT_GE(x[DO::kQ], -1e-12);
    ASSERT_LE(x[DO::kQ], 1.0 + 1e-12);
    ASSERT_LE(x[DO::kP] - x[DO::kQ] - prm[DO::kG], 1e-12);
    ASSERT_GE(x[DO::kS], 0.0);
    ASSERT_LT(x[DO::kS], kTwoPi);
  };
  for (const EventRecord& e : r.events) check(e.x);
  for (const PoincareSample& p : r.poincare) check(p.x);
  // Four events a period: the last period's impact against the first sampled period's.
  const EventRecord& last_impact = r.events[r.events.size() - 4];
  EXPECT_EQ(last_impact.from_mode, DO::kNoContact);
  EXPECT_EQ(r.events[0].from_mode, DO::kNoContact);
  EXPECT_NEAR(last_impact.s, r.events[0].s, 1e-11);
  EXPECT_NEAR(r.events.back().s, r.events[3].s, 1e-11);
  // Time bookkeeping: the last event's time is its period and phase, exactly.
  const EventRecord& last = r.events.back();
  EXPECT_NEAR(last.t, (kTwoPi * last.period + last.s) / prm[DO::kOmega], 1e-9 * last.t);
}

using testing::SpyPropagator;

TEST(OutputsOnDemand, ComputesNothingThatWasNotAsked) {
  DO model;
  ExactPropagator exact(model);
  SpyPropagator spy(exact);
  SimulationOptions opt;
  opt.transient_periods = 10;
  opt.sample_periods = 10;
  opt.outputs = SimulationOutputs{false, false, false, false, 0.0};
  const SimulationResult r =
      Simulate(model, spy, testing::ReferenceParams(), DefaultInitialState(model), opt);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted);
  EXPECT_FALSE(spy.measures_asked);
  EXPECT_FALSE(spy.samples_asked);
  EXPECT_TRUE(r.measure_means.empty());
  EXPECT_TRUE(r.poincare.empty());
  EXPECT_TRUE(r.events.empty());
  EXPECT_TRUE(r.period_modes.empty());
  EXPECT_TRUE(r.trajectory.empty());
}

TEST(OutputsOnDemand, MeasuresAreComputedOnlyInTheWindow) {
  DO model;
  ExactPropagator exact(model);
  SpyPropagator spy(exact);
  SimulationOptions opt;
  opt.transient_periods = 5;
  opt.sample_periods = 1;
  opt.outputs = SimulationOutputs{true, false, false, false, 0.0};
  const SimulationResult r =
      Simulate(model, spy, testing::ReferenceParams(), DefaultInitialState(model), opt);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted);
  EXPECT_TRUE(spy.measures_asked);
  EXPECT_EQ(r.measure_means.size(), 2u);
  EXPECT_TRUE(r.poincare.empty());
}

TEST(OutputsOnDemand, TrajectoryIsSampledAlongTheFlow) {
  DO model;
  ExactPropagator prop(model);
  const Params prm = testing::ReferenceParams();
  SimulationOptions opt;
  opt.transient_periods = 50;
  opt.sample_periods = 1;
  opt.outputs = SimulationOutputs{false, false, false, false, 0.5};
  const SimulationResult r = Simulate(model, prop, prm, DefaultInitialState(model), opt);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted);
  // One period of 62.8 time units at dt = 0.5 plus one point per segment end.
  ASSERT_GE(r.trajectory.size(), 126u);
  for (size_t k = 1; k < r.trajectory.size(); ++k) {
    const TrajectoryPoint& a = r.trajectory[k - 1];
    const TrajectoryPoint& b = r.trajectory[k];
    const double dt = b.t - a.t;
    ASSERT_GE(dt, -1e-12);
    ASSERT_LE(dt, 0.5 + 1e-12);
    // Within one mode, the later sample is the exact flow of the earlier one.
    if (a.mode != b.mode) continue;
    StateVector x;
    model.Flow(a.mode, a.x, dt, prm, &x, nullptr);
    for (int i = 0; i < 3; ++i) EXPECT_NEAR(x[i], b.x[i], 1e-9 * (1 + std::abs(b.x[i])));
  }
}

TEST(BadInput, EachInvalidParameterFailsWithAMessageNamingIt) {
  DO model;
  ExactPropagator prop(model);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  struct Case {
    int index;
    double value;
    const char* name;
  };
  for (const Case& c :
       {Case{DO::kXi, 0.0, "xi"}, Case{DO::kOmega, -0.1, "omega"}, Case{DO::kA, -1.0, "a"},
        Case{DO::kB, -1.0, "b"}, Case{DO::kG, 0.0, "g"}, Case{DO::kPhi0, nan, "phi0"}}) {
    Params p = testing::ReferenceParams();
    p[c.index] = c.value;
    const SimulationResult r = Simulate(model, prop, p, DefaultInitialState(model), {});
    EXPECT_EQ(r.summary.termination, Termination::kFailed);
    EXPECT_EQ(r.summary.status.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(r.summary.status.message().find(c.name), std::string::npos)
        << r.summary.status.message();
    for (double v : r.measure_means) EXPECT_FALSE(std::isnan(v));
  }
}

TEST(BadInput, InitialStateOutsideTheInvariantSetFails) {
  DO model;
  ExactPropagator prop(model);
  StateVector x = DefaultInitialState(model);
  x[DO::kP] = 1.0;  // p > q + g: the bit inside the rock
  const SimulationResult r = Simulate(model, prop, testing::ReferenceParams(), x, {});
  EXPECT_EQ(r.summary.termination, Termination::kFailed);
  EXPECT_NE(r.summary.status.message().find("p <= q + g"), std::string::npos)
      << r.summary.status.message();
}

TEST(BadInput, InvalidOptionsFail) {
  DO model;
  ExactPropagator prop(model);
  SimulationOptions opt;
  opt.sample_periods = 0;
  const SimulationResult r =
      Simulate(model, prop, testing::ReferenceParams(), DefaultInitialState(model), opt);
  EXPECT_EQ(r.summary.termination, Termination::kFailed);
  EXPECT_EQ(r.summary.status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(r.summary.status.message().find("sample_periods"), std::string::npos);
  EXPECT_EQ(r.summary.message, r.summary.status.message());
  EXPECT_EQ(r.summary.segments, 0);
}

TEST(Cancellation, ProgressCallbackStopsTheRun) {
  DO model;
  ExactPropagator prop(model);
  SimulationOptions opt;
  opt.transient_periods = 1000;
  int calls = 0;
  const SimulationResult r = Simulate(model, prop, testing::ReferenceParams(),
                                      DefaultInitialState(model), opt, [&](double fraction) {
                                        EXPECT_GE(fraction, 0.0);
                                        EXPECT_LE(fraction, 1.0);
                                        return ++calls < 3;
                                      });
  EXPECT_EQ(r.summary.termination, Termination::kCancelled);
  EXPECT_EQ(r.summary.status.code(), StatusCode::kCancelled);
  EXPECT_EQ(calls, 3);
}

}  // namespace
}  // namespace drillbif
