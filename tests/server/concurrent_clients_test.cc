// The service under load: 50 concurrent clients, each on its own channel, submit 500 jobs in
// all to one real server (2 workers, a real SQLite file). Every job completes, each with the job
// runner's own result, none is lost or run for another's request. Half of the requests are
// repeats of another client's (same request, no request_id): those share a result through the
// cache (or a running job) instead of running the engine again, so the engine runs at most once
// per distinct request.
#include <google/protobuf/util/message_differencer.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "jobs/continue_job.h"
#include "jobs/simulate_job.h"
#include "jobs/sweep_job.h"
#include "server/server.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

using google::longrunning::Operation;
using google::protobuf::util::MessageDifferencer;

constexpr int kClients = 50;
constexpr int kJobsPerClient = 10;
constexpr int kDistinct = kClients * kJobsPerClient / 2;  // every request is asked twice

// Request k of the distinct set: a short simulation at its own forcing amplitude.
v1::SimulateRequest Request(int k) {
  v1::SimulateRequest r;
  r.mutable_params()->set_a(0.2 + 0.2 * k / kDistinct);
  r.set_transient_periods(20);
  r.set_sample_periods(5);
  return r;
}

std::unique_ptr<grpc::ClientContext> Context(double seconds) {
  auto context = std::make_unique<grpc::ClientContext>();
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(static_cast<int>(seconds * 1000)));
  return context;
}

TEST(ConcurrentClients, FiftyClientsFiveHundredJobsAllCompleteWithTheRunnersResults) {
  drillbif::testing::TempDir dir("drillbif_load");
  ASSERT_FALSE(dir.path().empty());
  ServerOptions options;
  options.grpc_port = 0;
  options.http_port = 0;
  options.db_path = dir.path() + "/jobs.db";
  options.workers = 2;
  StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
  ASSERT_TRUE(server.ok()) << server.status().ToString();
  const std::string address = (*server)->grpc_address();

  // Client c submits requests c, c + 50, ... of the 500, request i being distinct request
  // i mod 250: every distinct request comes from two different clients.
  std::mutex mutex;
  std::map<int, std::vector<std::string>> names;  // distinct request -> operation names
  std::atomic<int> submit_failures{0};
  std::vector<std::thread> clients;
  for (int c = 0; c < kClients; ++c) {
    clients.emplace_back([&, c] {
      auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
      auto jobs = v1::Jobs::NewStub(channel);
      for (int j = 0; j < kJobsPerClient; ++j) {
        const int k = (c + kClients * j) % kDistinct;
        v1::SubmitSimulateRequest submit;
        *submit.mutable_request() = Request(k);
        Operation op;
        auto context = Context(60);
        if (!jobs->SubmitSimulate(context.get(), submit, &op).ok()) {
          ++submit_failures;
          continue;
        }
        std::lock_guard<std::mutex> lock(mutex);
        names[k].push_back(op.name());
      }
    });
  }
  for (std::thread& t : clients) t.join();
  ASSERT_EQ(submit_failures.load(), 0);
  ASSERT_EQ(static_cast<int>(names.size()), kDistinct);

  auto channel = grpc::CreateChannel(address, grpc::InsecureChannelCredentials());
  auto operations = google::longrunning::Operations::NewStub(channel);
  int completed = 0;
  for (const auto& [k, ops] : names) {
    ASSERT_EQ(ops.size(), 2u);
    EXPECT_NE(ops[0], ops[1]);  // one operation per submit, even when they share a result
    StatusOr<v1::SimulateResult> run = jobs::RunSimulate(Request(k));
    ASSERT_TRUE(run.ok());
    v1::SimulateResult direct = *run;
    direct.clear_wall_seconds();
    for (const std::string& name : ops) {
      Operation op;
      for (int tries = 0; tries < 10 && !op.done(); ++tries) {
        google::longrunning::WaitOperationRequest wait;
        wait.set_name(name);
        wait.mutable_timeout()->set_seconds(10);
        auto context = Context(15);
        ASSERT_TRUE(operations->WaitOperation(context.get(), wait, &op).ok()) << name;
      }
      ASSERT_TRUE(op.done()) << name;
      v1::SimulateResult served;
      ASSERT_TRUE(op.has_response()) << op.ShortDebugString().substr(0, 300);
      ASSERT_TRUE(op.response().UnpackTo(&served));
      served.clear_wall_seconds();
      EXPECT_TRUE(MessageDifferencer::Equals(served, direct)) << "request " << k;
      ++completed;
    }
  }
  EXPECT_EQ(completed, kClients * kJobsPerClient);
  // Each distinct request ran the engine once at most: its twin was a cache hit or shared it.
  EXPECT_LE((*server)->engine_runs(), kDistinct);
  EXPECT_GE((*server)->engine_runs(), 1);
}

}  // namespace
}  // namespace drillbif::server
