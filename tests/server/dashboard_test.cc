// The dashboard's static files served by the REST gateway (server/dashboard.h) from a real
// server on 127.0.0.1 with a token: every embedded file is served byte for byte with its
// Content-Type, the CSP and cache headers, without the token; unknown files are 404, methods
// other than GET and HEAD 405; the API routes still need the token. The page itself is tested in
// a browser by web/test/dashboard.test.mjs.
#include "server/dashboard.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <regex>
#include <set>
#include <string>

#include "server/dashboard_files.h"
#include "server/server.h"
#include "support/test_server.h"

// Last: httplib.h includes <resolv.h>, whose macro _res breaks Eigen's headers.
#include <httplib.h>

namespace drillbif::server {
namespace {

using ::testing::HasSubstr;
using ::testing::StartsWith;

constexpr char kToken[] = "dashboard-test-token";

class DashboardTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    ServerOptions options;
    options.token = kToken;
    options.workers = 1;
    server_ = new testing::TestServer(options, "dashboard_test");
  }
  static void TearDownTestSuite() { delete server_; }

  void SetUp() override {
    ASSERT_TRUE(server_ != nullptr && server_->ok());
    http_ = std::make_unique<httplib::Client>("127.0.0.1", server_->server().http_port());
    http_->set_read_timeout(std::chrono::seconds(30));
  }

  // GET without a token; fails the test on a transport error.
  httplib::Result Get(const std::string& path, const httplib::Headers& headers = {}) {
    httplib::Result result = http_->Get(path.c_str(), headers);
    EXPECT_TRUE(result) << "GET " << path << ": " << httplib::to_string(result.error());
    return result;
  }

  static const DashboardFile* FileAt(const std::string& path) {
    for (int i = 0; i < kDashboardFileCount; ++i) {
      if (path == kDashboardFiles[i].path) return &kDashboardFiles[i];
    }
    return nullptr;
  }

  static testing::TestServer* server_;
  std::unique_ptr<httplib::Client> http_;
};

testing::TestServer* DashboardTest::server_ = nullptr;

TEST_F(DashboardTest, RootIsTheIndexPageWithTheCspAndNoToken) {
  httplib::Result result = Get("/");
  ASSERT_TRUE(result);
  EXPECT_EQ(result->status, 200);
  EXPECT_EQ(result->get_header_value("Content-Type"), "text/html; charset=utf-8");
  EXPECT_EQ(result->get_header_value("Content-Security-Policy"), kDashboardCsp);
  EXPECT_THAT(result->get_header_value("Content-Security-Policy"),
              StartsWith("default-src 'self';"));
  EXPECT_EQ(result->get_header_value("X-Content-Type-Options"), "nosniff");
  EXPECT_EQ(result->get_header_value("Cache-Control"), "no-cache");
  EXPECT_FALSE(result->get_header_value("ETag").empty());
  const DashboardFile* index = FileAt("/index.html");
  ASSERT_NE(index, nullptr);
  EXPECT_EQ(result->body, std::string(reinterpret_cast<const char*>(index->data), index->size));
  EXPECT_THAT(result->body, HasSubstr("<!doctype html>"));
}

TEST_F(DashboardTest, EveryEmbeddedFileIsServedWithItsBytesAndType) {
  ASSERT_GT(kDashboardFileCount, 0);
  for (int i = 0; i < kDashboardFileCount; ++i) {
    const DashboardFile& file = kDashboardFiles[i];
    SCOPED_TRACE(file.path);
    httplib::Result result = Get(file.path);
    ASSERT_TRUE(result);
    EXPECT_EQ(result->status, 200);
    EXPECT_EQ(result->body, std::string(reinterpret_cast<const char*>(file.data), file.size));
    EXPECT_EQ(result->get_header_value("Content-Type"), DashboardContentType(file.path));
    EXPECT_NE(DashboardContentType(file.path), "application/octet-stream");
    EXPECT_EQ(result->get_header_value("Content-Security-Policy"), kDashboardCsp);
  }
}

TEST_F(DashboardTest, TheEmbeddedFilesAreTheSourceTreesPage) {
  // Every file of web/src/ is embedded at its name, with the bytes on disk now (the build
  // re-embeds a changed file).
  int files = 0;
  for (const auto& entry :
       std::filesystem::directory_iterator(std::string(DRILLBIF_SOURCE_DIR) + "/web/src")) {
    const std::string path = "/" + entry.path().filename().string();
    SCOPED_TRACE(path);
    ++files;
    const DashboardFile* file = FileAt(path);
    ASSERT_NE(file, nullptr);
    std::ifstream in(entry.path(), std::ios::binary);
    const std::string on_disk((std::istreambuf_iterator<char>(in)), {});
    EXPECT_EQ(std::string(reinterpret_cast<const char*>(file->data), file->size), on_disk);
  }
  // The page's files and Chart.js: nothing else is served.
  EXPECT_EQ(kDashboardFileCount, files + 1);
  EXPECT_NE(FileAt("/vendor/chart.umd.min.js"), nullptr);
}

TEST_F(DashboardTest, TheChartingLibraryIsServedAsJavaScript) {
  httplib::Result result = Get("/vendor/chart.umd.min.js");
  ASSERT_TRUE(result);
  EXPECT_EQ(result->status, 200);
  EXPECT_EQ(result->get_header_value("Content-Type"), "text/javascript; charset=utf-8");
  // Chart.js 4's minified bundle is about 200 KB; a few KB would be an error page or a stub.
  EXPECT_GT(result->body.size(), 100u << 10);
  EXPECT_THAT(result->body, HasSubstr("Chart.js v4"));
}

TEST_F(DashboardTest, EverySourceThePageNamesIsServedFromTheServerItself) {
  httplib::Result index = Get("/");
  ASSERT_TRUE(index);
  // Every src= and href= of the page: relative paths only (the CSP would block others anyway).
  const std::regex reference(R"re((?:src|href)="([^"]*)")re");
  std::set<std::string> named;
  for (std::sregex_iterator it(index->body.begin(), index->body.end(), reference), end; it != end;
       ++it) {
    named.insert((*it)[1].str());
  }
  EXPECT_GE(named.size(), 4u);  // the icon, the style sheet, Chart.js and app.js
  for (const std::string& path : named) {
    SCOPED_TRACE(path);
    EXPECT_EQ(path.find("//"), std::string::npos);
    EXPECT_EQ(path.find(':'), std::string::npos);
    httplib::Result result = Get("/" + path);
    ASSERT_TRUE(result);
    EXPECT_EQ(result->status, 200);
  }
}

TEST_F(DashboardTest, UnknownFilesAre404) {
  for (const char* path : {"/nope.js", "/vendor/other.js", "/index.htm", "/src/app.js"}) {
    SCOPED_TRACE(path);
    httplib::Result result = Get(path);
    ASSERT_TRUE(result);
    EXPECT_EQ(result->status, 404);
    EXPECT_THAT(result->body, HasSubstr("\"code\":\"NOT_FOUND\""));
    EXPECT_EQ(result->get_header_value("Content-Security-Policy"), kDashboardCsp);
  }
}

TEST_F(DashboardTest, OnlyGetAndHeadAreServed) {
  httplib::Result post = http_->Post("/", "x", "text/plain");
  ASSERT_TRUE(post);
  EXPECT_EQ(post->status, 405);
  EXPECT_EQ(post->get_header_value("Allow"), "GET, HEAD");
  EXPECT_TRUE(post->body.find("<!doctype") == std::string::npos);
  httplib::Result put = http_->Put("/app.js", "x", "text/javascript");
  ASSERT_TRUE(put);
  EXPECT_EQ(put->status, 405);
  httplib::Result erase = http_->Delete("/index.html");
  ASSERT_TRUE(erase);
  EXPECT_EQ(erase->status, 405);

  httplib::Result head = http_->Head("/");
  ASSERT_TRUE(head);
  EXPECT_EQ(head->status, 200);
  EXPECT_TRUE(head->body.empty());
  EXPECT_EQ(head->get_header_value("Content-Length"), std::to_string(FileAt("/index.html")->size));
}

TEST_F(DashboardTest, TheBrowsersCopyIsRevalidatedByItsETag) {
  httplib::Result first = Get("/app.js");
  ASSERT_TRUE(first);
  const std::string etag = first->get_header_value("ETag");
  ASSERT_FALSE(etag.empty());
  httplib::Result same = Get("/app.js", {{"If-None-Match", etag}});
  ASSERT_TRUE(same);
  EXPECT_EQ(same->status, 304);
  EXPECT_TRUE(same->body.empty());
  // Another file's tag is another version: the whole file again.
  httplib::Result other = Get("/api.js", {{"If-None-Match", etag}});
  ASSERT_TRUE(other);
  EXPECT_EQ(other->status, 200);
  EXPECT_NE(other->get_header_value("ETag"), etag);
}

TEST_F(DashboardTest, TheApiStillNeedsTheToken) {
  httplib::Result list = Get("/v1/operations");
  ASSERT_TRUE(list);
  EXPECT_EQ(list->status, 401);
  EXPECT_THAT(list->body, HasSubstr("UNAUTHENTICATED"));
  // Paths under /v1/ are the API's, never a file: an unknown one is the API's 404.
  httplib::Result unknown = Get("/v1/index.html");
  ASSERT_TRUE(unknown);
  EXPECT_EQ(unknown->status, 404);
  EXPECT_THAT(unknown->body, HasSubstr("no route"));
  httplib::Result with_token =
      Get("/v1/operations", {{"Authorization", std::string("Bearer ") + kToken}});
  ASSERT_TRUE(with_token);
  EXPECT_EQ(with_token->status, 200);
}

}  // namespace
}  // namespace drillbif::server
