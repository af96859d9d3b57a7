// The drillbif-server binary as a process: kill -9 with jobs queued and running, then a restart
// on the same SQLite file: every job completes, none is lost, none completes twice, and the
// results are the job runner's. Also a graceful SIGTERM: the running job is requeued, not lost.
// The binary's path comes from the build (DRILLBIF_SERVER_BINARY, server/CMakeLists.txt).
#include "support/server_process.h"

#include <gmock/gmock.h>
#include <google/protobuf/util/message_differencer.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "jobs/continue_job.h"
#include "jobs/optimum_map_job.h"
#include "jobs/simulate_job.h"
#include "jobs/sweep_job.h"
#include "server/store/sqlite_job_store.h"
#include "support/operations.h"
#include "support/small_requests.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

using drillbif::testing::ContextWithDeadline;
using drillbif::testing::GetOperation;
using drillbif::testing::MetadataOf;
using drillbif::testing::ServerProcess;
using drillbif::testing::WaitDone;
using google::longrunning::Operation;
using google::protobuf::util::MessageDifferencer;

using drillbif::testing::SmallSweep;
using drillbif::testing::TempDir;

// One worker and no worker reserved for short jobs: every job waits for the one worker, so the
// short ones are still queued behind the long one when the server is killed.
const std::vector<std::string> kOneWorker = {"--workers", "1", "--short-workers", "0"};

// Submits one long sweep (about a second of engine time on one worker) and three short ones;
// returns the requests and operation names, the long one first.
void SubmitJobs(v1::Jobs::Stub& jobs, std::vector<v1::SweepRequest>* requests,
                std::vector<std::string>* names) {
  requests->push_back(SmallSweep(0.0, 300));
  for (int i = 1; i <= 3; ++i) requests->push_back(SmallSweep(0.1 + 0.01 * i, 5));
  for (const v1::SweepRequest& sweep : *requests) {
    v1::SubmitSweepRequest submit;
    *submit.mutable_request() = sweep;
    Operation op;
    auto context = ContextWithDeadline();
    grpc::Status s = jobs.SubmitSweep(context.get(), submit, &op);
    ASSERT_TRUE(s.ok()) << s.error_message();
    names->push_back(op.name());
  }
}

// Waits until the first job runs on the single worker and has reported progress, so that a kill
// interrupts it in the engine (the others are then still queued behind it).
void WaitUntilRunning(google::longrunning::Operations::Stub& stub, const std::string& name) {
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (std::chrono::steady_clock::now() < give_up) {
    const v1::JobMetadata m = MetadataOf(GetOperation(stub, name));
    if (m.state() == v1::RUNNING && m.progress() > 0) return;
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ADD_FAILURE() << name << " never ran";
}

// After a restart: every job SUCCEEDED with the runner's result; the interrupted one ran twice.
void ExpectAllCompleteOnce(ServerProcess& server, const std::vector<v1::SweepRequest>& requests,
                           const std::vector<std::string>& names, int expected_first_attempts) {
  auto operations = google::longrunning::Operations::NewStub(server.channel());
  for (size_t i = 0; i < names.size(); ++i) {
    const Operation op = WaitDone(*operations, names[i]);
    const v1::JobMetadata m = MetadataOf(op);
    EXPECT_EQ(m.state(), v1::SUCCEEDED) << names[i];
    EXPECT_EQ(m.attempts(), i == 0 ? expected_first_attempts : 1) << names[i];
    v1::SweepResult served;
    ASSERT_TRUE(op.response().UnpackTo(&served));
    StatusOr<v1::SweepResult> direct = jobs::RunSweep(requests[i]);
    ASSERT_TRUE(direct.ok());
    served.clear_wall_seconds();
    direct.value().clear_wall_seconds();
    EXPECT_TRUE(MessageDifferencer::Equals(served, *direct)) << names[i];
  }
  // Exactly these jobs, each finished once (the store refuses a second completion; a lost or
  // duplicated job would show here as a missing or extra record).
  google::longrunning::ListOperationsRequest list;
  list.set_page_size(100);
  google::longrunning::ListOperationsResponse page;
  auto context = ContextWithDeadline();
  ASSERT_TRUE(operations->ListOperations(context.get(), list, &page).ok());
  ASSERT_EQ(page.operations_size(), static_cast<int>(names.size()));
  for (int i = 0; i < page.operations_size(); ++i) {
    EXPECT_EQ(page.operations(i).name(), names[i]);
    EXPECT_TRUE(page.operations(i).done());
  }
}

TEST(ServerProcess, KillNineWithJobsQueuedAndRunningThenRestartCompletesEveryJobOnce) {
  TempDir dir("drillbif_process");
  const std::string db = dir.path() + "/jobs.db";
  std::vector<v1::SweepRequest> requests;
  std::vector<std::string> names;
  {
    ServerProcess server(dir.path(), db, kOneWorker);
    auto jobs = v1::Jobs::NewStub(server.channel());
    auto operations = google::longrunning::Operations::NewStub(server.channel());
    SubmitJobs(*jobs, &requests, &names);
    WaitUntilRunning(*operations, names[0]);
    for (size_t i = 1; i < names.size(); ++i) {
      EXPECT_EQ(MetadataOf(GetOperation(*operations, names[i])).state(), v1::QUEUED);
    }
    const int status = server.Kill(SIGKILL);
    EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);
  }
  ServerProcess restarted(dir.path(), db, kOneWorker);
  // The interrupted run counts as an attempt: the job ran twice, completed once.
  ExpectAllCompleteOnce(restarted, requests, names, /*expected_first_attempts=*/2);
}

TEST(ServerProcess, SigtermRequeuesTheRunningJobAndExitsCleanly) {
  TempDir dir("drillbif_process");
  const std::string db = dir.path() + "/jobs.db";
  std::vector<v1::SweepRequest> requests;
  std::vector<std::string> names;
  {
    ServerProcess server(dir.path(), db, kOneWorker);
    auto jobs = v1::Jobs::NewStub(server.channel());
    auto operations = google::longrunning::Operations::NewStub(server.channel());
    SubmitJobs(*jobs, &requests, &names);
    WaitUntilRunning(*operations, names[0]);
    const auto sent = std::chrono::steady_clock::now();
    const int status = server.Kill(SIGTERM);
    const double ms =
        std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - sent).count();
    // Measured ~2.1 s: the job stops in ~50 ms, then gRPC's Shutdown waits out its 2 s grace
    // while this client's connection is open (docs/service.md, "Not done").
    std::printf("graceful shutdown with a running job: %.0f ms\n", ms);
    EXPECT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0) << status;
  }
  {
    // Requeued, not failed or lost: queued again, and its interrupted attempt is not counted.
    StatusOr<std::unique_ptr<JobStore>> store = SqliteJobStore::Open(db);
    ASSERT_TRUE(store.ok());
    StatusOr<JobRecord> first = (*store)->Get(names[0].substr(std::string("operations/").size()));
    ASSERT_TRUE(first.ok());
    EXPECT_EQ(first->state, JobState::kQueued);
  }
  ServerProcess restarted(dir.path(), db, kOneWorker);
  ExpectAllCompleteOnce(restarted, requests, names, /*expected_first_attempts=*/1);
}

// An optimum map of six cells on the small box over b: ~0.5 s a cell on one worker.
v1::OptimumMapRequest SixCellMap() { return drillbif::testing::SmallBoxMap(0.14, 0.165, 6); }

// The cells a map finished before kill -9 are not computed again by the restarted server: they
// are its children in the store, read back; the result equals a map computed in one go.
TEST(ServerProcess, KillNineDuringAnOptimumMapThenRestartResumesItsFinishedCells) {
  TempDir dir("drillbif_process");
  const std::string db = dir.path() + "/jobs.db";
  std::string name;
  double progress = 0;
  {
    ServerProcess server(dir.path(), db, kOneWorker);
    auto jobs = v1::Jobs::NewStub(server.channel());
    auto operations = google::longrunning::Operations::NewStub(server.channel());
    v1::SubmitOptimumMapRequest submit;
    *submit.mutable_request() = SixCellMap();
    Operation op;
    ASSERT_TRUE(jobs->SubmitOptimumMap(ContextWithDeadline().get(), submit, &op).ok());
    name = op.name();
    // Two cells done (progress counts the cells in), not all.
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (std::chrono::steady_clock::now() < give_up && progress < 2.0 / 6) {
      progress = MetadataOf(GetOperation(*operations, name)).progress();
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
    }
    ASSERT_GE(progress, 2.0 / 6);
    ASSERT_LT(progress, 1.0);
    server.Kill(SIGKILL);
  }
  ServerProcess restarted(dir.path(), db, kOneWorker);
  auto operations = google::longrunning::Operations::NewStub(restarted.channel());
  const Operation op = WaitDone(*operations, name);
  ASSERT_TRUE(op.has_response()) << op.error().message();
  EXPECT_EQ(MetadataOf(op).attempts(), 2);
  v1::OptimumMapResult served;
  ASSERT_TRUE(op.response().UnpackTo(&served));
  EXPECT_EQ(served.status(), "COMPLETED") << served.message();
  std::printf("killed at progress %.2f; %lld of 6 cells resumed\n", progress,
              static_cast<long long>(served.cells_resumed()));
  EXPECT_GE(served.cells_resumed(), static_cast<int64_t>(progress * 6 + 1e-9));
  EXPECT_LT(served.cells_resumed(), 6);
  ASSERT_EQ(served.cells_size(), 6);
  const StatusOr<v1::OptimumMapResult> direct = jobs::RunOptimumMap(SixCellMap());
  ASSERT_TRUE(direct.ok());
  for (const v1::OptimumMapCell& cell : served.cells()) {
    const auto same = std::find_if(direct->cells().begin(), direct->cells().end(),
                                   [&](const auto& c) { return c.index(0) == cell.index(0); });
    ASSERT_NE(same, direct->cells().end());
    EXPECT_EQ(cell.optimum().params().SerializeAsString(),
              same->optimum().params().SerializeAsString());
    EXPECT_EQ(cell.optimum().rop(), same->optimum().rop());
  }
}

}  // namespace
}  // namespace drillbif::server
