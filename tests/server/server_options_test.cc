// ServerOptions: the job limits set by --job-limit KIND.NAME=VALUE and what Validate refuses.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "jobs/trace_task_codec.h"
#include "server/server.h"
#include "server/worker_pool.h"

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

TEST(ServerOptions, AStoreUriWithAPasswordAndRolesWithoutAStoreAreRefused) {
  ServerOptions options;
  options.store_uri = "postgresql://drillbif@db:5432/drillbif?sslmode=require";
  EXPECT_TRUE(options.Validate().ok());
  for (const char* uri :
       {"postgresql://drillbif:s3cret@db/drillbif", "postgres://u:p@[::1]:5432/d",
        "postgresql://u@db/d?password=s3cret", "host=db user=u password=s3cret dbname=d"}) {
    options.store_uri = uri;
    const Status s = options.Validate();
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << uri;
    EXPECT_THAT(s.message(), HasSubstr("must not hold the password")) << uri;
  }
  options = ServerOptions();
  options.role = ServerOptions::Role::kWorker;
  EXPECT_THAT(options.Validate().message(), HasSubstr("role: api and worker processes share"));
  options.store_uri = "postgresql://u@db/d";
  EXPECT_TRUE(options.Validate().ok());
  options.lease_ms = 100;
  EXPECT_THAT(options.Validate().message(), HasSubstr("lease_ms: must be >= 300"));
}

TEST(ServerOptions, TraceFanOutOutOfRangeIsRefusedNamingIt) {
  ServerOptions options;
  options.store_uri = "postgresql://u@db/d";
  for (const int fan_out : {0, 32, kMaxTraceFanOut}) {
    options.trace_fan_out = fan_out;
    EXPECT_TRUE(options.Validate().ok()) << fan_out;
  }
  for (const int fan_out : {-1, kMaxTraceFanOut + 1}) {
    options.trace_fan_out = fan_out;
    EXPECT_THAT(options.Validate().message(), HasSubstr("trace_fan_out: must be 0 (off) .. "))
        << fan_out;
  }
  WorkerPoolOptions pool;
  pool.trace_fan_out = -1;
  EXPECT_THAT(pool.Validate().message(), HasSubstr("trace_fan_out"));
}

TEST(ServerOptions, TraceFanOutBatchOutOfRangeIsRefusedNamingIt) {
  ServerOptions options;
  options.store_uri = "postgresql://u@db/d";
  options.trace_fan_out = 32;
  for (const int batch : {1, 4, jobs::kMaxTraceTaskBatch}) {
    options.trace_fan_out_batch = batch;
    EXPECT_TRUE(options.Validate().ok()) << batch;
  }
  for (const int batch : {0, -3, jobs::kMaxTraceTaskBatch + 1}) {
    options.trace_fan_out_batch = batch;
    EXPECT_THAT(options.Validate().message(), HasSubstr("trace_fan_out_batch: must be 1 .. 64"))
        << batch;
    WorkerPoolOptions pool;
    pool.trace_fan_out_batch = batch;
    EXPECT_THAT(pool.Validate().message(), HasSubstr("trace_fan_out_batch"));
  }
}

}  // namespace
}  // namespace drillbif::server
