// The REST gateway's pure request decoding (server/rest_request.h): routing with its 404 and 405
// errors, the path variable and the query or body bound into the route's request message, and
// the X-Server-Timeout header. The gateway answers the same through HTTP (rest_gateway_test).
#include "server/rest_request.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <string>

#include "drillbif/v1/service.pb.h"
#include "google/longrunning/operations.pb.h"

namespace drillbif::server {
namespace {

using ::testing::HasSubstr;

StatusOr<DecodedRestRequest> Decode(std::string_view method, std::string_view raw_target,
                                    std::string_view body = "") {
  StatusOr<RequestTarget> target = ParseRequestTarget(raw_target);
  if (!target.ok()) return target.status();
  return DecodeRestRequest(method, *target, body);
}

TEST(DecodeRestRequest, BindsThePathNameAndTheQueryIntoTheRoutesRequest) {
  StatusOr<DecodedRestRequest> decoded =
      Decode("GET", "/v1/operations/abc:result?page_size=5&pageToken=t%3D");
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_EQ(decoded->route, kGetResult);
  EXPECT_EQ(decoded->name, "operations/abc");
  const auto* request = dynamic_cast<const v1::GetResultRequest*>(decoded->request.get());
  ASSERT_NE(request, nullptr);
  EXPECT_EQ(request->name(), "operations/abc");
  EXPECT_EQ(request->page_size(), 5);
  EXPECT_EQ(request->page_token(), "t=");
}

TEST(DecodeRestRequest, ParsesTheBodyOfASubmitAndTreatsABlankBodyAsEmpty) {
  StatusOr<DecodedRestRequest> decoded =
      Decode("POST", "/v1/jobs:simulate", R"({"request": {"samplePeriods": 100}})");
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  const auto* request = dynamic_cast<const v1::SubmitSimulateRequest*>(decoded->request.get());
  ASSERT_NE(request, nullptr);
  EXPECT_EQ(request->request().sample_periods(), 100);

  StatusOr<DecodedRestRequest> blank = Decode("POST", "/v1/operations/x:cancel", " \r\n");
  ASSERT_TRUE(blank.ok()) << blank.status().ToString();
  EXPECT_EQ(blank->route, kCancelOperation);
  EXPECT_EQ(
      dynamic_cast<const google::longrunning::CancelOperationRequest&>(*blank->request).name(),
      "operations/x");
}

TEST(DecodeRestRequest, RefusesWithTheGatewaysCodesAndNamesThePartAtFault) {
  StatusOr<DecodedRestRequest> unknown = Decode("GET", "/v2/nothing");
  EXPECT_EQ(unknown.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(unknown.status().message(), HasSubstr("no route for GET /v2/nothing"));

  StatusOr<DecodedRestRequest> wrong_method = Decode("PUT", "/v1/jobs:sweep");
  EXPECT_EQ(wrong_method.status().code(), StatusCode::kUnimplemented);
  EXPECT_THAT(wrong_method.status().message(), HasSubstr("method PUT is not served"));

  StatusOr<DecodedRestRequest> misspelt =
      Decode("POST", "/v1/jobs:simulate", R"({"request": {"samplePeriod": 100}})");
  EXPECT_EQ(misspelt.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(misspelt.status().message(), HasSubstr("body: not a valid"));

  StatusOr<DecodedRestRequest> query_on_body = Decode("POST", "/v1/jobs:simulate?x=1", "{}");
  EXPECT_THAT(query_on_body.status().message(), HasSubstr("query parameters"));

  StatusOr<DecodedRestRequest> other_name =
      Decode("POST", "/v1/operations/a:cancel", R"({"name": "operations/b"})");
  EXPECT_EQ(other_name.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(other_name.status().message(), HasSubstr("differs from the path's"));
}

TEST(DecodeRestRequest, MetricsBuildsNoMessage) {
  StatusOr<DecodedRestRequest> decoded = Decode("GET", "/metrics");
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_EQ(decoded->route, kMetrics);
  EXPECT_EQ(decoded->request, nullptr);
}

TEST(ParseServerTimeout, AcceptsPositiveSecondsCappedAndRefusesTheRest) {
  EXPECT_EQ(*ParseServerTimeout("2.5"), 2.5);
  EXPECT_EQ(*ParseServerTimeout("1e9"), kMaxServerTimeoutSeconds);
  const std::string refused[] = {"", "0", "-1", "nan", "inf", "5s", std::string("5\0", 2)};
  for (const std::string& bad : refused) {
    StatusOr<double> seconds = ParseServerTimeout(bad);
    EXPECT_EQ(seconds.status().code(), StatusCode::kInvalidArgument) << bad;
    EXPECT_THAT(seconds.status().message(), HasSubstr("X-Server-Timeout")) << bad;
  }
}

}  // namespace
}  // namespace drillbif::server
