// Fairness of the service: a short job never waits behind long ones (lanes and workers reserved
// for short jobs), and a client that fills its share of the queue does not refuse everybody else
// (tokens identify clients; per-client and total queue limits); lanes are reported.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <string>
#include <thread>

#include "support/operations.h"
#include "support/small_requests.h"
#include "support/temp_dir.h"
#include "support/test_server.h"

namespace drillbif::server {
namespace {

using drillbif::testing::LongSweep;
using drillbif::testing::MetadataOf;
using drillbif::testing::TestServer;
using google::longrunning::Operation;
using ::testing::HasSubstr;

// A long sweep that is not identical to the others (so it does not follow them).
v1::SubmitSweepRequest Long(int k) {
  v1::SubmitSweepRequest submit;
  *submit.mutable_request() = LongSweep();
  submit.mutable_request()->set_min(0.001 * k);
  return submit;
}

grpc::Status Submit(TestServer& server, const v1::SubmitSweepRequest& request, Operation* op,
                    const std::string& token = "") {
  auto context = TestServer::Context(token);
  return server.jobs().SubmitSweep(context.get(), request, op);
}

// The scenario: more long jobs than workers, all running or queued, then a simulation of
// 3 + 3 periods (a few milliseconds of engine time). It runs on the worker reserved for short
// jobs: done within 1 s of its submit (the bound asserted; the time measured is printed).
TEST(Fairness, AShortJobBehindMoreLongJobsThanWorkersFinishesWithinASecond) {
  ServerOptions options;
  options.workers = 2;
  options.short_workers = 1;
  TestServer server(options, "drillbif_fairness");
  ASSERT_TRUE(server.ok());
  for (int k = 0; k < 4; ++k) {
    Operation op;
    ASSERT_TRUE(Submit(server, Long(k), &op).ok());
    EXPECT_EQ(MetadataOf(op).lane(), "long");
  }
  v1::SubmitSimulateRequest quick;
  quick.mutable_request()->set_transient_periods(3);
  quick.mutable_request()->set_sample_periods(3);
  const auto start = std::chrono::steady_clock::now();
  Operation op;
  auto context = TestServer::Context();
  ASSERT_TRUE(server.jobs().SubmitSimulate(context.get(), quick, &op).ok());
  EXPECT_EQ(MetadataOf(op).lane(), "short");
  op = server.WaitDone(op.name(), "", 10);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(MetadataOf(op).state(), v1::SUCCEEDED);
  EXPECT_LT(seconds, 1.0);
  std::printf("3 + 3-period simulate behind 4 long jobs on 2 workers: done in %.1f ms\n",
              1e3 * seconds);
}

// Two clients by their tokens: alice fills her share of the queue and is refused, saying so;
// bob is still accepted.
TEST(Fairness, AClientThatFillsItsQueueShareDoesNotRefuseOthers) {
  drillbif::testing::TempDir secrets("drillbif_tokens");
  const std::string tokens = secrets.path() + "/tokens";
  std::ofstream(tokens) << "# clients\nalice alice-secret-1\nbob bob-secret-22\n";
  ServerOptions options;
  options.workers = 1;
  options.short_workers = 0;
  options.max_queued_per_client = 2;
  options.tokens_file = tokens;
  TestServer with_tokens(options, "drillbif_fairness_clients");
  ASSERT_TRUE(with_tokens.ok());
  Operation op;
  ASSERT_TRUE(Submit(with_tokens, Long(0), &op, "alice-secret-1").ok());  // runs
  // Claimed by the worker before the next submits (else it counts as waiting too).
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  while (MetadataOf(op).state() != v1::RUNNING && std::chrono::steady_clock::now() < give_up) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    google::longrunning::GetOperationRequest get;
    get.set_name(op.name());
    auto context = TestServer::Context("alice-secret-1");
    ASSERT_TRUE(with_tokens.operations().GetOperation(context.get(), get, &op).ok());
  }
  ASSERT_EQ(MetadataOf(op).state(), v1::RUNNING);
  ASSERT_TRUE(Submit(with_tokens, Long(1), &op, "alice-secret-1").ok());  // waits
  ASSERT_TRUE(Submit(with_tokens, Long(2), &op, "alice-secret-1").ok());  // waits
  const grpc::Status refused = Submit(with_tokens, Long(3), &op, "alice-secret-1");
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_THAT(refused.error_message(), HasSubstr("client 'alice' has 2 jobs waiting (limit 2)"));
  EXPECT_TRUE(Submit(with_tokens, Long(4), &op, "bob-secret-22").ok());
  // A token of nobody is refused.
  EXPECT_EQ(Submit(with_tokens, Long(5), &op, "mallory-secret").error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
}

}  // namespace
}  // namespace drillbif::server
