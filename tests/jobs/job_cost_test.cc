// Admission control: each kind's cost estimate from its request (registry.h, job_cost.h), checked
// against its limits at submit, with messages naming the field, its value and the limit; counts
// that would overflow are over every limit, never wrapped into small ones.
#include "jobs/job_cost.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>

#include "jobs/registry.h"
#include "jobs/trace_job.h"

namespace drillbif::jobs {
namespace {

using ::testing::HasSubstr;

StatusOr<JobCost> CostOf(v1::JobKind kind, const google::protobuf::Message& request) {
  return CheckRequest(*FindKind(kind), request);
}

Status Admit(v1::JobKind kind, const google::protobuf::Message& request) {
  const JobKindSpec& spec = *FindKind(kind);
  DRILLBIF_ASSIGN_OR_RETURN(const JobCost cost, CheckRequest(spec, request));
  return CheckCost(cost, spec.default_limits, spec.name.c_str());
}

TEST(JobCost, EveryKindHasFiniteDefaultLimitsWithinAGigabyte) {
  for (const JobKindSpec* kind : AllKinds()) {
    EXPECT_TRUE(kind->default_limits.Validate().ok()) << kind->name;
    EXPECT_GT(kind->default_limits.max_seconds, 0) << kind->name;
    EXPECT_GT(kind->default_limits.max_result_bytes, 0) << kind->name;
    EXPECT_LE(kind->default_limits.max_memory_bytes, 1'000'000'000) << kind->name;
  }
}

TEST(JobCost, TheReferenceSimulationIsCheapAndAccepted) {
  v1::SimulateRequest request;  // 500 + 100 periods, measures and Poincare samples
  const StatusOr<JobCost> cost = CostOf(v1::SIMULATE, request);
  ASSERT_TRUE(cost.ok()) << cost.status().ToString();
  // 600 periods at 1e-5 s: 6 ms; 100 samples of 40 bytes.
  EXPECT_NEAR(cost->seconds.amount, 600 * 1e-5, 1e-12);
  EXPECT_NEAR(cost->result_bytes.amount, 100 * 40.0, 1e-9);
  EXPECT_TRUE(Admit(v1::SIMULATE, request).ok());
}

TEST(JobCost, AnOverflowingTransientIsRefusedNamingTheFieldsNotWrapped) {
  v1::SimulateRequest request;
  request.set_transient_periods(std::numeric_limits<int32_t>::max());
  const Status s = Admit(v1::SIMULATE, request);
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(s.message(), HasSubstr("request.transient_periods + request.sample_periods = "
                                     "2147483747 forcing periods"));
  EXPECT_THAT(s.message(), HasSubstr("max_seconds of simulate jobs"));
}

TEST(JobCost, AMillionSampledPeriodsWithEventsExceedTheResultLimit) {
  v1::SimulateRequest request;
  request.set_transient_periods(0);
  request.set_sample_periods(1'000'000);
  request.mutable_outputs()->set_events(true);
  request.mutable_outputs()->set_poincare(true);
  const Status s = Admit(v1::SIMULATE, request);
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
  // 1e6 * (40 + 8 * 90) bytes = 760 MB against 256 MB.
  EXPECT_THAT(s.message(), HasSubstr("request.sample_periods = 1000000 with outputs poincare, "
                                     "events: about 760 MB of results, above the limit of 256 MB"));
}

TEST(JobCost, ATenMillionValueSweepIsRefusedAtSubmit) {
  v1::SweepRequest request;
  request.set_param("b");
  request.set_min(0);
  request.set_max(0.2);
  request.set_steps(10'000'000);
  const Status s = Admit(v1::SWEEP, request);
  EXPECT_FALSE(s.ok());
  EXPECT_THAT(s.message(), HasSubstr("steps"));
}

TEST(JobCost, ASweepWithoutSamplesOrWithANegativeTransientIsRefusedNamingTheField) {
  v1::SweepRequest request;  // Found by sweep_request_fuzz (the engine said "samples").
  request.set_param("b");
  request.set_min(0.1);
  request.set_max(0.2);
  request.set_sample_periods(0);
  StatusOr<JobCost> cost = CostOf(v1::SWEEP, request);
  EXPECT_EQ(cost.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(cost.status().message(), HasSubstr("sample_periods must be >= 1, got 0"));
  request.set_sample_periods(10);
  request.set_transient_periods(-1);
  cost = CostOf(v1::SWEEP, request);
  EXPECT_EQ(cost.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(cost.status().message(), HasSubstr("transient_periods must be >= 0, got -1"));
}

TEST(JobCost, SweepCostCountsEveryValueAndDirection) {
  v1::SweepRequest request;
  request.set_param("b");
  request.set_min(0.1);
  request.set_max(0.2);
  request.set_steps(1000);
  request.set_direction(v1::SweepRequest::BOTH);
  request.set_transient_periods(100);
  request.set_sample_periods(10);
  const StatusOr<JobCost> cost = CostOf(v1::SWEEP, request);
  ASSERT_TRUE(cost.ok()) << cost.status().ToString();
  // 2000 values of 110 periods (one chunk: no longer transient), at 1e-5 s a period, and 25 us of
  // each value's own work.
  EXPECT_NEAR(cost->seconds.amount, 2000.0 * 110 * 1e-5 + 2000 * 2.5e-5, 1e-9);
  EXPECT_NEAR(cost->result_bytes.amount, 2000.0 * 10 * 40 + 2000.0 * 30, 1e-6);
  // 8 chunks a direction: 7 later chunk starts each way, each 3 * 100 periods longer.
  request.set_chunks(8);
  const StatusOr<JobCost> chunked = CostOf(v1::SWEEP, request);
  ASSERT_TRUE(chunked.ok()) << chunked.status().ToString();
  EXPECT_NEAR(chunked->seconds.amount, (2000.0 * 110 + 2 * 7 * 3.0 * 100) * 1e-5 + 2000 * 2.5e-5,
              1e-9);
}

TEST(JobCost, ContinuationCostGrowsWithTheStepBudgetAndDirections) {
  v1::ContinueRequest request;
  request.set_param("b");
  request.set_min(0);
  request.set_max(0.2);
  request.set_max_steps(1000);
  request.set_direction(v1::ContinueRequest::INCREASING);
  const StatusOr<JobCost> one = CostOf(v1::CONTINUE, request);
  request.set_direction(v1::ContinueRequest::BOTH);
  const StatusOr<JobCost> both = CostOf(v1::CONTINUE, request);
  ASSERT_TRUE(one.ok() && both.ok());
  EXPECT_NEAR(both->memory_bytes.amount, 2 * one->memory_bytes.amount, 1e-6);
  EXPECT_GT(both->seconds.amount, one->seconds.amount);
  // The largest step budget in both directions: 200000 points of ~20 kB held, 4 GB.
  request.set_max_steps(100'000);
  const Status s = Admit(v1::CONTINUE, request);
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(s.message(), HasSubstr("request.max_steps = 100000"));
}

TEST(JobCost, AWholeBoxPeriodTwoMapIsRefusedAndAPeriodOneMapAccepted) {
  v1::TraceRequest request;
  request.add_trace_params("omega");
  request.add_trace_params("a");
  request.add_min(0.05);
  request.add_min(0.01);
  request.add_max(2);
  request.add_max(8);
  EXPECT_TRUE(Admit(v1::TRACE, request).ok());
  request.set_period2(true);
  const Status s = Admit(v1::TRACE, request);
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(s.message(), HasSubstr("orbits of period up to 2"));
}

TEST(JobCost, ARegionGridIsCountedWithoutOverflow) {
  const JobCost cost = RegionCost(10001, 10001);
  EXPECT_NEAR(cost.seconds.amount, 10001.0 * 10001 * 5e-5, 1e-3);
  EXPECT_TRUE(std::isfinite(cost.memory_bytes.amount));
}

TEST(JobCost, CheckCostNamesTheFirstLimitExceeded) {
  JobCost cost;
  cost.seconds = {10, "ten"};
  cost.result_bytes = {2e9, "two GB"};
  KindLimits limits;
  limits.max_seconds = 100;
  limits.max_result_bytes = 1'000'000'000;
  const Status s = CheckCost(cost, limits, "sweep");
  EXPECT_EQ(s.code(), StatusCode::kResourceExhausted);
  EXPECT_EQ(s.message(),
            "two GB: about 2.0 GB of results, above the limit of 1.0 GB (max_result_bytes of "
            "sweep jobs)");
  limits.max_result_bytes = 0;  // no limit
  EXPECT_TRUE(CheckCost(cost, limits, "sweep").ok());
  cost.seconds.amount = std::numeric_limits<double>::infinity();
  EXPECT_EQ(CheckCost(cost, limits, "sweep").code(), StatusCode::kResourceExhausted);
}

}  // namespace
}  // namespace drillbif::jobs
