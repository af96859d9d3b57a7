// Shutting the drillbif-server binary down (a child process on 127.0.0.1): SIGTERM with both
// workers busy on long jobs exits 0 within the grace period and requeues the jobs, which run
// again after a restart on the same file; a shutdown slower than a tiny grace is ended by the
// watchdog (exit 3) near the grace; a second SIGTERM exits at once (exit 3). Also a kind's time
// limit given on the command line (--job-limit KIND.seconds=S) fails a run that reaches it with
// DEADLINE_EXCEEDED, as the operation's error.
#include <gmock/gmock.h>
#include <google/protobuf/util/time_util.h>
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "server/store/sqlite_job_store.h"
#include "support/operations.h"
#include "support/server_process.h"
#include "support/small_requests.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

using drillbif::testing::ContextWithDeadline;
using drillbif::testing::GetOperation;
using drillbif::testing::MetadataOf;
using drillbif::testing::ServerExit;
using drillbif::testing::ServerProcess;
using drillbif::testing::WaitDone;
using google::longrunning::Operation;
using ::testing::HasSubstr;
using Clock = std::chrono::steady_clock;

// Submits a LongSweep and a LongContinuation (minutes each); returns their operation names.
std::vector<std::string> SubmitLongJobs(ServerProcess& server) {
  auto jobs = v1::Jobs::NewStub(server.channel());
  std::vector<std::string> names;
  Operation op;
  {
    v1::SubmitSweepRequest submit;
    *submit.mutable_request() = testing::LongSweep();
    auto context = ContextWithDeadline();
    const grpc::Status s = jobs->SubmitSweep(context.get(), submit, &op);
    EXPECT_TRUE(s.ok()) << s.error_message();
    names.push_back(op.name());
  }
  {
    v1::SubmitContinueRequest submit;
    *submit.mutable_request() = testing::LongContinuation();
    auto context = ContextWithDeadline();
    const grpc::Status s = jobs->SubmitContinue(context.get(), submit, &op);
    EXPECT_TRUE(s.ok()) << s.error_message();
    names.push_back(op.name());
  }
  return names;
}

// Waits (up to 30 s) until the job runs its engine: RUNNING with progress recorded (a
// continuation past its start search's 5%).
void WaitUntilComputing(ServerProcess& server, const std::string& name) {
  auto operations = google::longrunning::Operations::NewStub(server.channel());
  const auto give_up = Clock::now() + std::chrono::seconds(30);
  v1::JobMetadata m;
  while (Clock::now() < give_up) {
    m = MetadataOf(GetOperation(*operations, name));
    const double floor = m.kind() == v1::CONTINUE ? 0.05 : 0.0;
    if (m.state() == v1::RUNNING && m.progress() > floor) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ADD_FAILURE() << name << " never computed; last seen " << m.ShortDebugString();
}

// Cancels the job and expects it CANCELLED.
void CancelAndExpectCancelled(ServerProcess& server, const std::string& name) {
  auto operations = google::longrunning::Operations::NewStub(server.channel());
  google::longrunning::CancelOperationRequest cancel;
  cancel.set_name(name);
  google::protobuf::Empty empty;
  auto context = ContextWithDeadline();
  ASSERT_TRUE(operations->CancelOperation(context.get(), cancel, &empty).ok());
  EXPECT_EQ(MetadataOf(WaitDone(*operations, name, 10)).state(), v1::CANCELLED) << name;
}

// The store's record of the operation `name` ("operations/{id}"), read from the file while no
// server runs.
JobRecord StoredJob(const std::string& db, const std::string& name) {
  StatusOr<std::unique_ptr<JobStore>> store = SqliteJobStore::Open(db);
  EXPECT_TRUE(store.ok()) << store.status().ToString();
  if (!store.ok()) return {};
  StatusOr<JobRecord> job = (*store)->Get(name.substr(std::string("operations/").size()));
  EXPECT_TRUE(job.ok()) << job.status().ToString();
  return job.ok() ? *job : JobRecord();
}

std::string ReadFile(const std::string& path) {
  std::ifstream in(path);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// The process's exit after the signal sent last, waiting up to 30 s (a test failure if none).
ServerExit WaitExit(ServerProcess& server) {
  const std::optional<ServerExit> exit = server.WaitExit(std::chrono::seconds(30));
  EXPECT_TRUE(exit.has_value()) << "the server did not exit within 30 s";
  return exit.value_or(ServerExit{});
}

TEST(Shutdown, SigtermWithBothWorkersBusyExitsWithinTheGraceAndRequeuesBoth) {
  constexpr int kGraceMs = 5000;
  const std::vector<std::string> flags = {"--workers", "2", "--shutdown-grace-ms",
                                          std::to_string(kGraceMs)};
  testing::TempDir dir("drillbif_shutdown");
  const std::string db = dir.path() + "/jobs.db";
  std::vector<std::string> names;
  {
    ServerProcess server(dir.path(), db, flags);
    ASSERT_GT(server.grpc_port(), 0);
    names = SubmitLongJobs(server);
    for (const std::string& name : names) WaitUntilComputing(server, name);
    server.Signal(SIGTERM);
    const ServerExit exit = WaitExit(server);
    std::printf("SIGTERM with 2 running jobs -> exit %d after %.0f ms (grace %d ms)\n", exit.code(),
                exit.ms, kGraceMs);
    EXPECT_EQ(exit.code(), 0) << "see " << server.log_path();
    // Within the grace, plus 1 s for a loaded machine to schedule the exit.
    EXPECT_LT(exit.ms, kGraceMs + 1000);
  }
  // Both requeued: QUEUED in the file, their interrupted attempt not counted.
  for (const std::string& name : names) {
    const JobRecord job = StoredJob(db, name);
    EXPECT_EQ(job.state, JobState::kQueued) << name;
  }
  // After a restart on the same file both run again (first counted attempt), and a cancel ends
  // them.
  ServerProcess restarted(dir.path(), db, flags);
  ASSERT_GT(restarted.grpc_port(), 0);
  auto operations = google::longrunning::Operations::NewStub(restarted.channel());
  for (const std::string& name : names) {
    WaitUntilComputing(restarted, name);
    EXPECT_EQ(MetadataOf(GetOperation(*operations, name)).attempts(), 1) << name;
  }
  for (const std::string& name : names) CancelAndExpectCancelled(restarted, name);
}

// The shutdown outlasts a 300 ms grace: this client's connection stays open, and gRPC's
// Shutdown waits up to 2 s for it (docs/service.md, "Not done"). The watchdog ends the process
// with exit 3 at the grace; 1 s of margin for a loaded machine. The job, stopped or not, runs
// again after a restart.
TEST(Shutdown, AShutdownLongerThanTheGraceIsEndedByTheWatchdogNearTheGrace) {
  constexpr int kGraceMs = 300;
  const std::vector<std::string> flags = {"--workers", "1", "--shutdown-grace-ms",
                                          std::to_string(kGraceMs)};
  testing::TempDir dir("drillbif_shutdown");
  const std::string db = dir.path() + "/jobs.db";
  std::string name;
  {
    ServerProcess server(dir.path(), db, flags);
    ASSERT_GT(server.grpc_port(), 0);
    name = SubmitLongJobs(server)[0];
    WaitUntilComputing(server, name);
    server.Signal(SIGTERM);
    const ServerExit exit = WaitExit(server);
    std::printf("SIGTERM, grace %d ms -> exit %d after %.0f ms\n", kGraceMs, exit.code(), exit.ms);
    EXPECT_EQ(exit.code(), 3) << "see " << server.log_path();
    EXPECT_GE(exit.ms, kGraceMs);
    EXPECT_LT(exit.ms, kGraceMs + 1000);
    EXPECT_THAT(ReadFile(server.log_path()), HasSubstr("shutdown did not finish within 300 ms"));
  }
  ServerProcess restarted(dir.path(), db, flags);
  ASSERT_GT(restarted.grpc_port(), 0);
  WaitUntilComputing(restarted, name);
  CancelAndExpectCancelled(restarted, name);
}

// A second SIGTERM 100 ms after the first, while the graceful shutdown still waits (as above, for
// this client's connection), ends the process at once with exit 3: well before the 5 s grace
// (within 1 s of the second signal, for a loaded machine).
TEST(Shutdown, ASecondSigtermExitsAtOnce) {
  testing::TempDir dir("drillbif_shutdown");
  ServerProcess server(dir.path(), dir.path() + "/jobs.db",
                       {"--workers", "1", "--shutdown-grace-ms", "5000"});
  ASSERT_GT(server.grpc_port(), 0);
  const std::string name = SubmitLongJobs(server)[0];
  WaitUntilComputing(server, name);
  server.Signal(SIGTERM);
  ASSERT_FALSE(server.WaitExit(std::chrono::milliseconds(100)).has_value())
      << "the graceful shutdown ended within 100 ms: nothing left for a second signal to cut";
  server.Signal(SIGTERM);
  const ServerExit exit = WaitExit(server);
  std::printf("second SIGTERM -> exit %d after %.0f ms\n", exit.code(), exit.ms);
  EXPECT_EQ(exit.code(), 3) << "see " << server.log_path();
  EXPECT_LT(exit.ms, 1000);
  EXPECT_THAT(ReadFile(server.log_path()), HasSubstr("received again"));
}

// A time limit lowered across a restart applies to the jobs queued before it: the requeued long
// sweep runs under --job-limit sweep.seconds=1 and fails with DEADLINE_EXCEEDED within a second
// of reaching it (the limit is checked at every progress callback, about every 10 ms; 1 s of
// margin for a loaded machine). Admission refuses a request estimated above the limit, so a job
// that reaches its limit is one admitted under another.
TEST(Shutdown, AJobLimitFromTheCommandLineFailsARunThatReachesItWithDeadlineExceeded) {
  testing::TempDir dir("drillbif_shutdown");
  const std::string db = dir.path() + "/jobs.db";
  std::string name;
  {
    ServerProcess server(dir.path(), db, {"--workers", "1"});
    ASSERT_GT(server.grpc_port(), 0);
    name = SubmitLongJobs(server)[0];
    WaitUntilComputing(server, name);
    server.Signal(SIGTERM);
    EXPECT_EQ(WaitExit(server).code(), 0);
  }
  ServerProcess restarted(dir.path(), db, {"--workers", "1", "--job-limit", "sweep.seconds=1"});
  ASSERT_GT(restarted.grpc_port(), 0);
  auto operations = google::longrunning::Operations::NewStub(restarted.channel());
  const Operation op = WaitDone(*operations, name, 30);
  const v1::JobMetadata m = MetadataOf(op);
  EXPECT_EQ(m.state(), v1::FAILED);
  EXPECT_EQ(op.error().code(), grpc::StatusCode::DEADLINE_EXCEEDED);
  EXPECT_THAT(op.error().message(), HasSubstr("max_seconds of sweep jobs"));
  ASSERT_TRUE(m.has_start_time() && m.has_end_time());
  const double seconds =
      static_cast<double>(
          google::protobuf::util::TimeUtil::DurationToMilliseconds(m.end_time() - m.start_time())) /
      1000;
  std::printf("sweep with a 1 s limit failed after %.2f s\n", seconds);
  EXPECT_GE(seconds, 1.0);
  EXPECT_LT(seconds, 2.0);
}

}  // namespace
}  // namespace drillbif::server
