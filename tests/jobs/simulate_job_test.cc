// The simulate job (SimulateRequest -> engine simulation -> SimulateResult): the reference run of
// MODEL.md through the API, outputs on demand, invalid requests as INVALID_ARGUMENT naming the
// field, and cancellation. (What drillctl prints of the results: tests/client/output_test.cc.)
#include "jobs/simulate_job.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "problems/drifting_reference.h"

namespace drillbif::jobs {
namespace {

using ::testing::HasSubstr;

// Published to 10 decimals (MODEL.md); the run has converged far below that after 500 periods.
// The API only copies the engine's doubles, so the brief's 1e-9 holds with a wide margin.
constexpr double kRopTolerance = 1e-9;

TEST(RunSimulate, DefaultRequestGivesThePublishedReferenceOrbit) {
  const StatusOr<v1::SimulateResult> result = RunSimulate(v1::SimulateRequest());
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  EXPECT_EQ(result->status(), "COMPLETED");
  EXPECT_EQ(result->message(), "");
  ASSERT_TRUE(result->has_rop());
  ASSERT_TRUE(result->has_power());
  EXPECT_NEAR(result->rop(), testing::kRefRop, kRopTolerance);
  EXPECT_NEAR(result->power(), testing::kRefPc, kRopTolerance);
  // Default outputs: measures and Poincare samples only.
  ASSERT_EQ(result->poincare_size(), 100);
  EXPECT_EQ(result->events_size(), 0);
  EXPECT_EQ(result->period_modes_size(), 0);
  EXPECT_EQ(result->trajectory_size(), 0);
  for (int i = 0; i < result->poincare_size(); ++i) {
    const v1::PoincarePoint& pt = result->poincare(i);
    EXPECT_EQ(pt.period(), 501 + i);  // sections after the 500-period transient
    EXPECT_EQ(pt.mode(), v1::NO_CONTACT);
    EXPECT_NEAR(pt.p(), testing::kRefFixedP, testing::kRefFixedPrecision);
    EXPECT_NEAR(pt.y(), testing::kRefFixedY, testing::kRefFixedPrecision);
    EXPECT_NEAR(pt.q(), testing::kRefFixedQ, testing::kRefFixedPrecision);
  }
  // Four events per period (impact, progression, stick, separation) over 600 periods.
  EXPECT_EQ(result->events_total(), 4 * 600);
  EXPECT_GT(result->segments(), 0);
  EXPECT_GT(result->evaluations(), 0);
  EXPECT_GT(result->wall_seconds(), 0.0);
  EXPECT_FALSE(result->engine_version().empty());
}

TEST(RunSimulate, ExplicitOutputsAreExactlyThoseRequested) {
  v1::SimulateRequest request;
  request.set_sample_periods(3);
  request.mutable_outputs()->set_events(true);
  request.mutable_outputs()->set_modes(true);
  const StatusOr<v1::SimulateResult> result = RunSimulate(request);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  EXPECT_FALSE(result->has_rop());
  EXPECT_FALSE(result->has_power());
  EXPECT_EQ(result->poincare_size(), 0);
  EXPECT_EQ(result->trajectory_size(), 0);
  // The published signature from s = 0: NC, CwoP, CwP, CwoP, NC, in every window period.
  ASSERT_EQ(result->period_modes_size(), 3);
  for (int i = 0; i < 3; ++i) {
    EXPECT_EQ(result->period_modes(i).period(), 500 + i);
    EXPECT_THAT(result->period_modes(i).modes(),
                ::testing::ElementsAre(v1::NO_CONTACT, v1::CONTACT, v1::PROGRESSION, v1::CONTACT,
                                       v1::NO_CONTACT));
  }
  ASSERT_EQ(result->events_size(), 4 * 3);
  const v1::Event& impact = result->events(0);
  EXPECT_EQ(impact.surface(), "Pi");
  EXPECT_EQ(impact.guard(), "impact");
  EXPECT_EQ(impact.from_mode(), v1::NO_CONTACT);
  EXPECT_EQ(impact.to_mode(), v1::CONTACT);
  EXPECT_NEAR(impact.s(), testing::kRefImpactS, testing::kRefPhasePrecision);
  EXPECT_EQ(result->events(1).surface(), "l1");
  EXPECT_EQ(result->events(3).surface(), "l2");
  EXPECT_EQ(result->events(3).guard(), "separation");
}

TEST(RunSimulate, TrajectoryIsSampledInTheWindowOnly) {
  v1::SimulateRequest request;
  request.set_transient_periods(10);
  request.set_sample_periods(1);
  request.mutable_outputs()->set_trajectory_dt(1.0);
  const StatusOr<v1::SimulateResult> result = RunSimulate(request);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  // One forcing period is 2 pi / omega = 62.8 time units: at least 62 samples at dt = 1.
  ASSERT_GE(result->trajectory_size(), 62);
  const double start = 10 * 2 * 3.141592653589793 / 0.1;
  EXPECT_NEAR(result->trajectory(0).t(), start, 1e-9 * start);
  for (const v1::TrajectoryPoint& tp : result->trajectory()) {
    EXPECT_GE(tp.t(), start - 1e-9 * start);
    EXPECT_NE(tp.mode(), v1::MODE_UNSPECIFIED);
  }
}

TEST(RunSimulate, NegativeXiIsInvalidArgumentNamingXi) {
  v1::SimulateRequest request;
  request.mutable_params()->set_xi(-1.0);
  const StatusOr<v1::SimulateResult> result = RunSimulate(request);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(result.status().message(), HasSubstr("xi"));
}

TEST(RunSimulate, InvalidRequestsNameTheirField) {
  struct Case {
    std::string name;
    v1::SimulateRequest request;
    std::string field;  // expected in the message
  };
  std::vector<Case> cases(5);
  cases[0] = {"bad omega", {}, "omega"};
  cases[0].request.mutable_params()->set_omega(0.0);
  cases[1] = {"q outside [0, 1]", {}, "q"};
  cases[1].request.mutable_initial_state()->set_q(2.0);
  cases[2] = {"no samples", {}, "sample_periods"};
  cases[2].request.set_sample_periods(0);
  cases[3] = {"nothing requested", {}, "outputs"};
  cases[3].request.mutable_outputs();
  cases[4] = {"trajectory too dense", {}, "trajectory_dt"};
  cases[4].request.mutable_outputs()->set_trajectory_dt(1e-9);
  for (const Case& c : cases) {
    const StatusOr<v1::SimulateResult> result = RunSimulate(c.request);
    ASSERT_FALSE(result.ok()) << c.name;
    EXPECT_EQ(result.status().code(), StatusCode::kInvalidArgument) << c.name;
    EXPECT_THAT(result.status().message(), HasSubstr(c.field)) << c.name;
  }
}

TEST(RunSimulate, ProgressCallbackCancels) {
  std::vector<double> fractions;
  const StatusOr<v1::SimulateResult> result =
      RunSimulate(v1::SimulateRequest(), {.progress = [&](double fraction) {
                    fractions.push_back(fraction);
                    return fraction < 0.5;
                  }});
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  EXPECT_EQ(result->status(), "CANCELLED");
  EXPECT_FALSE(result->message().empty());
  EXPECT_FALSE(result->has_rop());
  ASSERT_FALSE(fractions.empty());
  EXPECT_GE(fractions.back(), 0.5);
  EXPECT_LT(fractions.back(), 1.0);
}

}  // namespace
}  // namespace drillbif::jobs
