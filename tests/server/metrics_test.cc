// The hand-written Prometheus exposition (server/metrics.h) and the REST gateway's status and
// error mappings (server/rest_gateway.h), without a server: exact text for known events.
#include "server/metrics.h"

#include <gmock/gmock.h>
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>

#include "drillbif/v1/service.pb.h"
#include "google/rpc/status.pb.h"
#include "server/rest_gateway.h"

namespace drillbif::server {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

TEST(Metrics, RendersTheSnapshotAsGaugesAndCounters) {
  Metrics metrics;
  MetricsSnapshot snapshot;
  snapshot.stats.jobs_by_state = {3, 1, 10, 2, 4};
  snapshot.stats.queue_depth = 2;
  snapshot.stats.cache_hits_total = 7;
  snapshot.engine_runs = 12;
  snapshot.watchers = 5;
  const std::string text = metrics.Render(snapshot);
  EXPECT_THAT(text, HasSubstr("# HELP drillbif_jobs Jobs in the store by state.\n"
                              "# TYPE drillbif_jobs gauge\n"
                              "drillbif_jobs{state=\"QUEUED\"} 3\n"
                              "drillbif_jobs{state=\"RUNNING\"} 1\n"
                              "drillbif_jobs{state=\"SUCCEEDED\"} 10\n"
                              "drillbif_jobs{state=\"FAILED\"} 2\n"
                              "drillbif_jobs{state=\"CANCELLED\"} 4\n"));
  EXPECT_THAT(text, HasSubstr("# TYPE drillbif_queue_depth gauge\ndrillbif_queue_depth 2\n"));
  EXPECT_THAT(text,
              HasSubstr("# TYPE drillbif_cache_hits_total counter\ndrillbif_cache_hits_total 7\n"));
  EXPECT_THAT(text, HasSubstr("# TYPE drillbif_engine_runs_total counter\n"
                              "drillbif_engine_runs_total 12\n"));
  EXPECT_THAT(text, HasSubstr("drillbif_watchers 5\n"));
  // Families with no event yet are declared, without samples.
  EXPECT_THAT(text, HasSubstr("# TYPE drillbif_job_duration_seconds histogram\n"));
  EXPECT_THAT(text, Not(HasSubstr("drillbif_job_duration_seconds_bucket")));
  EXPECT_EQ(text.back(), '\n');
}

TEST(Metrics, JobDurationsAreACumulativeHistogramByKindAndOutcome) {
  MetricsOptions options;
  options.job_duration_buckets = {0.1, 1, 10};
  ASSERT_TRUE(options.Validate().ok());
  Metrics metrics(options);
  metrics.ObserveJob("sweep", "succeeded", 0.05);
  metrics.ObserveJob("sweep", "succeeded", 0.1);  // On a bound: in that bucket ("le").
  metrics.ObserveJob("sweep", "succeeded", 5);
  metrics.ObserveJob("sweep", "succeeded", 50);
  metrics.ObserveJob("sweep", "cancelled", 0.5);
  const std::string text = metrics.Render({});
  EXPECT_THAT(
      text,
      HasSubstr(
          "drillbif_job_duration_seconds_bucket{kind=\"sweep\",outcome=\"succeeded\",le=\"0.1\"} "
          "2\n"
          "drillbif_job_duration_seconds_bucket{kind=\"sweep\",outcome=\"succeeded\",le=\"1\"} 2\n"
          "drillbif_job_duration_seconds_bucket{kind=\"sweep\",outcome=\"succeeded\",le=\"10\"} 3\n"
          "drillbif_job_duration_seconds_bucket{kind=\"sweep\",outcome=\"succeeded\",le=\"+Inf\"} "
          "4\n"
          "drillbif_job_duration_seconds_sum{kind=\"sweep\",outcome=\"succeeded\"} 55.15\n"
          "drillbif_job_duration_seconds_count{kind=\"sweep\",outcome=\"succeeded\"} 4\n"));
  EXPECT_THAT(
      text,
      HasSubstr(
          "drillbif_job_duration_seconds_bucket{kind=\"sweep\",outcome=\"cancelled\",le=\"1\"} "
          "1\n"));
}

TEST(Metrics, CountsRequestsByLabels) {
  Metrics metrics;
  metrics.CountHttpRequest("POST", "/v1/jobs:sweep", 200);
  metrics.CountHttpRequest("POST", "/v1/jobs:sweep", 200);
  metrics.CountHttpRequest("POST", "/v1/jobs:sweep", 400);
  metrics.CountGrpcRequest("/drillbif.v1.Jobs/SubmitSweep", 0);
  metrics.CountGrpcRequest("/drillbif.v1.Jobs/SubmitSweep", 3);
  const std::string text = metrics.Render({});
  EXPECT_THAT(text, HasSubstr("drillbif_http_requests_total{method=\"POST\",route=\"/v1/"
                              "jobs:sweep\",code=\"200\"} 2\n"));
  EXPECT_THAT(text, HasSubstr("drillbif_http_requests_total{method=\"POST\",route=\"/v1/"
                              "jobs:sweep\",code=\"400\"} 1\n"));
  EXPECT_THAT(text, HasSubstr("drillbif_grpc_requests_total{method=\"/drillbif.v1.Jobs/"
                              "SubmitSweep\",code=\"INVALID_ARGUMENT\"} 1\n"));
  EXPECT_THAT(text, HasSubstr("code=\"OK\"} 1\n"));
}

TEST(Metrics, EscapesLabelValuesAndFormatsSampleValues) {
  EXPECT_EQ(EscapeLabelValue("a\"b\\c\nd"), "a\\\"b\\\\c\\nd");
  EXPECT_EQ(FormatSampleValue(3), "3");
  EXPECT_EQ(FormatSampleValue(-2), "-2");
  EXPECT_EQ(FormatSampleValue(0.1), "0.1");
  EXPECT_EQ(FormatSampleValue(1e300), "1e+300");
  EXPECT_EQ(FormatSampleValue(std::numeric_limits<double>::infinity()), "+Inf");
  EXPECT_EQ(FormatSampleValue(-std::numeric_limits<double>::infinity()), "-Inf");
  EXPECT_EQ(FormatSampleValue(std::nan("")), "NaN");
  const double third = 1.0 / 3.0;
  EXPECT_EQ(std::stod(FormatSampleValue(third)), third) << "reads back exactly";
  Metrics metrics;
  metrics.CountHttpRequest("GET", "odd\"route", 200);
  EXPECT_THAT(metrics.Render({}), HasSubstr("route=\"odd\\\"route\""));
}

TEST(MetricsOptions, ValidateRefusesBadBuckets) {
  EXPECT_TRUE(MetricsOptions().Validate().ok());
  MetricsOptions options;
  options.job_duration_buckets = {};
  EXPECT_THAT(options.Validate().message(), HasSubstr("job_duration_buckets"));
  options.job_duration_buckets = {1, 1};
  EXPECT_THAT(options.Validate().message(), HasSubstr("job_duration_buckets[1]"));
  options.job_duration_buckets = {0};
  EXPECT_FALSE(options.Validate().ok());
  options.job_duration_buckets = {1, std::numeric_limits<double>::infinity()};
  EXPECT_FALSE(options.Validate().ok());
}

TEST(RestMapping, HttpStatusOfEachGrpcCode) {
  using grpc::StatusCode;
  EXPECT_EQ(HttpStatusOf(StatusCode::OK), 200);
  EXPECT_EQ(HttpStatusOf(StatusCode::INVALID_ARGUMENT), 400);
  EXPECT_EQ(HttpStatusOf(StatusCode::FAILED_PRECONDITION), 400);
  EXPECT_EQ(HttpStatusOf(StatusCode::UNAUTHENTICATED), 401);
  EXPECT_EQ(HttpStatusOf(StatusCode::PERMISSION_DENIED), 403);
  EXPECT_EQ(HttpStatusOf(StatusCode::NOT_FOUND), 404);
  EXPECT_EQ(HttpStatusOf(StatusCode::ALREADY_EXISTS), 409);
  EXPECT_EQ(HttpStatusOf(StatusCode::ABORTED), 409);
  EXPECT_EQ(HttpStatusOf(StatusCode::RESOURCE_EXHAUSTED), 429);
  EXPECT_EQ(HttpStatusOf(StatusCode::UNAVAILABLE), 503);
  EXPECT_EQ(HttpStatusOf(StatusCode::DEADLINE_EXCEEDED), 504);
  EXPECT_EQ(HttpStatusOf(StatusCode::INTERNAL), 500);
  EXPECT_EQ(HttpStatusOf(StatusCode::UNKNOWN), 500);
  EXPECT_EQ(HttpStatusOf(StatusCode::DATA_LOSS), 500);
  EXPECT_STREQ(GrpcCodeName(16), "UNAUTHENTICATED");
  EXPECT_STREQ(GrpcCodeName(17), "UNKNOWN");
}

TEST(RestMapping, ErrorJsonHasCodeNameMessageAndDetails) {
  EXPECT_EQ(ErrorJson(grpc::Status(grpc::StatusCode::NOT_FOUND, "no \"such\" job\n")),
            R"({"code":"NOT_FOUND","message":"no \"such\" job\n","details":[]})");
  // Details of a google.rpc.Status carried by the status, in the Any JSON mapping.
  google::rpc::Status rich;
  rich.set_code(3);
  v1::JobMetadata detail;
  detail.set_name("operations/x");
  rich.add_details()->PackFrom(detail);
  const std::string json =
      ErrorJson(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "bad", rich.SerializeAsString()));
  EXPECT_EQ(
      json,
      R"({"code":"INVALID_ARGUMENT","message":"bad","details":[{"@type":"type.googleapis.com/drillbif.v1.JobMetadata","name":"operations/x"}]})");
  google::protobuf::Struct parsed;
  EXPECT_TRUE(google::protobuf::util::JsonStringToMessage(json, &parsed).ok());
}

}  // namespace
}  // namespace drillbif::server
