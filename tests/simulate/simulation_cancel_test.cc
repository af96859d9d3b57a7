// Cancellation of simulations: a stop is honoured within the bound (support/cancel_probe.h) with
// the exact and the CVODE propagator, inside a single long CVODE integration, and in runs whose
// period counts do not fit 32 bits.
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <limits>

#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/simulate/simulator.h"
#include "problems/drifting_reference.h"
#include "support/cancel_probe.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;
using std::chrono::milliseconds;
using testing::CancelProbe;

// The stop is requested 200 ms into each run: long enough to be well inside the phase (the runs
// below would take from minutes to years), short enough to keep each test fast.
constexpr milliseconds kDelay(200);

// 2^31 - 1 transient periods: the sum with the sample periods used to wrap to a negative count,
// and the run returned at once, COMPLETED with ROP 0. Now it runs (~6 us a period: ~4 hours),
// reports its fraction and stops when asked.
TEST(SimulationOverflow, TransientOfIntMaxRunsAndIsCancellable) {
  DO model;
  ExactPropagator prop(model);
  SimulationOptions opt;
  opt.transient_periods = std::numeric_limits<int32_t>::max();
  opt.sample_periods = 100;
  ASSERT_TRUE(opt.Validate().ok());
  CancelProbe probe(kDelay);
  const SimulationResult r = Simulate(model, prop, testing::ReferenceParams(),
                                      DefaultInitialState(model), opt, probe.Callback());
  probe.Returned();
  EXPECT_EQ(r.summary.termination, Termination::kCancelled) << r.summary.status.ToString();
  EXPECT_EQ(r.summary.status.code(), StatusCode::kCancelled);
  // The message says where it stopped, and the report leads with the termination.
  EXPECT_EQ(r.summary.message.rfind("cancelled at period ", 0), 0u) << r.summary.message;
  EXPECT_EQ(r.summary.BriefReport().rfind("cancelled: ", 0), 0u) << r.summary.BriefReport();
  EXPECT_TRUE(r.measure_means.empty());
  EXPECT_TRUE(r.final_state.allFinite());
  EXPECT_GT(r.summary.segments, 1000);  // it ran
  EXPECT_GT(r.summary.evaluations, 0);
  EXPECT_GT(probe.calls(), 0);
  probe.ExpectPrompt("simulate exact, 2^31 - 1 transient periods");
}

// Counts beyond 64 bits are refused, naming the fields; counts beyond 32 bits are not.
TEST(SimulationOverflow, ValidateRefusesOnlyWhatDoesNotFit64Bits) {
  SimulationOptions opt;
  opt.transient_periods = std::numeric_limits<int64_t>::max();
  opt.sample_periods = 1;
  const Status s = opt.Validate();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("transient_periods + sample_periods"), std::string::npos)
      << s.message();
  opt.transient_periods = std::numeric_limits<int64_t>::max() - 1;
  EXPECT_TRUE(opt.Validate().ok());
  opt.transient_periods = int64_t{1} << 40;
  opt.sample_periods = int64_t{1} << 40;
  EXPECT_TRUE(opt.Validate().ok());
}

// The CVODE propagator (~1.5 ms a period): a million transient periods, stopped after 200 ms.
TEST(SimulationCancel, CvodeRunStopsPromptly) {
  DO model;
  CvodePropagator prop(model);
  SimulationOptions opt;
  opt.transient_periods = 1000000;
  CancelProbe probe(kDelay);
  const SimulationResult r = Simulate(model, prop, testing::ReferenceParams(),
                                      DefaultInitialState(model), opt, probe.Callback());
  probe.Returned();
  EXPECT_EQ(r.summary.termination, Termination::kCancelled) << r.summary.status.ToString();
  EXPECT_TRUE(r.final_state.allFinite());
  probe.ExpectPrompt("simulate cvode");
}

// One CVODE integration that alone takes minutes (a free flight of 1e9 time units, ~1e9 internal
// steps): the right-hand side polls the throttle the propagator carries, and the call returns
// CANCELLED with the documented well-formed result (x0, identity Jacobian).
TEST(SimulationCancel, SingleLongCvodeIntegrationStopsPromptly) {
  DO model;
  CvodeOptions o;
  o.max_steps = std::numeric_limits<long>::max();
  CvodePropagator prop(model, o);
  const Params prm = testing::ReferenceParams();
  StateVector x0 = DefaultInitialState(model);
  CancelProbe probe(kDelay);
  ProgressThrottle throttle(probe.Callback());
  FlowResult r;
  {
    ScopedProgress attach(prop, &throttle);
    FlowRequest request;
    request.state_jacobian = true;
    r = prop.FlowMap(DO::kNoContact, x0, 1e9, prm, request);
  }
  probe.Returned();
  EXPECT_EQ(r.status.code(), StatusCode::kCancelled) << r.status.ToString();
  EXPECT_EQ(r.x, x0);
  EXPECT_TRUE(r.state_jacobian.isIdentity(0.0));
  EXPECT_EQ(prop.progress(), nullptr);  // detached at the scope's end
  probe.ExpectPrompt("single CVODE integration");
  // The propagator works normally afterwards (a stop is the throttle's, not the propagator's).
  const FlowResult again = prop.FlowMap(DO::kNoContact, x0, 1.0, prm, {});
  EXPECT_TRUE(again.status.ok()) << again.status.ToString();
}

// A stopped throttle ends an exact Advance at once with the documented result.
TEST(SimulationCancel, StoppedThrottleEndsPropagatorCalls) {
  DO model;
  ExactPropagator prop(model);
  ProgressThrottle throttle;
  throttle.Stop();
  ScopedProgress attach(prop, &throttle);
  AdvanceRequest req;
  req.mode = DO::kNoContact;
  req.x0 = DefaultInitialState(model);
  req.t_max = 10.0;
  req.measures = true;
  const AdvanceResult r = prop.Advance(req, testing::ReferenceParams());
  EXPECT_EQ(r.end, AdvanceEnd::kFailed);
  EXPECT_EQ(r.status.code(), StatusCode::kCancelled);
  EXPECT_EQ(r.x, req.x0);
  ASSERT_EQ(r.measures.size(), 2);
  EXPECT_TRUE(r.measures.isZero(0.0));
}

}  // namespace
}  // namespace drillbif
