// The HTTP port against hostile clients: a real server (Server::Start) on 127.0.0.1 with port 0,
// one worker kept busy by a long sweep so that jobs stay queued, and raw sockets that send what
// an attacker would. Header floods and long URIs are refused with 431 / 414 and bounded memory,
// oversize and unauthenticated bodies before they are read, invalid UTF-8 anywhere with 400 naming
// where; slow clients, open event streams and a waiting QueryOptimum hold no thread, so other
// requests keep being answered; a client that leaves cancels its stream; a slowloris is cut at
// the request deadline; TLS serves both ports with one certificate.
#include <arpa/inet.h>
#include <gmock/gmock.h>
#include <google/protobuf/util/json_util.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "server/server.h"
#include "support/metrics_samples.h"
#include "support/raw_http.h"
#include "support/small_requests.h"
#include "support/temp_dir.h"

// Last: httplib.h includes <resolv.h>, whose macro _res breaks Eigen's headers (a parameter name)
// when they come after it.
#include <httplib.h>

namespace drillbif::server {
namespace {

using Clock = std::chrono::steady_clock;
using drillbif::testing::BodyOf;
using drillbif::testing::ExpectJsonError;
using drillbif::testing::RawConnection;
using drillbif::testing::StatusOf;
using drillbif::testing::TempDir;
using google::longrunning::Operation;
using std::chrono::milliseconds;
using ::testing::HasSubstr;

constexpr char kToken[] = "limits-token";

double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// The process's resident memory in KiB (VmRSS of /proc/self/status).
long VmRssKib() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmRSS:", 0) == 0) return std::atol(line.c_str() + 6);
  }
  return -1;
}

std::string Json(const google::protobuf::Message& message) {
  std::string out;
  EXPECT_TRUE(google::protobuf::util::MessageToJsonString(message, &out).ok());
  return out;
}

ServerOptions TestServerOptions(const std::string& dir) {
  ServerOptions options;
  options.grpc_port = 0;
  options.http_port = 0;
  options.db_path = dir + "/jobs.db";
  options.workers = 1;
  options.token = kToken;
  options.full_sync = false;  // Submits are on the path of the timed requests; durability is not.
  return options;
}

// One server per test process (ctest runs each test alone); its single worker runs a sweep of
// minutes, so every other job stays QUEUED and watchers of it wait.
class HttpLimitsTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir("drillbif_http_limits");
    StatusOr<std::unique_ptr<Server>> server = Server::Start(TestServerOptions(dir_->path()));
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(server).value().release();
  }
  static void TearDownTestSuite() {
    delete server_;
    delete dir_;
  }

  static int port() { return server_->http_port(); }

  static std::unique_ptr<httplib::Client> Client() {
    auto client = std::make_unique<httplib::Client>("127.0.0.1", port());
    client->set_read_timeout(std::chrono::seconds(30));
    client->set_connection_timeout(std::chrono::seconds(5));
    client->set_default_headers({{"Authorization", std::string("Bearer ") + kToken}});
    return client;
  }

  static std::string Auth() { return std::string("Authorization: Bearer ") + kToken + "\r\n"; }

  // Occupies the worker with a sweep of minutes and returns a job that stays queued behind it:
  // another long sweep (a short job would run at once on the worker reserved for short jobs).
  static std::string QueuedJob() {
    auto client = Client();
    v1::SubmitSweepRequest busy;
    *busy.mutable_request() = drillbif::testing::LongSweep();
    httplib::Result running = client->Post("/v1/jobs:sweep", Json(busy), "application/json");
    EXPECT_TRUE(running && running->status == 200);
    v1::SubmitSweepRequest queued;
    *queued.mutable_request() = drillbif::testing::LongSweep();
    queued.mutable_request()->set_min(0.001);  // not identical: it does not follow the first
    httplib::Result result = client->Post("/v1/jobs:sweep", Json(queued), "application/json");
    EXPECT_TRUE(result && result->status == 200);
    Operation op;
    if (result) {
      EXPECT_TRUE(google::protobuf::util::JsonStringToMessage(result->body, &op).ok());
    }
    return op.name();
  }

  static std::map<std::string, double> Metrics() {
    StatusOr<std::string> text = server_->MetricsText();
    EXPECT_TRUE(text.ok());
    return text.ok() ? drillbif::testing::MetricsSamples(*text) : std::map<std::string, double>();
  }

  // Polls the drillbif_watchers gauge until it equals `expected` or `wait` passes.
  static bool WatchersReach(double expected, milliseconds wait) {
    const auto end = Clock::now() + wait;
    while (Clock::now() < end) {
      if (Metrics()["drillbif_watchers"] == expected) return true;
      std::this_thread::sleep_for(milliseconds(10));
    }
    return Metrics()["drillbif_watchers"] == expected;
  }

  static TempDir* dir_;
  static Server* server_;
};

TempDir* HttpLimitsTest::dir_ = nullptr;
Server* HttpLimitsTest::server_ = nullptr;

// 1 MB of headers overflows the connection's memory (64 KiB): libmicrohttpd answers 431 itself
// (its fixed HTML body; the gateway is not called) and closes the connection. Five such floods
// at once must not grow the process by more than their five connection pools: the bound, 8 MiB,
// is 5 x 64 KiB of pools plus room for thread stacks and allocator arenas; the failure it guards
// against cost ~400 MB per connection.
TEST_F(HttpLimitsTest, HeaderFloodIs431AndCostsBoundedMemory) {
  const std::string flood = "GET /v1/operations HTTP/1.1\r\nHost: x\r\n" + Auth() +
                            "X-Flood: " + std::string(1 << 20, 'a') + "\r\n\r\n";
  const long before = VmRssKib();
  std::vector<std::thread> clients;
  std::atomic<int> refused{0}, closed{0};
  for (int i = 0; i < 5; ++i) {
    clients.emplace_back([&] {
      RawConnection c(port());
      c.Send(flood);  // The server stops reading early: the send may fail.
      bool eof = false;
      const std::string response = c.ReadResponse(milliseconds(10000), &eof);
      if (StatusOf(response) == 431) ++refused;
      if (eof || c.ClosedWithin(milliseconds(5000))) ++closed;
    });
  }
  for (auto& t : clients) t.join();
  const long after = VmRssKib();
  std::printf("RSS before %ld KiB, after 5 floods of 1 MB %ld KiB (+%ld KiB)\n", before, after,
              after - before);
  EXPECT_EQ(refused.load(), 5);
  EXPECT_EQ(closed.load(), 5);
  EXPECT_LT(after - before, 8 * 1024);
  // Still serving.
  EXPECT_EQ(Client()->Get("/v1/operations")->status, 200);
}

// Header limits the gateway answers itself, in JSON: 150 small headers (152 with Host and
// Authorization: over max_header_count = 100, within the connection's memory) and one 20 KB
// header (over max_header_bytes = 16 KiB). 1000 small headers do not fit in 64 KiB at all
// (libmicrohttpd keeps a record per header): 431 from libmicrohttpd, connection closed.
TEST_F(HttpLimitsTest, TooManyOrTooLargeHeadersAre431) {
  std::string many = "GET /v1/operations HTTP/1.1\r\nHost: x\r\n" + Auth();
  for (int i = 0; i < 150; ++i) many += "X-H" + std::to_string(i) + ": v\r\n";
  RawConnection a(port());
  ASSERT_TRUE(a.Send(many + "\r\n"));
  std::string response = a.ReadResponse(milliseconds(10000));
  EXPECT_EQ(StatusOf(response), 431) << response.substr(0, 200);
  EXPECT_THAT(ExpectJsonError(BodyOf(response), "RESOURCE_EXHAUSTED"),
              HasSubstr("headers: 152 fields, more than the limit of 100"));
  EXPECT_TRUE(a.ClosedWithin(milliseconds(5000)));

  RawConnection b(port());
  ASSERT_TRUE(b.Send("GET /v1/operations HTTP/1.1\r\nHost: x\r\n" + Auth() +
                     "X-Big: " + std::string(20000, 'b') + "\r\n\r\n"));
  response = b.ReadResponse(milliseconds(10000));
  EXPECT_EQ(StatusOf(response), 431);
  EXPECT_THAT(ExpectJsonError(BodyOf(response), "RESOURCE_EXHAUSTED"),
              HasSubstr("more than the limit of 16384"));
  EXPECT_TRUE(b.ClosedWithin(milliseconds(5000)));

  std::string thousand = "GET /v1/operations HTTP/1.1\r\nHost: x\r\n";
  for (int i = 0; i < 1000; ++i) thousand += "X-H" + std::to_string(i) + ": v\r\n";
  RawConnection c(port());
  c.Send(thousand + "\r\n");
  bool closed = false;
  response = c.ReadResponse(milliseconds(10000), &closed);
  EXPECT_EQ(StatusOf(response), 431) << response.substr(0, 200);
  EXPECT_TRUE(closed || c.ClosedWithin(milliseconds(5000)));
}

TEST_F(HttpLimitsTest, LongUriIs414) {
  RawConnection c(port());
  ASSERT_TRUE(c.Send("GET /v1/operations?filter=" + std::string(10000, 'k') +
                     " HTTP/1.1\r\nHost: x\r\n" + Auth() + "\r\n"));
  const std::string response = c.ReadResponse(milliseconds(10000));
  EXPECT_EQ(StatusOf(response), 414) << response.substr(0, 200);
  EXPECT_THAT(ExpectJsonError(BodyOf(response), "RESOURCE_EXHAUSTED"),
              HasSubstr("request target: 10022 bytes, longer than the limit of 8192"));
  EXPECT_TRUE(c.ClosedWithin(milliseconds(5000)));
}

// A Content-Length over the limit is answered at once, from the headers: the test sends no body
// byte, so an answer proves the body was not awaited. Likewise a missing token with a body.
TEST_F(HttpLimitsTest, OversizeOrUnauthenticatedBodyIsRefusedBeforeItIsRead) {
  RawConnection big(port());
  ASSERT_TRUE(big.Send("POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\n" + Auth() +
                       "Content-Type: application/json\r\nContent-Length: 100000000\r\n\r\n"));
  std::string response = big.ReadResponse(milliseconds(10000));
  EXPECT_EQ(StatusOf(response), 413) << response.substr(0, 200);
  EXPECT_THAT(ExpectJsonError(BodyOf(response), "RESOURCE_EXHAUSTED"),
              HasSubstr("Content-Length 100000000 is larger than the limit of 4194304"));
  EXPECT_TRUE(big.ClosedWithin(milliseconds(5000)));

  RawConnection anonymous(port());
  ASSERT_TRUE(anonymous.Send(
      "POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\nContent-Length: 1000000\r\n\r\n"));
  response = anonymous.ReadResponse(milliseconds(10000));
  EXPECT_EQ(StatusOf(response), 401) << response.substr(0, 200);
  EXPECT_THAT(ExpectJsonError(BodyOf(response), "UNAUTHENTICATED"), HasSubstr("missing"));
  EXPECT_TRUE(anonymous.ClosedWithin(milliseconds(5000)));

  // Two different Content-Length values (request smuggling's tool): 400.
  RawConnection twice(port());
  ASSERT_TRUE(twice.Send("POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\n" + Auth() +
                         "Content-Length: 2\r\nContent-Length: 3\r\n\r\n{}"));
  response = twice.ReadResponse(milliseconds(10000));
  EXPECT_EQ(StatusOf(response), 400) << response.substr(0, 200);
  EXPECT_THAT(ExpectJsonError(BodyOf(response), "INVALID_ARGUMENT"), HasSubstr("Content-Length"));
}

// Invalid UTF-8 in the path, a query name or value, the body (raw bytes, or a \u escape of a lone
// surrogate) or the Authorization header: 400 INVALID_ARGUMENT naming where, never a 500.
TEST_F(HttpLimitsTest, InvalidUtf8AnywhereIs400NamingWhere) {
  const auto send = [](const std::string& request) {
    RawConnection c(port());
    EXPECT_TRUE(c.Send(request));
    return c.ReadResponse(milliseconds(10000));
  };
  const auto get = [&](const std::string& target) {
    return send("GET " + target + " HTTP/1.1\r\nHost: x\r\n" + Auth() + "\r\n");
  };
  const auto post = [&](const std::string& body) {
    return send("POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\n" + Auth() +
                "Content-Length: " + std::to_string(body.size()) + "\r\n\r\n" + body);
  };
  struct Case {
    std::string response;
    const char* where;
  };
  const std::vector<Case> cases = {
      {get("/v1/operations/%FF%FE"), "path: not valid UTF-8"},
      {get("/v1/operations/\xC3\x28"), "path: not valid UTF-8"},
      {get("/v1/operations/a%00b"), "path: a NUL byte"},
      {get("/v1/operations?filter=%C3%28"), "query parameter 'filter': not valid UTF-8"},
      {get("/v1/operations?%ED%A0%80=1"), "query parameter name: not valid UTF-8"},
      {post("{\"requestId\": \"\xFF\"}"), "body: not valid UTF-8 (at byte 15)"},
      {post("{\"requestId\": \"\\ud800\"}"), "in JSON: Missing low surrogate"},
      {send("GET /v1/operations HTTP/1.1\r\nHost: x\r\nAuthorization: Bearer \xC0\xAF\r\n\r\n"),
       "header Authorization: not valid UTF-8"},
  };
  for (const Case& c : cases) {
    EXPECT_EQ(StatusOf(c.response), 400) << c.where << "\n" << c.response.substr(0, 300);
    EXPECT_THAT(ExpectJsonError(BodyOf(c.response), "INVALID_ARGUMENT"), HasSubstr(c.where));
  }
}

// Error bodies are JSON whatever the client sent, and what they echo is cut and cleaned.
TEST_F(HttpLimitsTest, ErrorBodiesAreJsonWithSanitisedEchoes) {
  RawConnection c(port());
  ASSERT_TRUE(c.Send("GET /v1/nothing%0A%22%5C" + std::string(500, 'z') +
                     " HTTP/1.1\r\nHost: x\r\n" + Auth() + "\r\n"));
  std::string response = c.ReadResponse(milliseconds(10000));
  EXPECT_EQ(StatusOf(response), 404);
  const std::string message = ExpectJsonError(BodyOf(response), "NOT_FOUND");
  EXPECT_THAT(message, HasSubstr("no route for GET /v1/nothing?\"\\zzz"));
  EXPECT_LT(message.size(), 100u);  // "no route for GET " + 64 bytes + "...".

  RawConnection timeout(port());
  ASSERT_TRUE(timeout.Send("GET /v1/operations HTTP/1.1\r\nHost: x\r\n" + Auth() +
                           "X-Server-Timeout: \xFF\x01soon\r\n\r\n"));
  response = timeout.ReadResponse(milliseconds(10000));
  EXPECT_EQ(StatusOf(response), 400);
  EXPECT_THAT(ExpectJsonError(BodyOf(response), "INVALID_ARGUMENT"),
              HasSubstr("header X-Server-Timeout: expected seconds > 0, got '\xEF\xBF\xBD?soon'"));
}

// 64 clients sending a request one byte at a time and 64 event streams of a queued job hold
// connections; /metrics and a submit are still answered at once. The bound, 1 s, is the service's;
// with the gateway holding a thread per such client they waited forever.
TEST_F(HttpLimitsTest, SlowClientsAndOpenStreamsDoNotBlockOtherRequests) {
  const std::string queued = QueuedJob();
  ASSERT_FALSE(queued.empty());
  const double watchers_before = Metrics()["drillbif_watchers"];

  std::vector<std::unique_ptr<RawConnection>> slow;
  for (int i = 0; i < 64; ++i) {
    slow.push_back(std::make_unique<RawConnection>(port()));
    ASSERT_TRUE(slow.back()->connected());
    ASSERT_TRUE(slow.back()->Send("POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\nX-Slow: "));
  }
  std::atomic<bool> stop{false};
  std::thread dripper([&] {
    while (!stop) {
      for (auto& c : slow) c->Send("a");
      std::this_thread::sleep_for(milliseconds(50));
    }
  });

  std::vector<std::unique_ptr<RawConnection>> streams;
  for (int i = 0; i < 64; ++i) {
    streams.push_back(std::make_unique<RawConnection>(port()));
    ASSERT_TRUE(streams.back()->Send("GET /v1/" + queued + ":watch HTTP/1.1\r\nHost: x\r\n" +
                                     Auth() + "\r\n"));
  }
  for (auto& s : streams) {
    const std::string first = s->ReadUntil(
        [](const std::string& r) { return r.find("\"state\":\"QUEUED\"") != std::string::npos; },
        milliseconds(10000));
    ASSERT_THAT(first, HasSubstr("text/event-stream"));
  }
  EXPECT_TRUE(WatchersReach(watchers_before + 64, milliseconds(5000)));

  auto client = Client();
  auto start = Clock::now();
  httplib::Result metrics = client->Get("/metrics");
  const double metrics_ms = MsSince(start);
  ASSERT_TRUE(metrics);
  EXPECT_EQ(metrics->status, 200);
  v1::SubmitSimulateRequest submit;
  submit.mutable_request()->set_sample_periods(9);
  start = Clock::now();
  httplib::Result submitted = client->Post("/v1/jobs:simulate", Json(submit), "application/json");
  const double submit_ms = MsSince(start);
  ASSERT_TRUE(submitted);
  EXPECT_EQ(submitted->status, 200) << submitted->body;
  std::printf("with 64 slow clients and 64 open streams: GET /metrics %.1f ms, submit %.1f ms\n",
              metrics_ms, submit_ms);
  EXPECT_LT(metrics_ms, 1000.0);
  // The submit commits to SQLite on the executor; 5 s is wide for a disk shared with other
  // builds, and far below "never".
  EXPECT_LT(submit_ms, 5000.0);

  stop = true;
  dripper.join();
}

// A QueryOptimum that waits for its job (queued behind the busy worker) keeps its connection
// suspended: other requests are answered meanwhile, and it answers at its X-Server-Timeout.
TEST_F(HttpLimitsTest, WaitingQueryOptimumDoesNotBlockOtherRequests) {
  ASSERT_FALSE(QueuedJob().empty());
  v1::QueryOptimumRequest query;
  *query.mutable_request()->mutable_trace() = drillbif::testing::SmallBoxTrace();
  query.mutable_request()->add_grid(17);
  query.mutable_request()->add_grid(19);
  query.set_compute(true);
  const std::string body = Json(query);
  std::vector<std::unique_ptr<RawConnection>> waiting;
  // More than 8: a gateway holding one of 8 threads per waiting request would block here.
  for (int i = 0; i < 12; ++i) {
    waiting.push_back(std::make_unique<RawConnection>(port()));
    ASSERT_TRUE(waiting.back()->Send("POST /v1/optimum:query HTTP/1.1\r\nHost: x\r\n" + Auth() +
                                     "X-Server-Timeout: 3\r\nContent-Length: " +
                                     std::to_string(body.size()) + "\r\n\r\n" + body));
  }
  std::this_thread::sleep_for(milliseconds(300));
  auto client = Client();
  const auto start = Clock::now();
  httplib::Result list = client->Get("/v1/operations?pageSize=1");
  const double ms = MsSince(start);
  ASSERT_TRUE(list);
  EXPECT_EQ(list->status, 200);
  std::printf("GET /v1/operations with 12 QueryOptimum calls waiting: %.1f ms\n", ms);
  EXPECT_LT(ms, 1000.0);
  for (auto& w : waiting) EXPECT_TRUE(w->NothingYet()) << "answered before its timeout";
  // Each answers at its timeout: the service names the job 50 ms before the deadline (200), or,
  // on a machine slow enough to miss that margin, the deadline ends the call (504).
  for (auto& w : waiting) {
    const std::string response = w->ReadResponse(milliseconds(20000));
    const int status = StatusOf(response);
    EXPECT_TRUE(status == 200 || status == 504) << response.substr(0, 300);
    if (status == 200) {
      EXPECT_THAT(BodyOf(response), HasSubstr("\"operation\":\"operations/"));
    } else {
      ExpectJsonError(BodyOf(response), "DEADLINE_EXCEEDED");
    }
  }
}

// A client that closes its event stream (or its waiting call) frees what it held: the service's
// watcher goes away, and the waiting call is cancelled (answered, counted, then dropped).
TEST_F(HttpLimitsTest, ClientThatLeavesCancelsItsStreamAndItsCall) {
  const std::string queued = QueuedJob();
  ASSERT_FALSE(queued.empty());
  const double before = Metrics()["drillbif_watchers"];
  {
    RawConnection stream(port());
    ASSERT_TRUE(
        stream.Send("GET /v1/" + queued + ":watch HTTP/1.1\r\nHost: x\r\n" + Auth() + "\r\n"));
    stream.ReadUntil([](const std::string& r) { return r.find("\n\n") != std::string::npos; },
                     milliseconds(10000));
    ASSERT_TRUE(WatchersReach(before + 1, milliseconds(5000)));
  }
  // The bound: the guard sees the close at once and the hub drops a finished watcher within its
  // 50 ms poll; 5 s leaves room for a loaded machine.
  const auto closed_at = Clock::now();
  EXPECT_TRUE(WatchersReach(before, milliseconds(5000)));
  std::printf("watcher freed %.1f ms after its client left\n", MsSince(closed_at));

  const std::string cancelled =
      R"(drillbif_http_requests_total{code="500",method="POST",route="/v1/optimum:query"})";
  const double cancelled_before = Metrics()[cancelled];
  v1::QueryOptimumRequest query;
  *query.mutable_request()->mutable_trace() = drillbif::testing::SmallBoxTrace();
  query.mutable_request()->add_grid(13);
  query.mutable_request()->add_grid(11);
  query.set_compute(true);
  const std::string body = Json(query);
  {
    RawConnection call(port());
    ASSERT_TRUE(call.Send("POST /v1/optimum:query HTTP/1.1\r\nHost: x\r\n" + Auth() +
                          "Content-Length: " + std::to_string(body.size()) + "\r\n\r\n" + body));
    ASSERT_TRUE(WatchersReach(before + 1, milliseconds(5000)));  // The call waits on its job.
  }
  // The call ends CANCELLED on the client side at once (the gateway answers 500 CANCELLED into
  // the closed connection and counts it); the service's own waiter stays until its deadline.
  const auto end = Clock::now() + milliseconds(5000);
  while (Clock::now() < end && Metrics()[cancelled] < cancelled_before + 1) {
    std::this_thread::sleep_for(milliseconds(10));
  }
  EXPECT_EQ(Metrics()[cancelled], cancelled_before + 1);
}

// At the connection limit the server stops accepting: a connection beyond it waits in the listen
// queue, unanswered, until one of the others closes, and is then served.
TEST(HttpConnectionLimit, ConnectionsBeyondTheLimitWaitForAFreeSlot) {
  TempDir dir("drillbif_http_connections");
  ServerOptions options = TestServerOptions(dir.path());
  options.http.connection_limit = 8;
  StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  const int port = (*server)->http_port();
  const std::string get = "GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n";
  std::vector<std::unique_ptr<RawConnection>> held;
  for (int i = 0; i < 8; ++i) {
    held.push_back(std::make_unique<RawConnection>(port));
    ASSERT_TRUE(held.back()->Send(get));
    EXPECT_EQ(StatusOf(held.back()->ReadResponse(milliseconds(10000))), 200);
  }
  RawConnection extra(port);
  ASSERT_TRUE(extra.connected());  // The kernel completes the handshake (listen queue).
  ASSERT_TRUE(extra.Send(get));
  EXPECT_EQ(StatusOf(extra.ReadResponse(milliseconds(500))), 0) << "served beyond the limit";
  const auto freed = Clock::now();
  held.pop_back();  // One leaves: the waiting connection is accepted and served.
  EXPECT_EQ(StatusOf(extra.ReadResponse(milliseconds(10000))), 200);
  std::printf("connection beyond the limit served %.1f ms after a slot freed\n", MsSince(freed));
}

// A client that sends its request one byte at a time is cut at the request deadline (here 1 s)
// although each byte resets the idle timeout; a whole request sent in time is served.
TEST(HttpRequestDeadline, SlowlorisIsCutAtTheRequestDeadline) {
  TempDir dir("drillbif_http_deadline");
  ServerOptions options = TestServerOptions(dir.path());
  options.http.request_timeout_ms = 1000;
  StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  RawConnection slow((*server)->http_port());
  const std::string request =
      "GET /metrics HTTP/1.1\r\nHost: x\r\nX-Slow: " + std::string(200, 's') + "\r\n\r\n";
  const auto start = Clock::now();
  size_t sent = 0;
  while (sent < request.size() && slow.Send(request.substr(sent, 1))) {
    ++sent;
    if (!slow.NothingYet()) break;  // The server closed it.
    std::this_thread::sleep_for(milliseconds(20));
  }
  EXPECT_TRUE(slow.ClosedWithin(milliseconds(5000)));
  const double ms = MsSince(start);
  std::printf("slowloris cut after %.0f ms, %zu of %zu bytes sent\n", ms, sent, request.size());
  EXPECT_LT(sent, request.size());
  // Not before the deadline; the upper bound leaves 4 s for a loaded machine.
  EXPECT_GE(ms, 950.0);
  EXPECT_LT(ms, 5000.0);

  RawConnection quick((*server)->http_port());
  ASSERT_TRUE(quick.Send("GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n"));
  EXPECT_EQ(StatusOf(quick.ReadResponse(milliseconds(10000))), 200);
}

// A connection that sends nothing, before its first request or after an answer, is closed at the
// idle timeout (here 1 s; libmicrohttpd counts whole seconds).
TEST(HttpIdleTimeout, IdleConnectionsAreClosed) {
  TempDir dir("drillbif_http_idle");
  ServerOptions options = TestServerOptions(dir.path());
  options.http.idle_timeout_ms = 1000;
  StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  RawConnection silent((*server)->http_port());
  auto start = Clock::now();
  EXPECT_TRUE(silent.ClosedWithin(milliseconds(10000)));
  const double silent_ms = MsSince(start);
  RawConnection kept((*server)->http_port());
  ASSERT_TRUE(kept.Send("GET /metrics HTTP/1.1\r\nHost: x\r\n\r\n"));
  EXPECT_EQ(StatusOf(kept.ReadResponse(milliseconds(10000))), 200);
  start = Clock::now();
  EXPECT_TRUE(kept.ClosedWithin(milliseconds(10000)));
  const double kept_ms = MsSince(start);
  std::printf("idle connection closed after %.0f ms, kept-alive one after %.0f ms\n", silent_ms,
              kept_ms);
  // Not before the timeout; the upper bound allows libmicrohttpd's whole-second rounding and a
  // loaded machine.
  for (double ms : {silent_ms, kept_ms}) {
    EXPECT_GE(ms, 900.0);
    EXPECT_LT(ms, 5000.0);
  }
}

// A client that stops reading a large answer is cut at the write deadline (here 1 s) although
// the idle timeout (30 s) has not passed: it asked for a ~9 MB result with a 4 KiB receive buffer
// and reads nothing for 3 s, then finds the connection closed before the answer's end.
TEST(HttpWriteDeadline, ClientThatStopsReadingIsCut) {
  TempDir dir("drillbif_http_write");
  ServerOptions options = TestServerOptions(dir.path());
  options.http.write_timeout_ms = 1000;
  StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  httplib::Client client("127.0.0.1", (*server)->http_port());
  client.set_read_timeout(std::chrono::seconds(30));
  client.set_default_headers({{"Authorization", std::string("Bearer ") + kToken}});
  v1::SubmitSimulateRequest request;
  request.mutable_request()->set_sample_periods(80000);
  httplib::Result submitted = client.Post("/v1/jobs:simulate", Json(request), "application/json");
  ASSERT_TRUE(submitted && submitted->status == 200);
  Operation op;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(submitted->body, &op).ok());
  for (int i = 0; i < 3000 && !op.done(); ++i) {
    std::this_thread::sleep_for(milliseconds(10));
    httplib::Result got = client.Get(("/v1/" + op.name()).c_str());
    ASSERT_TRUE(got);
    ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(got->body, &op).ok());
  }
  ASSERT_TRUE(op.done());
  const size_t whole = client.Get(("/v1/" + op.name()).c_str())->body.size();
  ASSERT_GT(whole, 1u << 20) << "the answer must exceed what the sockets buffer";

  const int fd = socket(AF_INET, SOCK_STREAM, 0);
  const int small = 4096;
  setsockopt(fd, SOL_SOCKET, SO_RCVBUF, &small, sizeof(small));
  sockaddr_in address{};
  address.sin_family = AF_INET;
  address.sin_port = htons(static_cast<uint16_t>((*server)->http_port()));
  address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
  ASSERT_EQ(connect(fd, reinterpret_cast<sockaddr*>(&address), sizeof(address)), 0);
  const std::string get = "GET /v1/" + op.name() + " HTTP/1.1\r\nHost: x\r\n" +
                          "Authorization: Bearer " + kToken + "\r\n\r\n";
  ASSERT_EQ(send(fd, get.data(), get.size(), MSG_NOSIGNAL), static_cast<ssize_t>(get.size()));
  std::this_thread::sleep_for(milliseconds(3000));
  size_t received = 0;
  bool eof = false;
  char buffer[65536];
  const auto end = Clock::now() + milliseconds(10000);
  while (Clock::now() < end) {
    pollfd p{fd, POLLIN, 0};
    if (poll(&p, 1, 100) <= 0) continue;
    const ssize_t n = recv(fd, buffer, sizeof(buffer), 0);
    if (n <= 0) {
      eof = true;
      break;
    }
    received += static_cast<size_t>(n);
  }
  close(fd);
  std::printf("answer of %zu bytes: %zu received before the cut\n", whole, received);
  EXPECT_TRUE(eof);
  EXPECT_LT(received, whole);
}

// --tls-cert / --tls-key: HTTPS on the HTTP port (verified against the certificate as CA) and
// TLS on the gRPC port, from one throwaway self-signed certificate; plain HTTP and an insecure
// gRPC channel get nothing.
TEST(HttpTls, BothPortsServeTlsWithOneCertificate) {
  TempDir dir("drillbif_http_tls");
  const std::string cert = dir.path() + "/cert.pem";
  const std::string key = dir.path() + "/key.pem";
  const std::string command =
      "openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 2 "
      "-subj /CN=localhost -addext subjectAltName=IP:127.0.0.1,DNS:localhost -keyout " +
      key + " -out " + cert + " 2>/dev/null";
  ASSERT_EQ(std::system(command.c_str()), 0) << "openssl (Debian's openssl package) is needed";
  ServerOptions options = TestServerOptions(dir.path());
  options.tls_cert_file = cert;
  options.tls_key_file = key;
  StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
  ASSERT_TRUE(server.ok()) << server.status().ToString();

  httplib::SSLClient https("127.0.0.1", (*server)->http_port());
  https.set_ca_cert_path(cert.c_str());
  https.enable_server_certificate_verification(true);
  https.set_connection_timeout(std::chrono::seconds(5));
  https.set_read_timeout(std::chrono::seconds(10));
  httplib::Result metrics = https.Get("/metrics");
  ASSERT_TRUE(metrics) << httplib::to_string(metrics.error());
  EXPECT_EQ(metrics->status, 200);
  httplib::Result list = https.Get("/v1/operations", {{"Authorization", "Bearer limits-token"}});
  ASSERT_TRUE(list);
  EXPECT_EQ(list->status, 200) << list->body;
  // Without the CA, verification fails; plain HTTP gets no HTTP answer.
  httplib::SSLClient unverified("127.0.0.1", (*server)->http_port());
  unverified.enable_server_certificate_verification(true);
  unverified.set_ca_cert_path((dir.path() + "/missing.pem").c_str());
  EXPECT_FALSE(unverified.Get("/metrics"));
  httplib::Client plain("127.0.0.1", (*server)->http_port());
  plain.set_read_timeout(std::chrono::seconds(5));
  httplib::Result plain_result = plain.Get("/metrics");
  EXPECT_TRUE(!plain_result || plain_result->status != 200);

  std::ifstream in(cert);
  std::stringstream pem;
  pem << in.rdbuf();
  grpc::SslCredentialsOptions ssl;
  ssl.pem_root_certs = pem.str();
  auto channel = grpc::CreateChannel((*server)->grpc_address(), grpc::SslCredentials(ssl));
  auto stub = google::longrunning::Operations::NewStub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  context.AddMetadata("authorization", "Bearer limits-token");
  google::longrunning::ListOperationsRequest request;
  google::longrunning::ListOperationsResponse response;
  const grpc::Status status = stub->ListOperations(&context, request, &response);
  EXPECT_TRUE(status.ok()) << status.error_message();

  auto insecure = google::longrunning::Operations::NewStub(
      grpc::CreateChannel((*server)->grpc_address(), grpc::InsecureChannelCredentials()));
  grpc::ClientContext plain_context;
  plain_context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(3));
  plain_context.AddMetadata("authorization", "Bearer limits-token");
  EXPECT_FALSE(insecure->ListOperations(&plain_context, request, &response).ok());
}

}  // namespace
}  // namespace drillbif::server
