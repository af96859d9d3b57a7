// Cancellation of one- and two-parameter continuation and of period-doubling switching: a stop is
// honoured within the bound (support/cancel_probe.h) however long a single step takes, with a
// CANCELLED status and only what was computed before the stop kept.
#include <gtest/gtest.h>

#include <chrono>

#include "drillbif/continuation/continuation.h"
#include "drillbif/continuation/curve.h"
#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"
#include "support/cancel_probe.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;
using std::chrono::milliseconds;
using testing::CancelProbe;

constexpr milliseconds kDelay(200);  // as in simulation_cancel_test.cc

// CVODE with steps bounded by 1e-4 of the time scale: every flow takes ~10^5 steps with
// sensitivities, a continuation step seconds, so that the stop comes inside one.
CvodeOptions Slow() {
  CvodeOptions o;
  o.max_step_fraction = 1e-4;
  o.max_steps = 1000000000;
  return o;
}

ContinuationOptions InB() {
  ContinuationOptions o;
  o.param = std::string("b");  // not = "b": GCC 12 -Wrestrict false positive
  o.min = 0.0;
  o.max = 0.2;
  return o;
}

PeriodicOrbit Reference(const DO& model) {
  ExactPropagator exact(model);
  const StatusOr<PeriodicOrbit> orbit =
      testing::SolvedOrbitFromRest(model, exact, testing::ReferenceParams());
  EXPECT_TRUE(orbit.ok()) << orbit.status().ToString();
  return orbit.ok() ? *orbit : PeriodicOrbit{};
}

// The reference b-branch's first located point of a kind (exact propagator).
SpecialPoint Located(const DO& model, SpecialPointKind kind) {
  ExactPropagator exact(model);
  const ContinuationResult r = Continue(model, exact, Reference(model), InB());
  for (const SpecialPoint& s : r.special_points) {
    if (s.kind == kind) return s;
  }
  ADD_FAILURE() << "no " << SpecialPointKindName(kind) << " on the reference b-branch";
  return {};
}

TEST(ContinuationCancel, StopsPromptlyInsideASlowStep) {
  DO model;
  CvodePropagator prop(model, Slow());
  const PeriodicOrbit start = Reference(model);
  int points = 0;
  CancelProbe probe(kDelay);
  const ContinuationResult r = Continue(
      model, prop, start, InB(),
      [&](const ContinuationPoint&, double) {
        ++points;
        return true;
      },
      probe.Callback());
  probe.Returned();
  EXPECT_EQ(r.summary.termination, Termination::kCancelled) << r.summary.message;
  EXPECT_EQ(r.summary.status.code(), StatusCode::kCancelled);
  // The counters count the steps accepted before the stop (the callback saw each).
  EXPECT_LE(r.summary.steps, points);
  EXPECT_EQ(r.summary.BriefReport().rfind("cancelled: ", 0), 0u) << r.summary.BriefReport();
  // Whatever was kept was accepted before the stop: the points handed to the callback, and the
  // start (recorded when the first direction began) if it was reached.
  EXPECT_LE(static_cast<int>(r.points.size()), points + 1);
  for (const ContinuationPoint& p : r.points) EXPECT_TRUE(p.stability.monodromy.allFinite());
  probe.ExpectPrompt("one-parameter continuation (slow CVODE flows)");
}

// Without a callback of its own the continuation polls the throttle its propagator carries.
TEST(ContinuationCancel, PollsThePropagatorsThrottle) {
  DO model;
  ExactPropagator prop(model);
  const PeriodicOrbit start = Reference(model);
  ProgressThrottle throttle;
  throttle.Stop();
  ScopedProgress attach(prop, &throttle);
  const ContinuationResult r = Continue(model, prop, start, InB());
  EXPECT_EQ(r.summary.termination, Termination::kCancelled) << r.summary.message;
  EXPECT_EQ(r.summary.status.code(), StatusCode::kCancelled);
  EXPECT_EQ(r.summary.message, "cancelled before the first step");
  EXPECT_EQ(r.summary.steps, 0);
  EXPECT_TRUE(r.points.empty());
}

TEST(ContinuationCancel, CurveStopsPromptlyInsideASlowStep) {
  DO model;
  const SpecialPoint fold = Located(model, SpecialPointKind::kFold);
  CvodePropagator prop(model, Slow());
  CurveOptions o;
  o.param1 = std::string("b");
  o.param2 = std::string("a");
  o.min1 = 0.0, o.max1 = 0.3;
  o.min2 = 0.1, o.max2 = 0.5;
  CancelProbe probe(kDelay);
  const CurveResult r = ContinueCurve(model, prop, fold, o, probe.Callback());
  probe.Returned();
  EXPECT_EQ(r.summary.termination, Termination::kCancelled) << r.summary.message;
  EXPECT_EQ(r.summary.status.code(), StatusCode::kCancelled);
  for (const CurvePoint& p : r.points) EXPECT_TRUE(p.stability.monodromy.allFinite());
  probe.ExpectPrompt("two-parameter curve (slow CVODE flows)");
}

// Switching by simulation, with a transient of 1e8 periods on each side.
TEST(ContinuationCancel, PeriodDoublingSwitchBySimulationStopsPromptly) {
  DO model;
  const SpecialPoint pd = Located(model, SpecialPointKind::kPeriodDoubling);
  ExactPropagator prop(model);
  PeriodDoublingSwitchOptions o;
  o.transient_periods = 100000000;
  CancelProbe probe(kDelay);
  const StatusOr<PeriodicOrbit> r =
      SwitchAtPeriodDoubling(model, prop, pd, "b", o, probe.Callback());
  probe.Returned();
  EXPECT_EQ(r.status().code(), StatusCode::kCancelled) << r.status().ToString();
  probe.ExpectPrompt("period-doubling switch (simulation)");
}

TEST(ContinuationCancel, AlgebraicPeriodDoublingSwitchStopsPromptly) {
  DO model;
  const SpecialPoint pd = Located(model, SpecialPointKind::kPeriodDoubling);
  CvodePropagator prop(model, Slow());
  CancelProbe probe(kDelay);
  const StatusOr<PeriodicOrbit> r =
      SwitchAtPeriodDoublingAlgebraic(model, prop, pd.point.orbit, "b", 1e-3, probe.Callback());
  probe.Returned();
  EXPECT_EQ(r.status().code(), StatusCode::kCancelled) << r.status().ToString();
  probe.ExpectPrompt("period-doubling switch (algebraic, slow CVODE flows)");
}

}  // namespace
}  // namespace drillbif
