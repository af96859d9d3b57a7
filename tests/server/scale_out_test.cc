// Several drillbif-server processes on one PostgreSQL store (a throwaway cluster): an API process
// that runs no jobs and worker processes that run them, claims as leases. A worker killed with
// kill -9 while it runs a job loses it to the other worker once its lease expires: every job
// finishes exactly once, with the result a direct run gives.
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "jobs/sweep_job.h"
#include "server/store/postgres_job_store.h"
#include "support/operations.h"
#include "support/postgres_cluster.h"
#include "support/server_process.h"
#include "support/small_requests.h"
#include "support/temp_dir.h"
// After Eigen (through the jobs headers): httplib brings <resolv.h>, whose _res macro breaks
// Eigen's product kernels.
#include <httplib.h>

namespace drillbif::server {
namespace {

using drillbif::testing::ContextWithDeadline;
using drillbif::testing::GetOperation;
using drillbif::testing::MetadataOf;
using drillbif::testing::PostgresCluster;
using drillbif::testing::ServerProcess;
using drillbif::testing::SmallSweep;
using drillbif::testing::TempDir;
using drillbif::testing::WaitDone;
using google::longrunning::Operation;
using google::protobuf::util::MessageDifferencer;

// A lease of 1.5 s: the heartbeat renews it every 0.5 s, and a dead worker's job is taken back
// within 2 s of its last renewal.
constexpr const char* kLeaseMs = "1500";

// A process of `role` on the cluster's database, its files in dir/name.
std::unique_ptr<ServerProcess> Start(const TempDir& dir, const std::string& name,
                                     const std::string& uri, const std::string& role) {
  const std::string sub = dir.path() + "/" + name;
  std::filesystem::create_directories(sub);
  return std::make_unique<ServerProcess>(
      sub, sub + "/unused.db",
      std::vector<std::string>{"--store", uri, "--role", role, "--workers", "1", "--short-workers",
                               "0", "--lease-ms", kLeaseMs});
}

std::string Submit(v1::Jobs::Stub& jobs, const v1::SweepRequest& sweep) {
  v1::SubmitSweepRequest submit;
  *submit.mutable_request() = sweep;
  Operation op;
  auto context = ContextWithDeadline();
  const grpc::Status s = jobs.SubmitSweep(context.get(), submit, &op);
  EXPECT_TRUE(s.ok()) << s.error_message();
  return op.name();
}

// The id of a job in the store: the operation's name is "operations/<id>".
std::string JobId(const std::string& name) { return name.substr(name.find('/') + 1); }

TEST(ScaleOut, AWorkerKilledWhileRunningLosesItsJobToTheOtherAndEveryJobFinishesOnce) {
  PostgresCluster cluster;
  ASSERT_TRUE(cluster.ok() && cluster.CreateDatabase("jobs")) << cluster.error();
  const std::string uri = cluster.Uri("jobs");
  TempDir dir("drillbif_scale_out");
  std::unique_ptr<ServerProcess> api = Start(dir, "api", uri, "api");
  std::vector<std::unique_ptr<ServerProcess>> workers;
  workers.push_back(Start(dir, "worker0", uri, "worker"));
  workers.push_back(Start(dir, "worker1", uri, "worker"));
  ASSERT_TRUE(api->serving() && workers[0]->serving() && workers[1]->serving());
  auto jobs = v1::Jobs::NewStub(api->channel());
  auto operations = google::longrunning::Operations::NewStub(api->channel());

  // Two long sweeps (about a second of engine time each) first, then 40 short ones.
  std::vector<v1::SweepRequest> requests = {SmallSweep(0.0, 300), SmallSweep(0.001, 300)};
  for (int i = 0; i < 40; ++i) requests.push_back(SmallSweep(0.1 + 0.001 * i, 5));
  std::vector<std::string> names;
  for (const v1::SweepRequest& sweep : requests) names.push_back(Submit(*jobs, sweep));

  // Once a long one runs and has reported progress, kill its worker.
  std::unique_ptr<JobStore> store = PostgresJobStore::Open(uri).value();
  std::optional<JobRecord> victim;
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  while (!victim && std::chrono::steady_clock::now() < give_up) {
    for (int i = 0; i < 2 && !victim; ++i) {
      StatusOr<JobRecord> job = store->Get(JobId(names[i]));
      ASSERT_TRUE(job.ok()) << job.status().ToString();
      if (job->state == JobState::kRunning && job->progress > 0) victim = *job;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_TRUE(victim.has_value()) << "no long job ran";
  EXPECT_GT(victim->lease_expires_ms, 0);
  int killed = -1;
  for (int w = 0; w < 2; ++w) {
    if (victim->worker_id.find("-" + std::to_string(workers[w]->pid()) + "-worker") !=
        std::string::npos) {
      killed = w;
    }
  }
  ASSERT_GE(killed, 0) << "worker id " << victim->worker_id << " names neither process";
  const int status = workers[killed]->Kill(SIGKILL);
  EXPECT_TRUE(WIFSIGNALED(status) && WTERMSIG(status) == SIGKILL);

  // Every job finishes, through the API process, with the direct run's result.
  for (size_t i = 0; i < names.size(); ++i) {
    const Operation op = WaitDone(*operations, names[i]);
    const v1::JobMetadata m = MetadataOf(op);
    ASSERT_EQ(m.state(), v1::SUCCEEDED) << names[i];
    const bool interrupted = JobId(names[i]) == victim->id;
    EXPECT_EQ(m.attempts(), interrupted ? 2 : 1) << names[i];
    v1::SweepResult served;
    ASSERT_TRUE(op.response().UnpackTo(&served));
    StatusOr<v1::SweepResult> direct = jobs::RunSweep(requests[i]);
    ASSERT_TRUE(direct.ok());
    served.clear_wall_seconds();
    direct.value().clear_wall_seconds();
    EXPECT_TRUE(MessageDifferencer::Equals(served, *direct)) << names[i];
  }
  // The interrupted job was finished by the surviving worker, in its second run.
  const JobRecord finished = store->Get(victim->id).value();
  EXPECT_EQ(finished.run, victim->run + 1);
  EXPECT_NE(finished.worker_id, victim->worker_id);
  // Exactly these jobs, each finished once.
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

TEST(ScaleOut, AWorkerServesNoJobsAndAnApiProcessRunsNone) {
  PostgresCluster cluster;
  ASSERT_TRUE(cluster.ok() && cluster.CreateDatabase("jobs")) << cluster.error();
  const std::string uri = cluster.Uri("jobs");
  TempDir dir("drillbif_roles");
  std::unique_ptr<ServerProcess> worker = Start(dir, "worker", uri, "worker");
  auto worker_jobs = v1::Jobs::NewStub(worker->channel());
  v1::SubmitSweepRequest submit;
  *submit.mutable_request() = SmallSweep(0.1, 5);
  Operation op;
  auto context = ContextWithDeadline();
  EXPECT_EQ(worker_jobs->SubmitSweep(context.get(), submit, &op).error_code(),
            grpc::StatusCode::UNIMPLEMENTED);
  // Over REST: 501; /metrics and the health check are served.
  httplib::Client http("127.0.0.1", worker->http_port());
  const httplib::Result rest = http.Post("/v1/jobs:sweep", "{}", "application/json");
  ASSERT_TRUE(rest);
  EXPECT_EQ(rest->status, 501);
  const httplib::Result metrics = http.Get("/metrics");
  ASSERT_TRUE(metrics);
  EXPECT_EQ(metrics->status, 200);
  worker->Kill(SIGTERM);

  // With no worker, a job submitted to an API process stays queued.
  std::unique_ptr<ServerProcess> api = Start(dir, "api", uri, "api");
  auto jobs = v1::Jobs::NewStub(api->channel());
  auto operations = google::longrunning::Operations::NewStub(api->channel());
  const std::string name = Submit(*jobs, SmallSweep(0.1, 5));
  std::this_thread::sleep_for(std::chrono::milliseconds(1000));
  EXPECT_EQ(MetadataOf(GetOperation(*operations, name)).state(), v1::QUEUED);
  // A worker that joins runs it.
  std::unique_ptr<ServerProcess> joined = Start(dir, "joined", uri, "worker");
  EXPECT_EQ(MetadataOf(WaitDone(*operations, name)).state(), v1::SUCCEEDED);
}

}  // namespace
}  // namespace drillbif::server
