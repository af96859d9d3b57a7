// The sweep job (SweepRequest -> engine sweep -> SweepResult): both directions, invalid requests
// as INVALID_ARGUMENT naming the field, and the cost refused before running.
#include "jobs/sweep_job.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>
#include <vector>

namespace drillbif::jobs {
namespace {

using ::testing::HasSubstr;

// A small sweep around the reference point: 5 values, short transient, 5 samples each.
v1::SweepRequest SmallSweep() {
  v1::SweepRequest request;
  request.set_param("b");
  request.set_min(0.145);
  request.set_max(0.155);
  request.set_steps(5);
  request.set_transient_periods(50);
  request.set_sample_periods(5);
  request.set_threads(1);
  return request;
}

TEST(RunSweep, SmallSweepInBothDirections) {
  v1::SweepRequest request = SmallSweep();
  request.set_direction(v1::SweepRequest::BOTH);
  const StatusOr<v1::SweepResult> result = RunSweep(request);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  EXPECT_EQ(result->status(), "COMPLETED");
  ASSERT_EQ(result->up_size(), 5);
  ASSERT_EQ(result->down_size(), 5);
  for (int i = 0; i < 5; ++i) {
    const double value = 0.145 + 0.0025 * i;
    EXPECT_NEAR(result->up(i).value(), value, 1e-15);
    EXPECT_NEAR(result->down(4 - i).value(), value, 1e-15);
  }
  for (const auto* points : {&result->up(), &result->down()}) {
    for (const v1::SweepPoint& pt : *points) {
      EXPECT_EQ(pt.status(), "COMPLETED") << pt.value() << ": " << pt.message();
      EXPECT_EQ(pt.samples_size(), 5);
      for (const v1::PoincarePoint& s : pt.samples()) EXPECT_NE(s.mode(), v1::MODE_UNSPECIFIED);
    }
  }
  EXPECT_GE(result->periods_total(), 2 * 5 * (50 + 5));
  EXPECT_GT(result->events_total(), 0);
}

TEST(RunSweep, UnknownParameterIsInvalidArgumentNamingIt) {
  v1::SweepRequest request = SmallSweep();
  request.set_param("zeta");
  const StatusOr<v1::SweepResult> result = RunSweep(request);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(result.status().message(), HasSubstr("zeta"));
}

TEST(RunSweep, RangeOutsideTheDomainNamesTheParameter) {
  v1::SweepRequest request = SmallSweep();
  request.set_min(-0.1);
  const StatusOr<v1::SweepResult> result = RunSweep(request);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(result.status().message(), HasSubstr("b"));
}

TEST(RunSweep, TooManySamplesIsRejectedBeforeRunning) {
  v1::SweepRequest request = SmallSweep();
  request.set_steps(1'000'000);
  request.set_sample_periods(100);
  const StatusOr<v1::SweepResult> result = RunSweep(request);
  ASSERT_FALSE(result.ok());
  EXPECT_EQ(result.status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace drillbif::jobs
