// ServerOptions: the job limits set by --job-limit KIND.NAME=VALUE and what Validate refuses.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "server/server.h"

namespace drillbif::server {
namespace {

using ::testing::HasSubstr;

TEST(ServerOptions, JobLimitsDefaultToTheRegistryAndCanBeSetOneByOne) {
  ServerOptions options;
  const jobs::JobKindSpec& trace = *jobs::FindKind("trace");
  EXPECT_EQ(options.LimitsOf(trace).max_seconds, trace.default_limits.max_seconds);
  ASSERT_TRUE(options.SetJobLimit("trace.seconds=3600").ok());
  ASSERT_TRUE(options.SetJobLimit("trace.result-bytes=1e9").ok());
  EXPECT_EQ(options.LimitsOf(trace).max_seconds, 3600);
  EXPECT_EQ(options.LimitsOf(trace).max_result_bytes, 1'000'000'000);
  // The others keep their defaults.
  EXPECT_EQ(options.LimitsOf(trace).max_memory_bytes, trace.default_limits.max_memory_bytes);
  const jobs::JobKindSpec& sweep = *jobs::FindKind("sweep");
  EXPECT_EQ(options.LimitsOf(sweep).max_seconds, sweep.default_limits.max_seconds);
  EXPECT_TRUE(options.Validate().ok());
}

TEST(ServerOptions, BadJobLimitsAreRefusedSayingWhy) {
  ServerOptions options;
  EXPECT_THAT(options.SetJobLimit("trace").message(), HasSubstr("expected KIND.NAME=VALUE"));
  EXPECT_THAT(options.SetJobLimit("tracer.seconds=1").message(), HasSubstr("unknown job kind"));
  EXPECT_THAT(options.SetJobLimit("trace.minutes=1").message(), HasSubstr("unknown limit"));
  EXPECT_THAT(options.SetJobLimit("trace.seconds=-1").message(), HasSubstr("a number in"));
  EXPECT_THAT(options.SetJobLimit("trace.seconds=nan").message(), HasSubstr("a number in"));
  EXPECT_THAT(options.SetJobLimit("trace.result-bytes=1e300").message(), HasSubstr("a number in"));
  EXPECT_THAT(options.SetJobLimit("trace.seconds=12x").message(), HasSubstr("a number in"));
  options.job_limits["nonsense"] = {};
  EXPECT_THAT(options.Validate().message(), HasSubstr("job_limits: unknown job kind 'nonsense'"));
}

}  // namespace
}  // namespace drillbif::server
