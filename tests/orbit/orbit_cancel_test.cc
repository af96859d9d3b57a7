// Cancellation of the start-orbit search (OrbitFromSimulation, then SolveOrbit: what a job runner
// does before its continuation) and of attractor sampling: a stop is honoured within the bound
// (support/cancel_probe.h), with a CANCELLED status and nothing computed after it kept.
#include <gtest/gtest.h>

#include <chrono>

#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/orbit/attractors.h"
#include "drillbif/orbit/periodic_orbit.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"
#include "support/cancel_probe.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;
using std::chrono::milliseconds;
using testing::CancelProbe;

constexpr milliseconds kDelay(200);  // as in simulation_cancel_test.cc

// A transient of 1e8 periods (~10 minutes) before the orbit is read off.
TEST(OrbitCancel, OrbitFromSimulationStopsPromptly) {
  DO model;
  ExactPropagator prop(model);
  GuessOptions guess;
  guess.transient_periods = 100000000;
  CancelProbe probe(kDelay);
  const StatusOr<PeriodicOrbit> r = OrbitFromSimulation(
      model, prop, testing::ReferenceParams(), DefaultInitialState(model), guess, probe.Callback());
  probe.Returned();
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kCancelled) << r.status().ToString();
  EXPECT_EQ(prop.progress(), nullptr);  // its throttle detached again
  probe.ExpectPrompt("start orbit: simulation");
}

// Newton with flows slowed a million-fold (CVODE steps bounded by 1e-6 of the time scale: ~1e6
// steps with sensitivities per segment, seconds each): the stop comes inside a flow.
TEST(OrbitCancel, SolveOrbitStopsPromptlyInsideAFlow) {
  DO model;
  ExactPropagator exact(model);
  const StatusOr<PeriodicOrbit> start =
      testing::SolvedOrbitFromRest(model, exact, testing::ReferenceParams());
  ASSERT_TRUE(start.ok()) << start.status().ToString();
  CvodeOptions slow;
  slow.max_step_fraction = 1e-6;
  slow.max_steps = 1000000000;
  CvodePropagator prop(model, slow);
  PeriodicOrbit orbit = *start;
  CancelProbe probe(kDelay);
  const OrbitSolveSummary s = SolveOrbit(model, prop, {}, &orbit, probe.Callback());
  probe.Returned();
  EXPECT_EQ(s.termination, Termination::kCancelled) << s.message;
  EXPECT_STREQ(TerminationName(s.termination), "CANCELLED");
  EXPECT_EQ(s.status.code(), StatusCode::kCancelled);
  EXPECT_EQ(s.BriefReport().rfind("cancelled: ", 0), 0u) << s.BriefReport();
  // Left as given.
  EXPECT_EQ(orbit.durations, start->durations);
  probe.ExpectPrompt("start orbit: Newton (slow CVODE flows)");
}

// Without a callback of its own, the solve polls the throttle its propagator carries (an outer
// computation's): a stopped one ends it at once.
TEST(OrbitCancel, SolveOrbitPollsThePropagatorsThrottle) {
  DO model;
  ExactPropagator prop(model);
  const StatusOr<PeriodicOrbit> start =
      testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  ASSERT_TRUE(start.ok());
  PeriodicOrbit orbit = *start;
  ProgressThrottle throttle;
  throttle.Stop();
  ScopedProgress attach(prop, &throttle);
  const OrbitSolveSummary s = SolveOrbit(model, prop, {}, &orbit);
  EXPECT_EQ(s.termination, Termination::kCancelled);
  EXPECT_EQ(s.status.code(), StatusCode::kCancelled);
}

// Attractor sampling from three states, each with a transient of 1e8 periods.
TEST(OrbitCancel, SampleAttractorsStopsPromptly) {
  DO model;
  ExactPropagator prop(model);
  GuessOptions guess;
  guess.transient_periods = 100000000;
  const Params prm = testing::ReferenceParams();
  const std::vector<StateVector> states(3, DefaultInitialState(model));
  CancelProbe probe(kDelay);
  const StatusOr<AttractorSample> r =
      SampleAttractors(model, prop, prm, states, guess, probe.Callback());
  probe.Returned();
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->summary.termination, Termination::kCancelled) << r->summary.BriefReport();
  EXPECT_EQ(r->summary.status.code(), StatusCode::kCancelled);
  EXPECT_EQ(r->summary.message.rfind("cancelled at initial state ", 0), 0u) << r->summary.message;
  EXPECT_TRUE(r->attractors.empty());
  EXPECT_TRUE(r->not_periodic.empty());  // the state it stopped in is in neither list
  probe.ExpectPrompt("attractor sampling");
}

// Not stopped: the same sample as without a callback.
TEST(OrbitCancel, SampleAttractorsWithACallbackCompletes) {
  DO model;
  ExactPropagator prop(model);
  const Params prm = testing::ReferenceParams();
  const std::vector<StateVector> states(2, DefaultInitialState(model));
  int calls = 0;
  const StatusOr<AttractorSample> r = SampleAttractors(model, prop, prm, states, {}, [&](double) {
    ++calls;
    return true;
  });
  ASSERT_TRUE(r.ok());
  EXPECT_EQ(r->summary.termination, Termination::kCompleted) << r->summary.BriefReport();
  ASSERT_EQ(r->attractors.size(), 1u);
  EXPECT_EQ(r->attractors[0].reached_from.size(), 2u);
  EXPECT_GT(calls, 0);
}

}  // namespace
}  // namespace drillbif
