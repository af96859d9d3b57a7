// The gRPC service end to end: a real server (Server::Start) on 127.0.0.1 with port 0 over a real
// SQLite file in a temp dir, called through the generated stubs with deadlines. Each job kind
// gives the job runner's own result; identical requests are cache hits that never reach the
// engine; a cancel reaches the engine in time; bad input, tokens and sizes give their codes and
// the server keeps serving; health and reflection answer.
#include <gmock/gmock.h>
#include <google/protobuf/descriptor.h>
#include <google/protobuf/dynamic_message.h>
#include <google/protobuf/util/message_differencer.h>
#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <stdlib.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <future>
#include <limits>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "jobs/continue_job.h"
#include "jobs/optimum_job.h"
#include "jobs/simulate_job.h"
#include "jobs/sweep_job.h"
#include "jobs/trace_job.h"
#include "server/server.h"
#include "support/generic_call.h"
#include "support/operations.h"
#include "support/same_result.h"
#include "support/small_requests.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

using drillbif::testing::MetadataOf;
using drillbif::testing::ResponseOf;
using google::longrunning::Operation;
using google::protobuf::util::MessageDifferencer;
using ::testing::HasSubstr;

constexpr char kToken[] = "test-token";
// Requests larger than this are refused by the test server (ServerOptions::max_request_bytes).
constexpr int kMaxRequestBytes = 64 * 1024;

using drillbif::testing::LongSweep;
using drillbif::testing::SmallBoxTrace;
using drillbif::testing::SmallSweep;
using drillbif::testing::TempDir;

// One server for the whole suite (starting one per test would cost a store and a port each);
// tests use requests of their own so that the shared cache does not couple them, except where
// the cache is what they test.
class GrpcServiceTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new TempDir("drillbif_grpc");
    ServerOptions options;
    options.grpc_port = 0;
    options.http_port = 0;  // Tests run in parallel: no fixed port.
    options.db_path = dir_->path() + "/jobs.db";
    options.workers = 2;
    options.token = kToken;
    options.max_request_bytes = kMaxRequestBytes;
    // Faster progress than the default so that Watch sees several updates of a short job.
    options.progress_interval_ms = 50;
    StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(server).value().release();
    channel_ = new std::shared_ptr<grpc::Channel>(
        grpc::CreateChannel(server_->grpc_address(), grpc::InsecureChannelCredentials()));
  }
  static void TearDownTestSuite() {
    delete channel_;
    delete server_;
    delete dir_;
  }

  void SetUp() override {
    ASSERT_NE(server_, nullptr);
    jobs_ = v1::Jobs::NewStub(*channel_);
    operations_ = google::longrunning::Operations::NewStub(*channel_);
  }

  // A context with the token and a deadline: every call of the tests has one.
  static std::unique_ptr<grpc::ClientContext> Context(double seconds = 30,
                                                      const char* token = kToken) {
    auto context = std::make_unique<grpc::ClientContext>();
    context->set_deadline(std::chrono::system_clock::now() +
                          std::chrono::milliseconds(static_cast<int>(seconds * 1000)));
    if (token != nullptr) context->AddMetadata("authorization", std::string("Bearer ") + token);
    return context;
  }

  // Waits until the operation is done (WaitOperation, repeated while it times out).
  Operation WaitDone(const std::string& name, double seconds = 60) {
    const auto end = std::chrono::steady_clock::now() +
                     std::chrono::milliseconds(static_cast<int>(seconds * 1000));
    Operation op;
    while (std::chrono::steady_clock::now() < end) {
      google::longrunning::WaitOperationRequest request;
      request.set_name(name);
      request.mutable_timeout()->set_seconds(10);
      auto context = Context(15);
      grpc::Status s = operations_->WaitOperation(context.get(), request, &op);
      EXPECT_TRUE(s.ok()) << s.error_message();
      if (!s.ok() || op.done()) return op;
    }
    ADD_FAILURE() << name << " not done after " << seconds << " s";
    return op;
  }

  // Job runs of the engine so far (the server's counter).
  static int64_t EngineRuns() { return server_->engine_runs(); }

  // Submits the optimum job, waits for it, and expects it to have reused the curves and the
  // region an earlier job left (the worker pool's jobs::OptimumCache), with the answer of the
  // job runner from scratch.
  void ExpectOptimumReusesCurvesAndRegion(const v1::SubmitOptimumRequest& submit) {
    Operation op;
    auto context = Context();
    ASSERT_TRUE(jobs_->SubmitOptimum(context.get(), submit, &op).ok());
    op = WaitDone(op.name());
    EXPECT_FALSE(MetadataOf(op).cache_hit());  // a job of its own, not a stored answer
    const auto served = ResponseOf<v1::OptimumResult>(op);
    EXPECT_TRUE(served.curves_reused());
    EXPECT_TRUE(served.region_reused());
    StatusOr<v1::OptimumResult> direct = jobs::RunOptimum(submit.request());
    ASSERT_TRUE(direct.ok());
    EXPECT_FALSE(direct->curves_reused());
    drillbif::testing::ExpectSameResult(served, *direct);
  }

  static TempDir* dir_;
  static Server* server_;
  static std::shared_ptr<grpc::Channel>* channel_;
  std::unique_ptr<v1::Jobs::Stub> jobs_;
  std::unique_ptr<google::longrunning::Operations::Stub> operations_;
};

TempDir* GrpcServiceTest::dir_ = nullptr;
Server* GrpcServiceTest::server_ = nullptr;
std::shared_ptr<grpc::Channel>* GrpcServiceTest::channel_ = nullptr;

using drillbif::testing::ExpectSameResult;

TEST_F(GrpcServiceTest, SimulateGivesTheRunnersResult) {
  v1::SubmitSimulateRequest request;
  request.mutable_request()->set_sample_periods(20);
  Operation op;
  auto context = Context();
  ASSERT_TRUE(jobs_->SubmitSimulate(context.get(), request, &op).ok());
  EXPECT_THAT(op.name(), ::testing::StartsWith("operations/"));
  op = WaitDone(op.name());
  EXPECT_EQ(MetadataOf(op).state(), v1::SUCCEEDED);
  StatusOr<v1::SimulateResult> direct = jobs::RunSimulate(request.request());
  ASSERT_TRUE(direct.ok());
  ExpectSameResult(ResponseOf<v1::SimulateResult>(op), *direct);
  EXPECT_EQ(MetadataOf(op).points(), 20);
}

TEST_F(GrpcServiceTest, SweepGivesTheRunnersResultWholeAndInPages) {
  v1::SubmitSweepRequest request;
  *request.mutable_request() = SmallSweep(0.1, 20);
  request.mutable_request()->set_direction(v1::SweepRequest::BOTH);
  Operation op;
  auto context = Context();
  ASSERT_TRUE(jobs_->SubmitSweep(context.get(), request, &op).ok());
  op = WaitDone(op.name());
  StatusOr<v1::SweepResult> direct = jobs::RunSweep(request.request());
  ASSERT_TRUE(direct.ok());
  ExpectSameResult(ResponseOf<v1::SweepResult>(op), *direct);
  // The current value: a grid value of the sweep (the last one finished as of the last record).
  const v1::JobMetadata metadata = MetadataOf(op);
  ASSERT_TRUE(metadata.has_current_value());
  bool on_grid = false;
  for (const auto& p : direct->up()) on_grid |= p.value() == metadata.current_value();
  for (const auto& p : direct->down()) on_grid |= p.value() == metadata.current_value();
  EXPECT_TRUE(on_grid) << metadata.current_value();

  // Pages of 7 points over up (20) ++ down (20): 6 pages, concatenated equal to the whole.
  v1::SweepResult joined;
  std::string token;
  int pages = 0;
  do {
    v1::GetResultRequest page_request;
    page_request.set_name(op.name());
    page_request.set_page_size(7);
    page_request.set_page_token(token);
    v1::GetResultResponse page;
    auto page_context = Context();
    grpc::Status s = jobs_->GetResult(page_context.get(), page_request, &page);
    ASSERT_TRUE(s.ok()) << s.error_message();
    EXPECT_EQ(page.total_points(), 40);
    EXPECT_LE(page.sweep().up_size() + page.sweep().down_size(), 7);
    for (const auto& p : page.sweep().up()) *joined.add_up() = p;
    for (const auto& p : page.sweep().down()) *joined.add_down() = p;
    token = page.next_page_token();
    ++pages;
  } while (!token.empty() && pages < 100);
  EXPECT_EQ(pages, 6);
  ASSERT_EQ(joined.up_size(), direct->up_size());
  ASSERT_EQ(joined.down_size(), direct->down_size());
  for (int i = 0; i < joined.up_size(); ++i) {
    EXPECT_TRUE(MessageDifferencer::Equals(joined.up(i), direct->up(i)));
  }
  for (int i = 0; i < joined.down_size(); ++i) {
    EXPECT_TRUE(MessageDifferencer::Equals(joined.down(i), direct->down(i)));
  }

  v1::GetResultRequest bad;
  bad.set_name(op.name());
  bad.set_page_size(5);
  bad.set_page_token("garbage");
  v1::GetResultResponse ignored;
  auto bad_context = Context();
  EXPECT_EQ(jobs_->GetResult(bad_context.get(), bad, &ignored).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(GrpcServiceTest, ContinueGivesTheRunnersResult) {
  v1::SubmitContinueRequest request;
  request.mutable_request()->set_param("b");
  request.mutable_request()->set_min(0.14);
  request.mutable_request()->set_max(0.16);
  Operation op;
  auto context = Context();
  ASSERT_TRUE(jobs_->SubmitContinue(context.get(), request, &op).ok());
  op = WaitDone(op.name());
  StatusOr<v1::ContinueResult> direct = jobs::RunContinue(request.request());
  ASSERT_TRUE(direct.ok());
  const auto served = ResponseOf<v1::ContinueResult>(op);
  ExpectSameResult(served, *direct);
  EXPECT_EQ(MetadataOf(op).points(), direct->points_size());
  EXPECT_GT(direct->points_size(), 2);
}

// A continue job's metadata carries the continued parameter's value of an accepted point (the
// last one recorded: with each progress record while it runs, and once more at its end), inside
// the range asked.
TEST_F(GrpcServiceTest, ContinueReportsItsCurrentValue) {
  v1::SubmitContinueRequest request;
  request.mutable_request()->set_param("b");
  request.mutable_request()->set_min(0.0);
  request.mutable_request()->set_max(0.2);
  Operation op;
  auto context = Context();
  ASSERT_TRUE(jobs_->SubmitContinue(context.get(), request, &op).ok());
  op = WaitDone(op.name());
  const v1::JobMetadata metadata = MetadataOf(op);
  ASSERT_EQ(metadata.state(), v1::SUCCEEDED);
  ASSERT_TRUE(metadata.has_current_value());
  EXPECT_GE(metadata.current_value(), 0.0);
  EXPECT_LE(metadata.current_value(), 0.2);
  const auto served = ResponseOf<v1::ContinueResult>(op);
  bool on_branch = false;
  for (const auto& p : served.points()) on_branch |= p.value() == metadata.current_value();
  EXPECT_TRUE(on_branch) << metadata.current_value();
}

TEST_F(GrpcServiceTest, TraceGivesTheRunnersResult) {
  v1::SubmitTraceRequest request;
  *request.mutable_request() = SmallBoxTrace();
  Operation op;
  auto context = Context();
  ASSERT_TRUE(jobs_->SubmitTrace(context.get(), request, &op).ok());
  op = WaitDone(op.name());
  StatusOr<v1::TraceResult> direct = jobs::RunTrace(request.request());
  ASSERT_TRUE(direct.ok());
  ExpectSameResult(ResponseOf<v1::TraceResult>(op), *direct);
  EXPECT_GT(direct->curves_size(), 0);
}

// The optimum: computed on demand by QueryOptimum, then answered from the stored result (no
// engine run), and a submit of the same request is a cache hit.
TEST_F(GrpcServiceTest, OptimumComputedOnDemandThenStored) {
  v1::QueryOptimumRequest query;
  *query.mutable_request()->mutable_trace() = SmallBoxTrace();
  query.mutable_request()->add_grid(21);
  query.mutable_request()->add_grid(21);

  v1::QueryOptimumResponse response;
  auto context = Context();
  grpc::Status s = jobs_->QueryOptimum(context.get(), query, &response);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::NOT_FOUND) << "nothing stored yet";

  query.set_compute(true);
  auto compute_context = Context(60);
  s = jobs_->QueryOptimum(compute_context.get(), query, &response);
  ASSERT_TRUE(s.ok()) << s.error_message();
  EXPECT_FALSE(response.stored());
  ASSERT_TRUE(response.has_optimum());
  StatusOr<v1::OptimumResult> direct = jobs::RunOptimum(query.request());
  ASSERT_TRUE(direct.ok());
  ExpectSameResult(response.optimum(), *direct);
  EXPECT_EQ(direct->status(), "COMPLETED");

  const int64_t runs = EngineRuns();
  query.set_compute(false);
  v1::QueryOptimumResponse stored;
  auto stored_context = Context();
  ASSERT_TRUE(jobs_->QueryOptimum(stored_context.get(), query, &stored).ok());
  EXPECT_TRUE(stored.stored());
  ExpectSameResult(stored.optimum(), *direct);
  EXPECT_EQ(stored.operation(), response.operation());

  v1::SubmitOptimumRequest submit;
  *submit.mutable_request() = query.request();
  Operation op;
  auto submit_context = Context();
  ASSERT_TRUE(jobs_->SubmitOptimum(submit_context.get(), submit, &op).ok());
  EXPECT_TRUE(op.done());
  EXPECT_TRUE(MetadataOf(op).cache_hit());
  ExpectSameResult(ResponseOf<v1::OptimumResult>(op), *direct);
  EXPECT_EQ(EngineRuns(), runs) << "stored answers must not run the engine";
}

// An optimum job with another margin over the curves and grid of an earlier one: a new job (its
// answer differs), run without tracing or filling the region again (the worker pool's
// jobs::OptimumCache), and its answer is the runner's from scratch.
TEST_F(GrpcServiceTest, AnotherMarginReusesTheCurvesAndRegionOfAnEarlierOptimum) {
  v1::SubmitOptimumRequest submit;
  *submit.mutable_request()->mutable_trace() = SmallBoxTrace();
  submit.mutable_request()->add_grid(23);
  submit.mutable_request()->add_grid(23);
  submit.mutable_request()->add_margin(0.005);
  Operation first;
  auto context = Context();
  ASSERT_TRUE(jobs_->SubmitOptimum(context.get(), submit, &first).ok());
  first = WaitDone(first.name());
  ASSERT_EQ(MetadataOf(first).state(), v1::SUCCEEDED);

  submit.mutable_request()->set_margin(0, 0.01);
  ExpectOptimumReusesCurvesAndRegion(submit);
}

// A trace job (the map, with its region) leaves its curves and region for an optimum job over the
// same box and grid. (A box of its own: other tests' optimum jobs fill the same cache.)
TEST_F(GrpcServiceTest, AnOptimumAfterATraceOfItsBoxReusesTheTrace) {
  v1::TraceRequest box = SmallBoxTrace();
  box.set_max(1, 0.58);
  v1::SubmitTraceRequest trace;
  *trace.mutable_request() = box;
  trace.mutable_request()->mutable_region()->add_grid(23);
  trace.mutable_request()->mutable_region()->add_grid(23);
  Operation traced;
  auto context = Context();
  ASSERT_TRUE(jobs_->SubmitTrace(context.get(), trace, &traced).ok());
  traced = WaitDone(traced.name());
  ASSERT_EQ(MetadataOf(traced).state(), v1::SUCCEEDED);

  v1::SubmitOptimumRequest submit;
  *submit.mutable_request()->mutable_trace() = box;
  submit.mutable_request()->add_grid(23);
  submit.mutable_request()->add_grid(23);
  submit.mutable_request()->add_margin(0.005);
  ExpectOptimumReusesCurvesAndRegion(submit);
}

TEST_F(GrpcServiceTest, IdenticalRequestIsACacheHitWithoutEngineRun) {
  v1::SubmitSimulateRequest request;
  request.mutable_request()->set_sample_periods(7);
  request.mutable_request()->mutable_params()->set_b(0.151);
  Operation first;
  auto context = Context();
  ASSERT_TRUE(jobs_->SubmitSimulate(context.get(), request, &first).ok());
  first = WaitDone(first.name());
  EXPECT_FALSE(MetadataOf(first).cache_hit());

  const int64_t runs = EngineRuns();
  StatusOr<StoreStats> before = server_->store().Stats();
  ASSERT_TRUE(before.ok());
  // Another request_id: a new job, but the same content (request_id is not in the key).
  request.set_request_id("second");
  Operation second;
  auto second_context = Context();
  ASSERT_TRUE(jobs_->SubmitSimulate(second_context.get(), request, &second).ok());
  EXPECT_NE(second.name(), first.name());
  EXPECT_TRUE(second.done()) << "a cache hit is done at submit";
  EXPECT_TRUE(MetadataOf(second).cache_hit());
  EXPECT_EQ(MetadataOf(second).state(), v1::SUCCEEDED);
  EXPECT_TRUE(MessageDifferencer::Equals(ResponseOf<v1::SimulateResult>(second),
                                         ResponseOf<v1::SimulateResult>(first)));
  EXPECT_EQ(EngineRuns(), runs);
  StatusOr<StoreStats> after = server_->store().Stats();
  ASSERT_TRUE(after.ok());
  EXPECT_EQ(after->cache_hits_total, before->cache_hits_total + 1);

  // The same request_id again: the same operation (idempotent retry).
  Operation again;
  auto again_context = Context();
  ASSERT_TRUE(jobs_->SubmitSimulate(again_context.get(), request, &again).ok());
  EXPECT_EQ(again.name(), second.name());
}

// A running sweep of 1e5 values (minutes of work) is cancelled; the time from the return of
// CancelOperation until the store says CANCELLED is measured.
//
// Where the time goes: CancelOperation sets the store flag and the job's in-memory flag before
// it returns; the sweep's calling thread calls the progress callback every 50 ms (sweep.cc), which
// then returns false; the sweep's worker checks its cancel flag every 1/200 of a value's 600
// forcing periods (microseconds); MarkCancelled is one committed transaction (an fsync, ~1 ms
// here, tens of ms on a slow disk). So the engine-side bound is 50 ms plus a few ms: the
// 100 ms target. That goal is measured by bench/service_bench.cc (BM_CancelRunningSweep, on a
// quiet machine), not asserted here: on a loaded machine (ctest -j2 beside other work) this
// test measured 135 ms and more. Here the job must reach CANCELLED within the 5 s it is polled
// for (it would run for minutes); the value measured is printed.
TEST_F(GrpcServiceTest, CancelOfARunningSweepReachesCancelled) {
  v1::SubmitSweepRequest request;
  *request.mutable_request() = LongSweep();
  Operation op;
  auto context = Context();
  ASSERT_TRUE(jobs_->SubmitSweep(context.get(), request, &op).ok());
  const std::string id = op.name().substr(std::string("operations/").size());
  // Wait until it runs (claimed, and the engine has started).
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  while (std::chrono::steady_clock::now() < give_up) {
    StatusOr<JobRecord> record = server_->store().Get(id);
    ASSERT_TRUE(record.ok());
    if (record->state == JobState::kRunning) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(100));  // Well inside the engine.

  google::longrunning::CancelOperationRequest cancel;
  cancel.set_name(op.name());
  google::protobuf::Empty empty;
  auto cancel_context = Context();
  ASSERT_TRUE(operations_->CancelOperation(cancel_context.get(), cancel, &empty).ok());
  const auto cancelled_at = std::chrono::steady_clock::now();
  JobState state = JobState::kRunning;
  while (std::chrono::steady_clock::now() - cancelled_at < std::chrono::seconds(5)) {
    StatusOr<JobRecord> record = server_->store().Get(id);
    ASSERT_TRUE(record.ok());
    state = record->state;
    if (state != JobState::kRunning) break;
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  const double ms =
      std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - cancelled_at)
          .count();
  std::printf("cancel of a running sweep: CANCELLED after %.1f ms\n", ms);
  EXPECT_EQ(state, JobState::kCancelled);

  const Operation done = WaitDone(op.name());
  EXPECT_EQ(MetadataOf(done).state(), v1::CANCELLED);
  EXPECT_EQ(done.error().code(), static_cast<int>(grpc::StatusCode::CANCELLED));
}

TEST_F(GrpcServiceTest, WatchStreamsProgressUntilTheFinalState) {
  v1::SubmitSweepRequest request;
  *request.mutable_request() = SmallSweep(0.05, 100);
  Operation op;
  auto context = Context();
  ASSERT_TRUE(jobs_->SubmitSweep(context.get(), request, &op).ok());
  v1::WatchRequest watch;
  watch.set_name(op.name());
  auto watch_context = Context(60);
  auto reader = jobs_->Watch(watch_context.get(), watch);
  v1::JobMetadata metadata;
  std::vector<v1::JobMetadata> seen;
  while (reader->Read(&metadata)) seen.push_back(metadata);
  grpc::Status s = reader->Finish();
  ASSERT_TRUE(s.ok()) << s.error_message();
  ASSERT_FALSE(seen.empty());
  EXPECT_EQ(seen.back().state(), v1::SUCCEEDED);
  EXPECT_EQ(seen.back().points(), 100);
  EXPECT_DOUBLE_EQ(seen.back().progress(), 1.0);
  for (size_t i = 1; i < seen.size(); ++i) {
    EXPECT_GE(seen[i].progress(), seen[i - 1].progress());
  }
  std::printf("watch: %zu updates\n", seen.size());

  v1::WatchRequest unknown;
  unknown.set_name("operations/0123456789abcdef0123456789abcdef");
  auto unknown_context = Context();
  auto unknown_reader = jobs_->Watch(unknown_context.get(), unknown);
  while (unknown_reader->Read(&metadata)) {
  }
  EXPECT_EQ(unknown_reader->Finish().error_code(), grpc::StatusCode::NOT_FOUND);
}

TEST_F(GrpcServiceTest, ListDeleteAndErrorsOfOperations) {
  v1::SubmitSimulateRequest request;
  request.mutable_request()->set_sample_periods(3);
  request.mutable_request()->mutable_params()->set_a(0.31);
  Operation op;
  auto context = Context();
  ASSERT_TRUE(jobs_->SubmitSimulate(context.get(), request, &op).ok());
  WaitDone(op.name());

  // Walk every page of the SUCCEEDED simulate jobs, 2 at a time: ours is among them.
  std::set<std::string> names;
  google::longrunning::ListOperationsRequest list;
  list.set_filter("state=SUCCEEDED AND kind=simulate");
  list.set_page_size(2);
  do {
    google::longrunning::ListOperationsResponse page;
    auto list_context = Context();
    ASSERT_TRUE(operations_->ListOperations(list_context.get(), list, &page).ok());
    EXPECT_LE(page.operations_size(), 2);
    for (const Operation& o : page.operations()) {
      EXPECT_TRUE(names.insert(o.name()).second) << "listed twice: " << o.name();
      EXPECT_EQ(MetadataOf(o).state(), v1::SUCCEEDED);
    }
    list.set_page_token(page.next_page_token());
  } while (!list.page_token().empty());
  EXPECT_TRUE(names.count(op.name()));

  list.set_filter("colour=blue");
  google::longrunning::ListOperationsResponse ignored;
  auto bad_filter = Context();
  EXPECT_EQ(operations_->ListOperations(bad_filter.get(), list, &ignored).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);

  google::longrunning::DeleteOperationRequest del;
  del.set_name(op.name());
  google::protobuf::Empty empty;
  auto delete_context = Context();
  ASSERT_TRUE(operations_->DeleteOperation(delete_context.get(), del, &empty).ok());
  google::longrunning::GetOperationRequest get;
  get.set_name(op.name());
  Operation gone;
  auto get_context = Context();
  EXPECT_EQ(operations_->GetOperation(get_context.get(), get, &gone).error_code(),
            grpc::StatusCode::NOT_FOUND);
  get.set_name("jobs/42");
  auto bad_name = Context();
  EXPECT_EQ(operations_->GetOperation(bad_name.get(), get, &gone).error_code(),
            grpc::StatusCode::INVALID_ARGUMENT);
}

TEST_F(GrpcServiceTest, BadInputGivesClearCodesAndTheServerKeepsServing) {
  Operation op;
  {
    v1::SubmitSimulateRequest request;
    request.mutable_request()->mutable_params()->set_xi(std::numeric_limits<double>::quiet_NaN());
    auto context = Context();
    grpc::Status s = jobs_->SubmitSimulate(context.get(), request, &op);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_THAT(s.error_message(), HasSubstr("request.params.xi"));
  }
  {
    v1::SubmitContinueRequest request;
    request.mutable_request()->set_param("b");
    request.mutable_request()->set_min(0.1);
    request.mutable_request()->set_max(0.2);
    request.mutable_request()->mutable_params()->set_xi(0.0);
    auto context = Context();
    grpc::Status s = jobs_->SubmitContinue(context.get(), request, &op);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_THAT(s.error_message(), HasSubstr("xi"));
  }
  {
    // Every check of the request is made at submit (here an unknown parameter name): nothing is
    // queued for a request that cannot run.
    v1::SubmitSweepRequest request;
    request.mutable_request()->set_param("zeta");
    request.mutable_request()->set_min(0);
    request.mutable_request()->set_max(1);
    auto context = Context();
    const grpc::Status s = jobs_->SubmitSweep(context.get(), request, &op);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
    EXPECT_THAT(s.error_message(), HasSubstr("param: unknown parameter 'zeta'"));
  }
  {
    // Larger than max_request_bytes: refused by gRPC before it is parsed.
    v1::SubmitSimulateRequest request;
    request.set_request_id(std::string(kMaxRequestBytes + 1000, 'x'));
    auto context = Context();
    EXPECT_EQ(jobs_->SubmitSimulate(context.get(), request, &op).error_code(),
              grpc::StatusCode::RESOURCE_EXHAUSTED);
  }
  {
    v1::SubmitSimulateRequest request;
    request.set_request_id(std::string(200, 'x'));
    auto context = Context();
    EXPECT_EQ(jobs_->SubmitSimulate(context.get(), request, &op).error_code(),
              grpc::StatusCode::INVALID_ARGUMENT);
  }
  // Still serving.
  v1::SubmitSimulateRequest request;
  request.mutable_request()->set_sample_periods(2);
  auto context = Context();
  EXPECT_TRUE(jobs_->SubmitSimulate(context.get(), request, &op).ok());
}

// Admission control: a request whose estimated cost is over its kind's limit is refused at submit
// with RESOURCE_EXHAUSTED naming the fields, their value and the limit; nothing is queued.
TEST_F(GrpcServiceTest, RequestsOverTheirKindsLimitsAreRefusedAtSubmit) {
  const StatusOr<StoreStats> before = server_->store().Stats();
  ASSERT_TRUE(before.ok());
  v1::SubmitSimulateRequest request;
  request.mutable_request()->set_transient_periods(2147483647);
  Operation op;
  auto context = Context();
  const grpc::Status s = jobs_->SubmitSimulate(context.get(), request, &op);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED);
  EXPECT_THAT(s.error_message(), HasSubstr("request.transient_periods + request.sample_periods = "
                                           "2147483747 forcing periods"));
  EXPECT_THAT(s.error_message(), HasSubstr("max_seconds of simulate jobs"));
  const StatusOr<StoreStats> after = server_->store().Stats();
  ASSERT_TRUE(after.ok());
  EXPECT_EQ(after->jobs_by_state, before->jobs_by_state);  // nothing was stored
}

TEST_F(GrpcServiceTest, MissingOrWrongTokenIsUnauthenticated) {
  v1::SubmitSimulateRequest request;
  Operation op;
  auto none = Context(10, nullptr);
  EXPECT_EQ(jobs_->SubmitSimulate(none.get(), request, &op).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  auto wrong = Context(10, "test-tokex");
  EXPECT_EQ(jobs_->SubmitSimulate(wrong.get(), request, &op).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  google::longrunning::ListOperationsRequest list;
  google::longrunning::ListOperationsResponse page;
  auto list_none = Context(10, nullptr);
  EXPECT_EQ(operations_->ListOperations(list_none.get(), list, &page).error_code(),
            grpc::StatusCode::UNAUTHENTICATED);
  v1::WatchRequest watch;
  watch.set_name("operations/0123456789abcdef0123456789abcdef");
  auto watch_none = Context(10, nullptr);
  auto reader = jobs_->Watch(watch_none.get(), watch);
  v1::JobMetadata metadata;
  while (reader->Read(&metadata)) {
  }
  EXPECT_EQ(reader->Finish().error_code(), grpc::StatusCode::UNAUTHENTICATED);
  auto right = Context();
  EXPECT_TRUE(operations_->ListOperations(right.get(), list, &page).ok());
}

// Request bytes that do not parse are INVALID_ARGUMENT with a message naming the field (gRPC's own
// handlers would answer UNIMPLEMENTED with an empty message): invalid UTF-8 in a proto3 string, a
// truncated message, garbage; for every kind of method (submit, operations, the Watch stream).
TEST_F(GrpcServiceTest, UnparsableRequestBytesAreInvalidArgumentNamingTheField) {
  const auto call = [](const std::string& method, const std::string& bytes) {
    std::string response;
    grpc::Status s = drillbif::testing::GenericUnary(*channel_, method, bytes, &response,
                                                     std::string("Bearer ") + kToken);
    EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << method;
    return s.error_message();
  };
  // SubmitSweepRequest{request (1): SweepRequest{param (2): "\xff\xfe"}}.
  const std::string sweep("\x0a\x04\x12\x02\xff\xfe", 6);
  EXPECT_EQ(call("/drillbif.v1.Jobs/SubmitSweep", sweep),
            "not a valid drillbif.v1.SubmitSweepRequest: request.param: not valid UTF-8");
  // request_id (2) with invalid UTF-8.
  EXPECT_THAT(call("/drillbif.v1.Jobs/SubmitSimulate", std::string("\x12\x01\xc3", 3)),
              HasSubstr("request_id: not valid UTF-8"));
  // A length beyond the message, garbage.
  EXPECT_THAT(call("/drillbif.v1.Jobs/SubmitTrace", std::string("\x0a\x7f\x01", 3)),
              HasSubstr("a length beyond the message"));
  EXPECT_THAT(call("/drillbif.v1.Jobs/GetResult", std::string("\xff\xff\xff", 3)),
              HasSubstr("not a valid drillbif.v1.GetResultRequest: malformed protobuf bytes"));
  EXPECT_THAT(call("/google.longrunning.Operations/GetOperation", std::string("\x0a\x01\x80", 3)),
              HasSubstr("name: not valid UTF-8"));
  // The Watch stream, with a name of invalid UTF-8.
  std::string watch_response;
  const grpc::Status watch = drillbif::testing::GenericServerStreamFirst(
      *channel_, "/drillbif.v1.Jobs/Watch", std::string("\x0a\x01\xfe", 3), &watch_response,
      std::string("Bearer ") + kToken);
  EXPECT_EQ(watch.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(watch.error_message(), HasSubstr("name: not valid UTF-8"));
}

TEST_F(GrpcServiceTest, HealthReportsServing) {
  EXPECT_EQ(drillbif::testing::HealthStatus(*channel_), 1);  // SERVING
}

// Reflection lists the services. Its messages are built from the descriptors that the
// reflection library registers in the generated pool (no reflection proto compiled here).
TEST_F(GrpcServiceTest, ReflectionListsTheServices) {
  const auto* pool = google::protobuf::DescriptorPool::generated_pool();
  const auto* request_type =
      pool->FindMessageTypeByName("grpc.reflection.v1alpha.ServerReflectionRequest");
  const auto* response_type =
      pool->FindMessageTypeByName("grpc.reflection.v1alpha.ServerReflectionResponse");
  ASSERT_NE(request_type, nullptr);
  ASSERT_NE(response_type, nullptr);
  google::protobuf::DynamicMessageFactory factory;
  std::unique_ptr<google::protobuf::Message> request(factory.GetPrototype(request_type)->New());
  request->GetReflection()->SetString(request.get(), request_type->FindFieldByName("list_services"),
                                      "");
  std::string request_bytes = request->SerializeAsString();

  // A bidi stream of one request and one response, driven through a completion queue.
  grpc::GenericStub stub(*channel_);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  grpc::CompletionQueue cq;
  auto call = stub.PrepareCall(
      &context, "/grpc.reflection.v1alpha.ServerReflection/ServerReflectionInfo", &cq);
  void* tag = nullptr;
  bool ok = false;
  auto step = [&](int expected) {
    ASSERT_TRUE(cq.Next(&tag, &ok));
    ASSERT_EQ(tag, reinterpret_cast<void*>(static_cast<intptr_t>(expected)));
  };
  call->StartCall(reinterpret_cast<void*>(1));
  step(1);
  grpc::Slice slice(request_bytes);
  grpc::ByteBuffer in(&slice, 1);
  call->Write(in, reinterpret_cast<void*>(2));
  step(2);
  call->WritesDone(reinterpret_cast<void*>(3));
  step(3);
  grpc::ByteBuffer out;
  call->Read(&out, reinterpret_cast<void*>(4));
  step(4);
  ASSERT_TRUE(ok);
  grpc::Status status;
  call->Finish(&status, reinterpret_cast<void*>(5));
  step(5);
  ASSERT_TRUE(status.ok()) << status.error_message();

  std::vector<grpc::Slice> slices;
  ASSERT_TRUE(out.Dump(&slices).ok());
  std::string response_bytes;
  for (const grpc::Slice& s : slices) response_bytes.append(s.begin(), s.end());
  std::unique_ptr<google::protobuf::Message> response(factory.GetPrototype(response_type)->New());
  ASSERT_TRUE(response->ParseFromString(response_bytes));
  // ServerReflectionResponse.list_services_response.service[].name
  const auto* list_field = response_type->FindFieldByName("list_services_response");
  const google::protobuf::Message& list =
      response->GetReflection()->GetMessage(*response, list_field);
  const auto* service_field = list.GetDescriptor()->FindFieldByName("service");
  std::set<std::string> services;
  for (int i = 0; i < list.GetReflection()->FieldSize(list, service_field); ++i) {
    const auto& service = list.GetReflection()->GetRepeatedMessage(list, service_field, i);
    services.insert(service.GetReflection()->GetString(
        service, service.GetDescriptor()->FindFieldByName("name")));
  }
  EXPECT_TRUE(services.count("drillbif.v1.Jobs"));
  EXPECT_TRUE(services.count("google.longrunning.Operations"));
  EXPECT_TRUE(services.count("grpc.health.v1.Health"));
}

}  // namespace
}  // namespace drillbif::server
