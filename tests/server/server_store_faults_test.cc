// Faults of the job store seen through a running server (Server::Start on 127.0.0.1, ports 0):
// a full disk (the SQLite file on a 2 MiB tmpfs mounted in a mount namespace of the test
// process), a file overwritten with garbage under the running server, and a corrupt file at
// start. Checks what clients see: the job that hit the fault ends FAILED (never stuck RUNNING),
// every error names the problem without SQL text, the gRPC health service and GET /healthz say
// NOT_SERVING while the fault lasts and SERVING once it is gone, and jobs run again then.
// store_faults_test.cc checks the same faults on the store alone.
#include <fcntl.h>
#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <sqlite3.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <memory>
#include <random>
#include <string>
#include <thread>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "server/server.h"
#include "server/store/sqlite_job_store.h"
#include "support/generic_call.h"
#include "support/operations.h"
#include "support/raw_http.h"
#include "support/small_tmpfs.h"
#include "support/store_faults.h"
#include "support/temp_dir.h"

// Last: httplib.h includes <resolv.h>, whose macro _res breaks Eigen's headers (a parameter name)
// when they come after it.
#include <httplib.h>

namespace drillbif::server {
namespace {

using drillbif::testing::ExpectNoSql;
using drillbif::testing::FileSize;
using drillbif::testing::OverwritePages;

using Clock = std::chrono::steady_clock;
using drillbif::testing::BodyOf;
using drillbif::testing::ExpectJsonError;
using drillbif::testing::HealthStatus;
using drillbif::testing::MetadataOf;
using drillbif::testing::TempDir;
using google::longrunning::Operation;
using ::testing::HasSubstr;
using ::testing::Not;
using ::testing::StartsWith;

// grpc.health.v1 HealthCheckResponse.ServingStatus values (HealthStatus's answer).
constexpr int kServing = 1;
constexpr int kNotServing = 2;

// How often the server probes a faulty store. Small, so that the test sees health change
// within a few intervals; the bounds below allow for a loaded machine.
constexpr int kProbeMs = 50;
// Longest wait for health to follow the store (many probe intervals: on a loaded 2-core machine
// a maintenance round can be late by a second or more; the server changes it within one).
constexpr double kHealthWaitSeconds = 10;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// A server on 127.0.0.1 with free ports over the store at `db_path`, one worker (so jobs run one
// after another) and a fast store probe.
ServerOptions OptionsFor(const std::string& db_path) {
  ServerOptions options;
  options.host = "127.0.0.1";
  options.grpc_port = 0;
  options.http_port = 0;
  options.db_path = db_path;
  options.workers = 1;
  options.short_workers = 0;
  options.store_probe_ms = kProbeMs;
  // No eviction: the jobs a test put in the store stay there.
  options.retention = RetentionOptions{0, 0};
  return options;
}

// gRPC stubs and REST calls to one running server.
class Client {
 public:
  explicit Client(Server& server)
      : http_port_(server.http_port()),
        channel_(grpc::CreateChannel(server.grpc_address(), grpc::InsecureChannelCredentials())),
        jobs_(v1::Jobs::NewStub(channel_)),
        operations_(google::longrunning::Operations::NewStub(channel_)) {}

  static std::unique_ptr<grpc::ClientContext> Context(double seconds = 10) {
    auto context = std::make_unique<grpc::ClientContext>();
    context->set_deadline(std::chrono::system_clock::now() +
                          std::chrono::milliseconds(static_cast<int>(seconds * 1000)));
    return context;
  }

  grpc::Status Submit(const v1::SimulateRequest& request, Operation* op) {
    v1::SubmitSimulateRequest submit;
    *submit.mutable_request() = request;
    auto context = Context();
    return jobs_->SubmitSimulate(context.get(), submit, op);
  }

  grpc::Status Get(const std::string& name, Operation* op) {
    google::longrunning::GetOperationRequest request;
    request.set_name(name);
    auto context = Context();
    return operations_->GetOperation(context.get(), request, op);
  }

  grpc::Status Cancel(const std::string& name) {
    google::longrunning::CancelOperationRequest request;
    request.set_name(name);
    google::protobuf::Empty empty;
    auto context = Context();
    return operations_->CancelOperation(context.get(), request, &empty);
  }

  // The operation once done (WaitOperation, repeated), or as it is after `seconds`.
  Operation WaitDone(const std::string& name, double seconds) {
    const auto end = Clock::now() + std::chrono::milliseconds(static_cast<int>(seconds * 1000));
    Operation op;
    while (Clock::now() < end) {
      google::longrunning::WaitOperationRequest request;
      request.set_name(name);
      request.mutable_timeout()->set_seconds(1);
      auto context = Context(5);
      const grpc::Status s = operations_->WaitOperation(context.get(), request, &op);
      EXPECT_TRUE(s.ok()) << s.error_message();
      if (!s.ok() || op.done()) return op;
    }
    return op;
  }

  google::longrunning::Operations::Stub& operations() { return *operations_; }

  // gRPC health of the whole server (kServing, kNotServing; -1 when the call fails).
  int Health() { return HealthStatus(channel_); }

  // Waits until the health service says `want`; the seconds it took, or -1 when it did not
  // within kHealthWaitSeconds.
  double WaitForHealth(int want) {
    const Clock::time_point start = Clock::now();
    while (SecondsSince(start) < kHealthWaitSeconds) {
      if (Health() == want) return SecondsSince(start);
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    return -1;
  }

  // GET `path` on the HTTP port: the status (0 when the request failed) and body.
  std::pair<int, std::string> HttpGet(const std::string& path) {
    httplib::Client http("127.0.0.1", http_port_);
    http.set_read_timeout(10, 0);
    httplib::Result result = http.Get(path);
    if (!result) return {0, ""};
    return {result->status, result->body};
  }

 private:
  const int http_port_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::Jobs::Stub> jobs_;
  std::unique_ptr<google::longrunning::Operations::Stub> operations_;
};

// A small simulation: 3 transient and 3 sampled periods (milliseconds).
v1::SimulateRequest SmallSimulate() {
  v1::SimulateRequest request;
  request.set_transient_periods(3);
  request.set_sample_periods(3);
  return request;
}

// A simulation whose stored result is far larger than a 2 MiB disk, well inside admission:
// 20000 sampled periods with Poincare samples and events, ~400 bytes a period (the reference
// orbit has 4 events a period, ~90 bytes each): ~8 MB, computed in a fraction of a second
// (4.5 us a period, jobs/simulate_job.cc).
v1::SimulateRequest LargeResultSimulate() {
  v1::SimulateRequest request;
  request.set_transient_periods(0);
  request.set_sample_periods(20000);
  request.mutable_outputs()->set_poincare(true);
  request.mutable_outputs()->set_events(true);
  return request;
}

// A closed store file of about 6 MB: 20000 cancelled jobs finished now (so that no retention
// evicts them), padded with 100 random bytes each, so that garbage anywhere in the middle of the
// file lands in table and index pages that a listing reads. Larger than SQLite's page cache
// (2 MB by default): pages the server read at start (its scan of the jobs) and kept in memory
// would hide garbage written under them, as in any store of real size most pages are not cached.
void MakeStoreWithManyJobs(const std::string& path) {
  {
    StatusOr<std::unique_ptr<JobStore>> store = SqliteJobStore::Open(path);
    ASSERT_TRUE(store.ok()) << store.status().ToString();
  }
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  const char* sql =
      "WITH RECURSIVE n(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM n WHERE i < 20000) "
      "INSERT INTO jobs (id, kind, state, request, cache_key, result_key, created_ms, "
      "finished_ms, worker_id) SELECT printf('%032x', i), 'simulate', 4, X'', '', "
      "'j:' || printf('%032x', i), CAST(strftime('%s', 'now') AS INTEGER) * 1000 - 20000 + i, "
      "CAST(strftime('%s', 'now') AS INTEGER) * 1000 - 20000 + i, hex(randomblob(50)) FROM n";
  EXPECT_EQ(sqlite3_exec(db, sql, nullptr, nullptr, nullptr), SQLITE_OK) << sqlite3_errmsg(db);
  sqlite3_close(db);
}

// ---------------------------------------------------------------------------------------------

TEST(ServerStoreFaultsTest, AFullDiskFailsTheJobTurnsHealthNotServingAndRecovers) {
  // The mount namespace first, before any thread of gRPC or the server starts.
  TempDir dir("drillbif_server_faults");
  ASSERT_FALSE(dir.path().empty());
  const std::string mount_dir = dir.path() + "/small";
  ASSERT_TRUE(std::filesystem::create_directory(mount_dir));
  constexpr int64_t kDiskBytes = 2 << 20;
  drillbif::testing::SmallTmpfs tmpfs(mount_dir, kDiskBytes);
  if (!tmpfs.error().empty()) GTEST_SKIP() << "no small file system to fill: " << tmpfs.error();

  StatusOr<std::unique_ptr<Server>> started = Server::Start(OptionsFor(mount_dir + "/jobs.db"));
  ASSERT_TRUE(started.ok()) << started.status().ToString();
  Server& server = **started;
  Client client(server);
  ASSERT_EQ(client.Health(), kServing);

  // A job whose result does not fit on the disk ends FAILED with the reason, not RUNNING.
  Operation big;
  grpc::Status s = client.Submit(LargeResultSimulate(), &big);
  ASSERT_TRUE(s.ok()) << s.error_message();
  const Clock::time_point run_start = Clock::now();
  big = client.WaitDone(big.name(), 30);
  std::printf("large-result job done after %.2f s\n", SecondsSince(run_start));
  ASSERT_TRUE(big.done()) << "stuck in " << v1::JobState_Name(MetadataOf(big).state());
  EXPECT_EQ(MetadataOf(big).state(), v1::FAILED);
  EXPECT_EQ(big.error().code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_THAT(big.error().message(), StartsWith("the job store's disk is full"));
  ExpectNoSql(big.error().message());
  // Failing it dropped its partial result, and the store's probe gave the space back: the
  // fault clears by itself, and more than the 1 MiB chunk it had written (WorkerPoolOptions::
  // chunk_bytes) is free on the 2 MiB disk again.
  const Clock::time_point fail_time = Clock::now();
  while (!server.store().Health().ok() && SecondsSince(fail_time) < kHealthWaitSeconds) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_TRUE(server.store().Health().ok()) << server.store().Health().ToString();
  std::printf("store fault cleared %.3f s after the job failed\n", SecondsSince(fail_time));
  EXPECT_GE(client.WaitForHealth(kServing), 0);

  // The disk filled to the last byte by another file: the next write fails, and the server
  // says NOT_SERVING for as long as the disk stays full.
  const std::string filler = mount_dir + "/filler";
  const int64_t free_bytes = drillbif::testing::FillDisk(filler);
  std::printf("free on the disk after the failed job: %lld bytes\n",
              static_cast<long long>(free_bytes));
  EXPECT_GT(free_bytes, int64_t{1} << 20);
  Operation refused;
  s = client.Submit(SmallSimulate(), &refused);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_EQ(s.error_message(), "the job store's disk is full");
  ExpectNoSql(s.error_message());
  const double down = client.WaitForHealth(kNotServing);
  EXPECT_GE(down, 0) << "health did not turn NOT_SERVING with the disk full";
  std::printf("NOT_SERVING %.3f s after the failed write (probe every %d ms)\n", down, kProbeMs);
  // Still NOT_SERVING several probe intervals later: probes fail while the disk is full.
  std::this_thread::sleep_for(std::chrono::milliseconds(5 * kProbeMs));
  EXPECT_EQ(client.Health(), kNotServing);
  auto [healthz_status, healthz_body] = client.HttpGet("/healthz");
  EXPECT_EQ(healthz_status, 503) << healthz_body;
  EXPECT_EQ(healthz_body, R"({"status":"NOT_SERVING"})");

  // Reads still answer: the failed job is there with its reason; cancelling it is answered
  // too (it is already finished), and changes nothing.
  Operation read;
  s = client.Get(big.name(), &read);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(MetadataOf(read).state(), v1::FAILED);
  EXPECT_EQ(read.error().message(), big.error().message());
  s = client.Cancel(big.name());
  EXPECT_EQ(s.error_code(), grpc::StatusCode::FAILED_PRECONDITION) << s.error_message();
  EXPECT_THAT(s.error_message(), HasSubstr("already finished (FAILED)"));
  ExpectNoSql(s.error_message());
  s = client.Get(big.name(), &read);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_EQ(MetadataOf(read).state(), v1::FAILED);
  s = client.Cancel("operations/00000000000000000000000000000000");
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND) << s.error_message();
  ExpectNoSql(s.error_message());
  // A submit over REST gets the same reason.
  {
    httplib::Client http("127.0.0.1", server.http_port());
    httplib::Result posted = http.Post(
        "/v1/jobs:simulate", R"({"request": {"transientPeriods": 3, "samplePeriods": 3}})",
        "application/json");
    ASSERT_TRUE(posted);
    EXPECT_EQ(posted->status, 429) << posted->body;
    const std::string message = ExpectJsonError(posted->body, "RESOURCE_EXHAUSTED");
    EXPECT_EQ(message, "the job store's disk is full");
    ExpectNoSql(message);
  }

  // Space freed: health comes back, and a small job runs to the end.
  ASSERT_TRUE(std::filesystem::remove(filler));
  const double recovered = client.WaitForHealth(kServing);
  EXPECT_GE(recovered, 0) << "health did not return to SERVING once space was freed";
  std::printf("SERVING %.3f s after the filler was deleted\n", recovered);
  auto [after_status, after_body] = client.HttpGet("/healthz");
  EXPECT_EQ(after_status, 200) << after_body;
  Operation small;
  s = client.Submit(SmallSimulate(), &small);
  ASSERT_TRUE(s.ok()) << s.error_message();
  small = client.WaitDone(small.name(), 20);
  EXPECT_EQ(MetadataOf(small).state(), v1::SUCCEEDED) << small.error().message();
  server.Shutdown();
}

TEST(ServerStoreFaultsTest, CorruptionUnderARunningServerTurnsHealthNotServing) {
  TempDir dir("drillbif_server_faults");
  const std::string path = dir.path() + "/store.db";
  MakeStoreWithManyJobs(path);
  const int64_t pages = FileSize(path) / 4096;
  ASSERT_GT(pages, 200);
  StatusOr<std::unique_ptr<Server>> started = Server::Start(OptionsFor(path));
  ASSERT_TRUE(started.ok()) << started.status().ToString();
  Server& server = **started;
  Client client(server);
  ASSERT_EQ(client.Health(), kServing);

  // The middle half of the file becomes garbage behind the server's back.
  OverwritePages(path, 4096, pages / 4, pages / 2);

  // Listing every job reads those pages: DATA_LOSS, named, without SQL.
  google::longrunning::ListOperationsRequest list;
  list.set_page_size(1000);
  grpc::Status failure;
  for (int page = 0; page < 30 && failure.ok(); ++page) {
    google::longrunning::ListOperationsResponse response;
    auto context = Client::Context();
    failure = client.operations().ListOperations(context.get(), list, &response);
    if (!failure.ok() || response.next_page_token().empty()) break;
    list.set_page_token(response.next_page_token());
  }
  EXPECT_EQ(failure.error_code(), grpc::StatusCode::DATA_LOSS) << failure.error_message();
  EXPECT_EQ(failure.error_message(), "the job store is corrupt");
  ExpectNoSql(failure.error_message());
  // The same page over REST: 500 with the same reason in the JSON error.
  auto [list_status, list_body] = client.HttpGet(
      "/v1/operations?pageSize=1000" +
      (list.page_token().empty() ? std::string() : "&pageToken=" + list.page_token()));
  EXPECT_EQ(list_status, 500) << list_body.substr(0, 300);
  const std::string message = ExpectJsonError(list_body, "DATA_LOSS");
  EXPECT_EQ(message, "the job store is corrupt");
  ExpectNoSql(message);

  // The fault stays: the probe's integrity check fails, health says NOT_SERVING.
  const double down = client.WaitForHealth(kNotServing);
  EXPECT_GE(down, 0) << "health did not turn NOT_SERVING with a corrupt store";
  std::printf("NOT_SERVING %.3f s after the corrupt read (probe every %d ms)\n", down, kProbeMs);
  std::this_thread::sleep_for(std::chrono::milliseconds(5 * kProbeMs));
  EXPECT_EQ(client.Health(), kNotServing);
  auto [healthz_status, healthz_body] = client.HttpGet("/healthz");
  EXPECT_EQ(healthz_status, 503) << healthz_body;

  // Every answer meanwhile is either a success or names the problem without SQL; none crashes
  // the server.
  Operation op;
  grpc::Status s = client.Submit(SmallSimulate(), &op);
  if (!s.ok()) {
    EXPECT_THAT(s.error_message(), StartsWith("the job store")) << s.error_message();
    ExpectNoSql(s.error_message());
  }
  for (int i : {1, 10000, 20000}) {
    char id[64];
    std::snprintf(id, sizeof(id), "operations/%032x", i);
    s = client.Get(id, &op);
    if (!s.ok()) {
      EXPECT_EQ(s.error_code(), grpc::StatusCode::DATA_LOSS) << s.error_message();
      EXPECT_THAT(s.error_message(), StartsWith("the job store")) << s.error_message();
      ExpectNoSql(s.error_message());
    }
    s = client.Cancel(id);
    if (!s.ok()) {
      EXPECT_THAT(s.error_message(), StartsWith("the job store")) << s.error_message();
      ExpectNoSql(s.error_message());
    }
  }
  EXPECT_EQ(client.Health(), kNotServing);
  server.Shutdown();
}

TEST(ServerStoreFaultsTest, ACorruptFileIsRefusedAtStartWithAClearStatus) {
  TempDir dir("drillbif_server_faults");
  const std::string path = dir.path() + "/store.db";
  MakeStoreWithManyJobs(path);
  const int64_t pages = FileSize(path) / 4096;
  ASSERT_GT(pages, 200);
  OverwritePages(path, 4096, pages / 2, 8);

  StatusOr<std::unique_ptr<Server>> started = Server::Start(OptionsFor(path));
  ASSERT_FALSE(started.ok());
  EXPECT_EQ(started.status().code(), StatusCode::kDataLoss);
  const std::string& message = started.status().message();
  std::printf("Server::Start: %s\n", started.status().ToString().c_str());
  EXPECT_THAT(message, StartsWith("the job store failed its integrity check: "));
  EXPECT_THAT(message, HasSubstr(path));
  for (const char* word : {"SELECT", "INSERT", "UPDATE", "DELETE", "BEGIN", "PRAGMA"}) {
    EXPECT_THAT(message, Not(HasSubstr(word)));
  }
}

}  // namespace
}  // namespace drillbif::server
