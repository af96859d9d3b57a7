// CORS on the REST gateway (server/cors.h, RestOptions::cors_origins): a real server on
// 127.0.0.1 with port 0 (tests/support/test_server.h) called with httplib as a browser would:
// preflights (OPTIONS with Origin and Access-Control-Request-Method) and actual requests from an
// allowed origin, another origin, "*" mode and no CORS at all; hostile Origin values; and the
// flag's validation, in the library and in the drillbif-server binary.
#include "server/cors.h"

#include <gmock/gmock.h>
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <cstdio>
#include <string>
#include <vector>

#include "server/server.h"
#include "support/small_requests.h"
#include "support/temp_dir.h"
#include "support/test_server.h"

// Last: httplib.h includes <resolv.h>, whose macro _res breaks Eigen's headers.
#include <httplib.h>

namespace drillbif::server {
namespace {

using ::testing::HasSubstr;

constexpr char kToken[] = "cors-test-token";
constexpr char kDash[] = "https://dash.example.com";
constexpr char kLocal[] = "http://127.0.0.1:8080";
constexpr char kOther[] = "https://evil.example.com";
// Request bodies above this are refused by the server itself (413) before the gateway sees them.
constexpr int kMaxRequestBytes = 64 * 1024;

// A server with a token and `origins` as --cors-origins.
ServerOptions OptionsWith(std::vector<std::string> origins) {
  ServerOptions options;
  options.token = kToken;
  options.workers = 1;
  options.max_request_bytes = kMaxRequestBytes;
  options.http.cors_origins = std::move(origins);
  return options;
}

// The names of the response's Access-Control-* headers.
std::vector<std::string> CorsHeaderNames(const httplib::Response& response) {
  std::vector<std::string> names;
  for (const auto& [name, value] : response.headers) {
    if (name.rfind("Access-Control-", 0) == 0) names.push_back(name);
  }
  return names;
}

// Expects a JSON error body with gRPC code name `code`; returns its message.
std::string ErrorMessage(const httplib::Response& response, const char* code) {
  google::protobuf::Struct body;
  EXPECT_TRUE(google::protobuf::util::JsonStringToMessage(response.body, &body).ok())
      << response.body;
  if (body.fields().count("code") == 0 || body.fields().count("message") == 0) {
    ADD_FAILURE() << "not an error body: " << response.body;
    return "";
  }
  EXPECT_EQ(body.fields().at("code").string_value(), code) << response.body;
  return body.fields().at("message").string_value();
}

class CorsTest : public ::testing::Test {
 protected:
  explicit CorsTest(std::vector<std::string> origins = {kDash, kLocal})
      : server_(OptionsWith(std::move(origins)), "drillbif_cors") {}

  void SetUp() override { ASSERT_TRUE(server_.ok()); }

  httplib::Client Client() {
    httplib::Client client("127.0.0.1", server_.server().http_port());
    client.set_read_timeout(std::chrono::seconds(30));
    return client;
  }

  // A browser's preflight for `method` on `path` from `origin`.
  httplib::Result Preflight(const std::string& path, const std::string& origin,
                            const std::string& method, const std::string& headers = "") {
    httplib::Headers sent = {{"Origin", origin}, {"Access-Control-Request-Method", method}};
    if (!headers.empty()) sent.emplace("Access-Control-Request-Headers", headers);
    httplib::Result result = Client().Options(path, sent);
    EXPECT_TRUE(result) << "OPTIONS " << path;
    return result;
  }

  // GET with the token (when `token`) and Origin `origin` (when not empty).
  httplib::Result Get(const std::string& path, const std::string& origin, bool token = true) {
    httplib::Headers sent;
    if (!origin.empty()) sent.emplace("Origin", origin);
    if (token) sent.emplace("Authorization", std::string("Bearer ") + kToken);
    httplib::Result result = Client().Get(path, sent);
    EXPECT_TRUE(result) << "GET " << path;
    return result;
  }

  testing::TestServer server_;
};

TEST_F(CorsTest, PreflightFromAnAllowedOriginIsAnsweredWithoutAToken) {
  httplib::Result result =
      Preflight("/v1/operations/abc", kLocal, "DELETE", "authorization, content-type");
  ASSERT_TRUE(result);
  EXPECT_EQ(result->status, 204) << result->body;
  EXPECT_EQ(result->body, "");
  EXPECT_EQ(result->get_header_value("Access-Control-Allow-Origin"), kLocal);
  // Both methods served on operations/**, nothing else.
  EXPECT_EQ(result->get_header_value("Access-Control-Allow-Methods"), "GET, DELETE");
  const std::string allowed = result->get_header_value("Access-Control-Allow-Headers");
  EXPECT_THAT(allowed, HasSubstr("authorization"));
  EXPECT_THAT(allowed, HasSubstr("content-type"));
  EXPECT_EQ(result->get_header_value("Access-Control-Max-Age"), "600");
  EXPECT_EQ(result->get_header_value("Vary"), "Origin");
  // Credentials are never allowed (the token travels in Authorization, set by the script).
  EXPECT_FALSE(result->has_header("Access-Control-Allow-Credentials"));

  httplib::Result submit = Preflight("/v1/jobs:sweep", kDash, "POST", "content-type");
  ASSERT_TRUE(submit);
  EXPECT_EQ(submit->status, 204);
  EXPECT_EQ(submit->get_header_value("Access-Control-Allow-Origin"), kDash);
  EXPECT_EQ(submit->get_header_value("Access-Control-Allow-Methods"), "POST");
}

TEST_F(CorsTest, PreflightFromAnotherOriginIsForbiddenWithoutCorsHeaders) {
  httplib::Result result = Preflight("/v1/jobs:sweep", kOther, "POST");
  ASSERT_TRUE(result);
  EXPECT_EQ(result->status, 403);
  EXPECT_EQ(result->get_header_value("Content-Type"), "application/json");
  EXPECT_THAT(ErrorMessage(*result, "PERMISSION_DENIED"), HasSubstr(kOther));
  EXPECT_THAT(CorsHeaderNames(*result), ::testing::IsEmpty());
}

TEST_F(CorsTest, PreflightOnAnUnknownPathIsNotFound) {
  httplib::Result result = Preflight("/v1/nothing-here", kDash, "GET");
  ASSERT_TRUE(result);
  EXPECT_EQ(result->status, 404);
  ErrorMessage(*result, "NOT_FOUND");
}

TEST_F(CorsTest, OptionsWithoutPreflightHeadersIsNotAPreflight) {
  // No Access-Control-Request-Method: not a browser's preflight, so not answered as one (and
  // nothing else is served with OPTIONS).
  httplib::Result result = Client().Options("/v1/operations", {{"Origin", kDash}});
  ASSERT_TRUE(result);
  EXPECT_EQ(result->status, 405);
}

TEST_F(CorsTest, ActualRequestsFromAnAllowedOriginCarryTheHeaders) {
  httplib::Result list = Get("/v1/operations", kDash);
  ASSERT_TRUE(list);
  EXPECT_EQ(list->status, 200) << list->body;
  EXPECT_EQ(list->get_header_value("Access-Control-Allow-Origin"), kDash);
  EXPECT_EQ(list->get_header_value("Vary"), "Origin");
  EXPECT_THAT(list->get_header_value("Access-Control-Expose-Headers"), HasSubstr("Retry-After"));

  v1::SubmitSweepRequest submit;
  *submit.mutable_request() = testing::SmallSweep(0.1, 3);
  std::string body;
  ASSERT_TRUE(google::protobuf::util::MessageToJsonString(submit, &body).ok());
  httplib::Result posted = Client().Post(
      "/v1/jobs:sweep", {{"Origin", kLocal}, {"Authorization", std::string("Bearer ") + kToken}},
      body, "application/json");
  ASSERT_TRUE(posted);
  EXPECT_EQ(posted->status, 200) << posted->body;
  EXPECT_EQ(posted->get_header_value("Access-Control-Allow-Origin"), kLocal);

  // The finished job's event stream: the answer's head carries the headers too.
  google::longrunning::Operation op;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(posted->body, &op).ok());
  server_.WaitDone(op.name(), kToken);
  httplib::Result watch = Get("/v1/" + op.name() + ":watch", kDash);
  ASSERT_TRUE(watch);
  EXPECT_EQ(watch->status, 200) << watch->body;
  EXPECT_EQ(watch->get_header_value("Content-Type"), "text/event-stream");
  EXPECT_EQ(watch->get_header_value("Access-Control-Allow-Origin"), kDash);
}

TEST_F(CorsTest, ErrorsToAnAllowedOriginCarryTheHeaders) {
  // The gateway's errors: no token (401), an unknown operation (404).
  httplib::Result unauthenticated = Get("/v1/operations", kDash, /*token=*/false);
  ASSERT_TRUE(unauthenticated);
  EXPECT_EQ(unauthenticated->status, 401);
  EXPECT_EQ(unauthenticated->get_header_value("Access-Control-Allow-Origin"), kDash);
  httplib::Result unknown = Get("/v1/operations/0123456789abcdef0123456789abcdef", kDash);
  ASSERT_TRUE(unknown);
  EXPECT_EQ(unknown->status, 404);
  EXPECT_EQ(unknown->get_header_value("Access-Control-Allow-Origin"), kDash);
  // The HTTP server's own: a body over the limit (413), refused before the gateway sees it.
  httplib::Result large = Client().Post(
      "/v1/jobs:sweep", {{"Origin", kDash}, {"Authorization", std::string("Bearer ") + kToken}},
      std::string(2 * kMaxRequestBytes, ' '), "application/json");
  ASSERT_TRUE(large);
  EXPECT_EQ(large->status, 413);
  EXPECT_EQ(large->get_header_value("Access-Control-Allow-Origin"), kDash);
}

TEST_F(CorsTest, RequestsFromAnotherOriginAreServedWithoutCorsHeaders) {
  // The browser then hides the answer from the script; a client that is no browser still works.
  httplib::Result result = Get("/v1/operations", kOther);
  ASSERT_TRUE(result);
  EXPECT_EQ(result->status, 200) << result->body;
  EXPECT_THAT(CorsHeaderNames(*result), ::testing::IsEmpty());
  httplib::Result no_origin = Get("/v1/operations", "");
  ASSERT_TRUE(no_origin);
  EXPECT_EQ(no_origin->status, 200);
  EXPECT_THAT(CorsHeaderNames(*no_origin), ::testing::IsEmpty());
}

TEST_F(CorsTest, OnlyAnExactOriginIsEverEchoed) {
  // Near misses: case, a trailing slash, a longer host, another scheme, the allowed origin
  // followed by 6 KB or by bytes that are not UTF-8 and a control character.
  const std::vector<std::string> near = {"HTTPS://DASH.EXAMPLE.COM",
                                         std::string(kDash) + "/",
                                         std::string(kDash) + ".evil.com",
                                         "http://dash.example.com",
                                         std::string(kDash) + std::string(6000, 'a'),
                                         std::string(kDash) + "\xff\xfe\x01"};
  for (const std::string& origin : near) {
    SCOPED_TRACE(origin.substr(0, 60));
    httplib::Result actual = Get("/v1/operations", origin);
    ASSERT_TRUE(actual);
    EXPECT_EQ(actual->status, 200);
    EXPECT_THAT(CorsHeaderNames(*actual), ::testing::IsEmpty());
    httplib::Result preflight = Preflight("/v1/operations", origin, "GET");
    ASSERT_TRUE(preflight);
    EXPECT_EQ(preflight->status, 403);
    EXPECT_THAT(CorsHeaderNames(*preflight), ::testing::IsEmpty());
    // The error names the origin cut to a bounded echo (the 6 KB one is not sent back whole),
    // made valid UTF-8 without control characters: still a JSON body.
    EXPECT_LT(preflight->body.size(), 300u);
    ErrorMessage(*preflight, "PERMISSION_DENIED");
  }
  // The server still serves.
  httplib::Result after = Preflight("/v1/operations", kDash, "GET");
  ASSERT_TRUE(after);
  EXPECT_EQ(after->status, 204);
}

class CorsAnyOriginTest : public CorsTest {
 protected:
  CorsAnyOriginTest() : CorsTest({"*"}) {}
};

TEST_F(CorsAnyOriginTest, EveryOriginGetsAStar) {
  httplib::Result preflight = Preflight("/v1/jobs:trace", kOther, "POST", "authorization");
  ASSERT_TRUE(preflight);
  EXPECT_EQ(preflight->status, 204);
  EXPECT_EQ(preflight->get_header_value("Access-Control-Allow-Origin"), "*");
  EXPECT_THAT(preflight->get_header_value("Access-Control-Allow-Headers"),
              HasSubstr("authorization"));
  EXPECT_FALSE(preflight->has_header("Access-Control-Allow-Credentials"));
  httplib::Result actual = Get("/v1/operations", kOther);
  ASSERT_TRUE(actual);
  EXPECT_EQ(actual->status, 200);
  EXPECT_EQ(actual->get_header_value("Access-Control-Allow-Origin"), "*");
}

class CorsOffTest : public CorsTest {
 protected:
  CorsOffTest() : CorsTest({}) {}
};

TEST_F(CorsOffTest, NoFlagSendsNoCorsHeaderAndServesNoOptions) {
  httplib::Result actual = Get("/v1/operations", kDash);
  ASSERT_TRUE(actual);
  EXPECT_EQ(actual->status, 200);
  EXPECT_THAT(CorsHeaderNames(*actual), ::testing::IsEmpty());
  EXPECT_FALSE(actual->has_header("Vary"));
  httplib::Result preflight = Preflight("/v1/operations", kDash, "GET");
  ASSERT_TRUE(preflight);
  EXPECT_EQ(preflight->status, 405);
  EXPECT_THAT(CorsHeaderNames(*preflight), ::testing::IsEmpty());
}

TEST(CorsOrigins, ValidOriginsAreAccepted) {
  for (const std::vector<std::string>& origins : std::vector<std::vector<std::string>>{
           {}, {"*"}, {kDash}, {kDash, kLocal}, {"http://[::1]:3000"}, {"https://a-b.c.d:65535"}}) {
    EXPECT_TRUE(ValidateCorsOrigins(origins).ok()) << ::testing::PrintToString(origins);
  }
}

TEST(CorsOrigins, InvalidOriginsAreRefusedNamingTheFlagAndTheValue) {
  for (const std::string bad :
       {"dash.example.com", "ftp://dash.example.com", "https://dash.example.com/",
        "https://dash.example.com/app", "https://Dash.example.com", "https://user@dash.example.com",
        "https://dash.example.com:0", "https://dash.example.com:65536",
        "https://dash.example.com:", "https://", "null", ""}) {
    const Status s = ValidateCorsOrigins({bad});
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << bad;
    EXPECT_THAT(s.message(), HasSubstr("--cors-origins")) << bad;
    EXPECT_THAT(s.message(), HasSubstr("'" + bad + "'")) << bad;
  }
  // "*" is all origins: listing others beside it says something it does not do.
  EXPECT_THAT(ValidateCorsOrigins({"*", kDash}).message(), HasSubstr("only value"));
}

TEST(CorsOrigins, ServerStartRefusesABadOrigin) {
  testing::TempDir dir("drillbif_cors_start");
  ServerOptions options = OptionsWith({"https://dash.example.com/"});
  options.grpc_port = 0;
  options.http_port = 0;
  options.db_path = dir.path() + "/jobs.db";
  StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
  ASSERT_FALSE(server.ok());
  EXPECT_EQ(server.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(server.status().message(), HasSubstr("--cors-origins"));
}

// DRILLBIF_SERVER_BINARY: server/CMakeLists.txt defines it for this test.
TEST(CorsOrigins, TheBinaryExitsAtStartOnABadOriginNamingTheFlag) {
  testing::TempDir dir("drillbif_cors_binary");
  const std::string command = std::string(DRILLBIF_SERVER_BINARY) +
                              " --grpc-port 0 --http-port 0 --db " + dir.path() +
                              "/jobs.db --cors-origins https://ok.example.com,ftp://bad 2>&1";
  FILE* pipe = popen(command.c_str(), "r");
  ASSERT_NE(pipe, nullptr);
  std::string output;
  char buffer[512];
  while (size_t n = fread(buffer, 1, sizeof(buffer), pipe)) output.append(buffer, n);
  const int status = pclose(pipe);
  ASSERT_TRUE(WIFEXITED(status)) << output;
  EXPECT_EQ(WEXITSTATUS(status), 2) << output;
  EXPECT_THAT(output, HasSubstr("--cors-origins"));
  EXPECT_THAT(output, HasSubstr("ftp://bad"));
}

}  // namespace
}  // namespace drillbif::server
