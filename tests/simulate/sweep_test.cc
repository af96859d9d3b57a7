// Brute-force bifurcation sweeps: grid, directions, continuation from the last state, errors and
// cancellation.
#include "drillbif/simulate/sweep.h"

#include <gtest/gtest.h>

#include <cmath>

#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

PropagatorFactory Exact(const DO& model) {
  return [&model] { return std::make_unique<ExactPropagator>(model); };
}

SweepOptions Small(double min, double max, int steps, SweepDirection direction) {
  SweepOptions o;
  o.param = std::string("b");  // not = "b": GCC 12 warns falsely (-Wrestrict, GCC bug 105329)
  o.min = min, o.max = max, o.steps = steps, o.direction = direction;
  o.transient_periods = 200;
  o.sample_periods = 5;
  return o;
}

// Inside the stable period-1 window (PD at b = 0.110, fold at b = 0.167 in MODEL.md) there is one
// attractor, so up and down sweeps land on the same fixed point at every value (to the contraction
// left after 200 periods at multiplier ~0.1: far below 1e-9).
TEST(Sweep, UpAndDownAgreeInsideThePeriodOneWindow) {
  DO model;
  const SweepOptions o = Small(0.12, 0.16, 5, SweepDirection::kBoth);
  const SweepResult r =
      Sweep(model, Exact(model), testing::ReferenceParams(), DefaultInitialState(model), o);
  ASSERT_EQ(r.termination, Termination::kCompleted) << r.status.ToString();
  ASSERT_EQ(r.up.size(), 5u);
  ASSERT_EQ(r.down.size(), 5u);
  for (int i = 0; i < 5; ++i) {
    const SweepPoint& u = r.up[i];
    const SweepPoint& d = r.down[4 - i];
    EXPECT_DOUBLE_EQ(u.value, 0.12 + 0.01 * i);
    EXPECT_DOUBLE_EQ(u.value, d.value);
    ASSERT_EQ(u.termination, Termination::kCompleted) << u.message;
    ASSERT_EQ(u.samples.size(), 5u);
    ASSERT_EQ(d.samples.size(), 5u);
    for (int k = 0; k < 5; ++k) {
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(u.samples[k].x[c], d.samples[k].x[c], 1e-9 * (1 + std::abs(d.samples[k].x[c])));
      }
      // Period 1: every sample is the same point.
      EXPECT_NEAR(u.samples[k].x[DO::kP], u.samples[0].x[DO::kP], 1e-9 * 60);
    }
  }
  // At b = 0.15 the fixed point is MODEL.md's (7 decimals).
  EXPECT_NEAR(r.up[3].samples[0].x[DO::kP], testing::kRefFixedP, testing::kRefFixedPrecision);
}

// Sequential sweeping starts each value from the previous value's final state: one chunk, one
// thread, gives the same result as simulating the values one after another by hand.
TEST(Sweep, EachValueStartsFromTheLastState) {
  DO model;
  SweepOptions o = Small(0.09, 0.12, 3, SweepDirection::kUp);
  o.threads = 1;
  o.chunks = 1;
  o.chunk_start_transient_factor = 1;
  const SweepResult r =
      Sweep(model, Exact(model), testing::ReferenceParams(), DefaultInitialState(model), o);
  ASSERT_EQ(r.termination, Termination::kCompleted);
  ExactPropagator prop(model);
  StateVector x = DefaultInitialState(model);
  for (int i = 0; i < 3; ++i) {
    Params p = testing::ReferenceParams();
    p[DO::kB] = r.up[i].value;
    SimulationOptions so;
    so.transient_periods = o.transient_periods;
    so.sample_periods = o.sample_periods;
    const SimulationResult s = Simulate(model, prop, p, x, so);
    ASSERT_EQ(s.poincare.size(), r.up[i].samples.size());
    for (size_t k = 0; k < s.poincare.size(); ++k) {
      EXPECT_EQ(s.poincare[k].x, r.up[i].samples[k].x) << "value " << i << " sample " << k;
    }
    x = s.final_state;
  }
}

TEST(Sweep, ChunksCoverTheGridInOrder) {
  DO model;
  SweepOptions o = Small(0.0, 0.2, 11, SweepDirection::kUp);
  o.threads = 2;
  o.chunks = 3;
  o.transient_periods = 20;
  o.sample_periods = 2;
  const SweepResult r =
      Sweep(model, Exact(model), testing::ReferenceParams(), DefaultInitialState(model), o);
  ASSERT_EQ(r.termination, Termination::kCompleted);
  ASSERT_EQ(r.up.size(), 11u);
  EXPECT_TRUE(r.down.empty());
  for (int i = 0; i < 11; ++i) {
    EXPECT_NEAR(r.up[i].value, 0.02 * i, 1e-15);
    EXPECT_EQ(r.up[i].termination, Termination::kCompleted) << r.up[i].message;
    EXPECT_EQ(r.up[i].samples.size(), 2u);
  }
}

TEST(Sweep, InvalidRequestsNameTheProblem) {
  DO model;
  const Params prm = testing::ReferenceParams();
  const StateVector x0 = DefaultInitialState(model);
  struct Case {
    SweepOptions options;
    const char* needle;
  };
  SweepOptions unknown = Small(0, 1, 3, SweepDirection::kUp);
  unknown.param = "zeta";
  SweepOptions reversed = Small(0.2, 0.1, 3, SweepDirection::kUp);
  SweepOptions one_step = Small(0.1, 0.2, 1, SweepDirection::kUp);
  SweepOptions bad_xi = Small(-1.0, 0.5, 3, SweepDirection::kUp);
  bad_xi.param = "xi";
  for (const Case& c : {Case{unknown, "zeta"}, Case{reversed, "max must be > min"},
                        Case{one_step, "steps"}, Case{bad_xi, "xi"}}) {
    const SweepResult r = Sweep(model, Exact(model), prm, x0, c.options);
    EXPECT_FALSE(r.status.ok());
    EXPECT_NE(r.termination, Termination::kCompleted);
    EXPECT_NE(r.status.message().find(c.needle), std::string::npos) << r.status.message();
  }
}

TEST(Sweep, ProgressCanCancel) {
  DO model;
  SweepOptions o = Small(0.0, 0.2, 400, SweepDirection::kBoth);
  o.transient_periods = 500;
  const SweepResult r = Sweep(model, Exact(model), testing::ReferenceParams(),
                              DefaultInitialState(model), o, [](double) { return false; });
  EXPECT_EQ(r.termination, Termination::kCancelled);
  EXPECT_EQ(r.status.code(), StatusCode::kCancelled);
}

}  // namespace
}  // namespace drillbif
