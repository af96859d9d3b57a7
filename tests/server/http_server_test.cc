// HttpServer (the gateway's libmicrohttpd side) with a handler of the test's own: on one event
// thread, a request answered later from another thread does not hold up the requests after it;
// a stream's events are pulled as the handler wakes the server; the connection limit is fitted to
// RLIMIT_NOFILE.
#include "server/http_server.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <chrono>
#include <deque>
#include <future>
#include <mutex>
#include <thread>
#include <vector>

#include "server/rest_gateway.h"

// Last: httplib.h includes <resolv.h>, whose macro _res breaks Eigen's headers.
#include <httplib.h>

namespace drillbif::server {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

// A stream that sends what Push gives it, then ends at Close.
class PushStream : public HttpStream {
 public:
  Pull Next(std::string* out) override {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!chunks_.empty()) {
      *out = std::move(chunks_.front());
      chunks_.pop_front();
      return Pull::kData;
    }
    return closed_ ? Pull::kEnd : Pull::kWait;
  }
  void Push(std::string chunk) {
    std::lock_guard<std::mutex> lock(mutex_);
    chunks_.push_back(std::move(chunk));
  }
  void Close() {
    std::lock_guard<std::mutex> lock(mutex_);
    closed_ = true;
  }

 private:
  std::mutex mutex_;
  std::deque<std::string> chunks_;
  bool closed_ = false;
};

// /slow answers from a thread of its own once the test calls ReleaseSlow; /fast at once;
// /stream sends three chunks 100 ms apart.
class TestHandler : public HttpHandler {
 public:
  ~TestHandler() override {
    for (auto& t : threads_) t.join();
  }
  // Waits until /slow has been handed to the handler (its connection is then suspended).
  void AwaitSlow() { slow_arrived_future_.wait(); }
  void ReleaseSlow() { release_slow_.set_value(); }
  std::optional<HttpResponse> OnHeaders(HttpExchange&) override { return std::nullopt; }
  void OnRequest(std::shared_ptr<HttpExchange> exchange) override {
    const std::string path = exchange->target().path;
    if (path == "/fast") return exchange->Respond(Text("fast"));
    std::lock_guard<std::mutex> lock(mutex_);
    if (path == "/slow") {
      slow_arrived_.set_value();
      threads_.emplace_back([this, exchange] {
        release_slow_.get_future().wait();
        exchange->Respond(Text("slow"));
      });
    } else {
      auto stream = std::make_shared<PushStream>();
      stream->Push("one;");
      exchange->RespondStream(Text(""), stream);
      threads_.emplace_back([exchange, stream] {
        for (const char* chunk : {"two;", "three;"}) {
          std::this_thread::sleep_for(milliseconds(100));
          stream->Push(chunk);
          exchange->Wake();
        }
        stream->Close();
        exchange->Wake();
      });
    }
  }

 private:
  static HttpResponse Text(std::string body) {
    HttpResponse response;
    response.content_type = "text/plain";
    response.body = std::move(body);
    return response;
  }
  std::mutex mutex_;
  std::vector<std::thread> threads_;
  std::promise<void> slow_arrived_;
  std::shared_future<void> slow_arrived_future_ = slow_arrived_.get_future().share();
  std::promise<void> release_slow_;
};

RestOptions OneThread() {
  RestOptions options;
  options.port = 0;
  options.threads = 1;
  return options;
}

// With one event thread, /fast is answered while /slow waits for its answer (which comes only
// after /fast's): a server holding its thread for /slow would never answer /fast (the client
// gives up after 10 s and the test fails).
TEST(HttpServer, AnAnswerGivenLaterHoldsNoThread) {
  TestHandler handler;
  Metrics metrics;
  StatusOr<std::unique_ptr<HttpServer>> server = HttpServer::Start(OneThread(), &handler, &metrics);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  const int port = (*server)->port();
  std::string slow_body;
  std::thread slow([&] {
    httplib::Client client("127.0.0.1", port);
    client.set_read_timeout(std::chrono::seconds(30));
    httplib::Result result = client.Get("/slow");
    if (result) slow_body = result->body;
  });
  handler.AwaitSlow();
  httplib::Client client("127.0.0.1", port);
  client.set_read_timeout(std::chrono::seconds(10));
  httplib::Result fast = client.Get("/fast");
  handler.ReleaseSlow();
  slow.join();
  ASSERT_TRUE(fast) << httplib::to_string(fast.error());
  EXPECT_EQ(fast->body, "fast");
  EXPECT_EQ(slow_body, "slow");
  (*server)->Stop(1000);
}

TEST(HttpServer, StreamSendsEachChunkWhenWokenThenEnds) {
  TestHandler handler;
  Metrics metrics;
  StatusOr<std::unique_ptr<HttpServer>> server = HttpServer::Start(OneThread(), &handler, &metrics);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  httplib::Client client("127.0.0.1", (*server)->port());
  std::vector<std::string> chunks;
  httplib::Result result = client.Get("/stream", [&](const char* data, size_t size) {
    chunks.emplace_back(data, size);
    return true;
  });
  ASSERT_TRUE(result) << httplib::to_string(result.error());
  std::string joined;
  for (const auto& c : chunks) joined += c;
  EXPECT_EQ(joined, "one;two;three;");
  EXPECT_GE(chunks.size(), 3u);  // 100 ms apart: not coalesced into one read.
}

TEST(HttpServer, ConnectionLimitFitsTheDescriptorLimit) {
  rlimit saved{};
  ASSERT_EQ(getrlimit(RLIMIT_NOFILE, &saved), 0);
  if (saved.rlim_cur < 1024) GTEST_SKIP() << "RLIMIT_NOFILE already below 1024";
  rlimit lowered = saved;
  lowered.rlim_cur = 600;
  ASSERT_EQ(setrlimit(RLIMIT_NOFILE, &lowered), 0);
  TestHandler handler;
  Metrics metrics;
  StatusOr<std::unique_ptr<HttpServer>> server = HttpServer::Start(OneThread(), &handler, &metrics);
  setrlimit(RLIMIT_NOFILE, &saved);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  // 600 descriptors minus the 256 kept for gRPC, SQLite and logs.
  EXPECT_EQ((*server)->connection_limit(), 344);
}

TEST(HttpServer, BadCertificateIsRefusedAtStart) {
  RestOptions options = OneThread();
  options.tls_cert_file = "/nonexistent/cert.pem";
  options.tls_key_file = "/nonexistent/key.pem";
  TestHandler handler;
  Metrics metrics;
  StatusOr<std::unique_ptr<HttpServer>> server = HttpServer::Start(options, &handler, &metrics);
  ASSERT_FALSE(server.ok());
  EXPECT_EQ(server.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(server.status().message(), ::testing::HasSubstr("tls_cert_file: cannot read"));
}

}  // namespace
}  // namespace drillbif::server
