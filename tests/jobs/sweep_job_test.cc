// The sweep job (SweepRequest -> engine sweep -> SweepResult): both directions, continuity on
// several threads and explicit chunks (each value's start), invalid requests as INVALID_ARGUMENT
// naming the field, and the cost refused before running.
#include "jobs/sweep_job.h"

#include <gmock/gmock.h>
#include <google/protobuf/util/message_differencer.h>
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

// One direction on 2 and 4 threads: the same result as on 1 thread (the engine is deterministic:
// equal fields, wall time aside), each value but the first FROM_PREVIOUS_VALUE with the
// request's transient. The grid crosses the period doubling at b = 0.110.
TEST(RunSweep, MoreThreadsGiveTheOneThreadSweepValueAfterValue) {
  v1::SweepRequest request = SmallSweep();
  request.set_min(0.09);
  request.set_max(0.13);
  request.set_steps(12);
  const StatusOr<v1::SweepResult> one = RunSweep(request);
  ASSERT_TRUE(one.ok()) << one.status().ToString();
  ASSERT_EQ(one->up_size(), 12);
  for (int i = 0; i < 12; ++i) {
    EXPECT_EQ(one->up(i).start(),
              i == 0 ? v1::SweepPoint::FROM_INITIAL_STATE : v1::SweepPoint::FROM_PREVIOUS_VALUE)
        << i;
    EXPECT_EQ(one->up(i).transient_periods(), 50) << i;
  }
  google::protobuf::util::MessageDifferencer differ;
  differ.IgnoreField(v1::SweepResult::descriptor()->FindFieldByName("wall_seconds"));
  std::string diff;
  differ.ReportDifferencesToString(&diff);
  for (int threads : {2, 4}) {
    request.set_threads(threads);
    const StatusOr<v1::SweepResult> many = RunSweep(request);
    ASSERT_TRUE(many.ok()) << many.status().ToString();
    EXPECT_TRUE(differ.Compare(*many, *one)) << threads << " threads: " << diff.substr(0, 2000);
  }
}

// chunks = 3 over 12 values: pieces from 0, 4 and 8, each starting FROM_INITIAL_STATE, the later
// two with 4 times the transient; the periods count them.
TEST(RunSweep, ExplicitChunksMarkEachChunksFirstValue) {
  v1::SweepRequest request = SmallSweep();
  request.set_min(0.09);
  request.set_max(0.13);
  request.set_steps(12);
  request.set_threads(3);
  request.set_chunks(3);
  const StatusOr<v1::SweepResult> result = RunSweep(request);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  ASSERT_EQ(result->up_size(), 12);
  for (int i = 0; i < 12; ++i) {
    const bool chunk_start = i % 4 == 0;
    EXPECT_EQ(result->up(i).start(), chunk_start ? v1::SweepPoint::FROM_INITIAL_STATE
                                                 : v1::SweepPoint::FROM_PREVIOUS_VALUE)
        << i;
    EXPECT_EQ(result->up(i).transient_periods(), chunk_start && i > 0 ? 200 : 50) << i;
  }
  EXPECT_EQ(result->periods_total(), 12 * (50 + 5) + 2 * 3 * 50);
}

TEST(RunSweep, ChunksOutsideOneToStepsAreInvalidArgumentNamingThem) {
  for (int chunks : {0, -1, 6}) {
    v1::SweepRequest request = SmallSweep();  // 5 steps
    request.set_chunks(chunks);
    const StatusOr<v1::SweepResult> result = RunSweep(request);
    ASSERT_FALSE(result.ok()) << chunks;
    EXPECT_EQ(result.status().code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(result.status().message(), HasSubstr("chunks"));
  }
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
