// StoreTaskRunner on a SQLite store, without a server: the trace's result equals the trace on its
// own thread whoever runs its tasks; alone, the trace stores only its budget's few tasks and runs
// the rest itself; with another worker taking stored tasks, the budget grows and that worker runs
// some; every stored child ends deleted or finished.
#include "server/trace_fan_out.h"

#include <gtest/gtest.h>

#include <atomic>
#include <cstdio>
#include <optional>
#include <string>
#include <thread>

#include "jobs/optimum_job.h"
#include "jobs/registry.h"
#include "jobs/request_bytes.h"
#include "jobs/trace_job.h"
#include "jobs/trace_task_codec.h"
#include "jobs/trace_task_job.h"
#include "support/claimed_parent.h"
#include "support/same_result.h"
#include "support/small_requests.h"
#include "support/sqlite_store.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

// The tasks of one child (FanOutOptions::batch).
constexpr size_t kBatch = FanOutOptions{}.batch;

class TraceFanOut : public ::testing::Test {
 protected:
  void SetUp() override {
    store_ = drillbif::testing::OpenSqliteStore(dir_);
    ASSERT_NE(store_, nullptr);
    request_ = drillbif::testing::SmallBoxTrace();
    std::optional<JobRecord> parent =
        drillbif::testing::SubmitAndClaim(*store_, "trace", request_, "parent");
    ASSERT_TRUE(parent.has_value());
    parent_ = *parent;
  }

  // Runs a claimed child as a worker does and completes it: with `keep`, with an empty result,
  // returning the result's bytes (the trace's own claims).
  std::optional<std::string> RunChild(const JobRecord& child, bool keep) {
    const jobs::JobKindSpec* kind = jobs::FindChildKind(child.kind);
    StatusOr<jobs::JobOutput> out = jobs::RunJob(*kind, child.request, {});
    if (!out.ok() || out->status != "COMPLETED") return std::nullopt;
    const std::string bytes = jobs::DeterministicBytes(*out->result);
    if (!store_->Complete(child.id, child.run, keep ? "" : bytes, 0).ok()) return std::nullopt;
    return bytes;
  }

  StatusOr<v1::TraceResult> FannedOut(StoreTaskRunner& runner) {
    return jobs::RunTrace(request_, {.trace_tasks = &runner});
  }

  // Runs `body` while another worker claims any child as soon as one is queued, runs it and
  // stores its result; *ran: the tasks it ran (each child a batch of them).
  template <typename Body>
  auto WithAnotherWorker(const Body& body, int* ran) {
    std::atomic<bool> done{false};
    std::atomic<int> count{0};
    std::thread other([&] {
      while (!done.load()) {
        StatusOr<std::optional<JobRecord>> claimed = store_->ClaimNext("other");
        std::optional<std::string> bytes;
        if (claimed.ok() && claimed->has_value()) bytes = RunChild(**claimed, /*keep=*/false);
        if (bytes.has_value()) {
          count += static_cast<int>(jobs::DecodeTraceTaskBatchResponse(*bytes).value().size());
        } else {
          std::this_thread::sleep_for(std::chrono::milliseconds(1));
        }
      }
    });
    auto result = body();
    done = true;
    other.join();
    *ran = count.load();
    return result;
  }

  // Every child of `parent` (default: the trace) is finished (those taken were deleted).
  void ExpectNoChildLeftToRun(const std::string& parent = "") {
    ListRequest list;
    list.parent = parent.empty() ? parent_.id : parent;
    list.page_size = 1000;
    StatusOr<ListResult> children = store_->List(list);
    ASSERT_TRUE(children.ok());
    for (const JobRecord& c : children->jobs) EXPECT_TRUE(IsFinished(c.state)) << c.id;
  }

  drillbif::testing::TempDir dir_{"drillbif_fan_out"};
  std::unique_ptr<JobStore> store_;
  v1::TraceRequest request_;
  JobRecord parent_;
};

TEST_F(TraceFanOut, AloneTheTraceStoresFewTasksAndRunsTheRestItself) {
  StatusOr<jobs::LocalTraceTasks> local =
      jobs::LocalTraceTasks::ForRequest(jobs::DeterministicBytes(request_));
  ASSERT_TRUE(local.ok());
  StoreTaskRunner runner(*store_, parent_, "parent", *local, FanOutOptions{},
                         [&](const JobRecord& child) { return RunChild(child, /*keep=*/true); },
                         {});
  StatusOr<v1::TraceResult> fanned = FannedOut(runner);
  ASSERT_TRUE(fanned.ok()) << fanned.status().ToString();
  StatusOr<v1::TraceResult> direct = jobs::RunTrace(request_);
  ASSERT_TRUE(direct.ok());
  drillbif::testing::ExpectSameResult(*fanned, *direct);
  // Nobody else takes a stored batch: each one the trace claims back lowers the budget to one
  // open batch, so a small share of the tasks is stored, all claimed back by the trace.
  EXPECT_GT(runner.tasks(), 10);
  EXPECT_GE(runner.stored(), 2);
  EXPECT_LT(runner.stored(), runner.tasks() / 2);
  // Only full batches are stored.
  EXPECT_EQ(runner.stored(), runner.batches_stored() * static_cast<int64_t>(kBatch));
  EXPECT_EQ(runner.run_elsewhere(), 0);
  EXPECT_GT(runner.claimed_here(), 0);
  EXPECT_LE(runner.claimed_here(), runner.stored());  // the others were dropped
  std::printf("alone: %lld tasks, %lld stored, %lld claimed back\n",
              static_cast<long long>(runner.tasks()), static_cast<long long>(runner.stored()),
              static_cast<long long>(runner.claimed_here()));
  ExpectNoChildLeftToRun();
}

TEST_F(TraceFanOut, AnotherWorkerTakesStoredTasksAndTheBudgetGrows) {
  StatusOr<jobs::LocalTraceTasks> local =
      jobs::LocalTraceTasks::ForRequest(jobs::DeterministicBytes(request_));
  ASSERT_TRUE(local.ok());
  StoreTaskRunner runner(*store_, parent_, "parent", *local, FanOutOptions{},
                         [&](const JobRecord& child) { return RunChild(child, /*keep=*/true); },
                         {});
  int ran = 0;
  StatusOr<v1::TraceResult> fanned = WithAnotherWorker([&] { return FannedOut(runner); }, &ran);
  ASSERT_TRUE(fanned.ok()) << fanned.status().ToString();
  StatusOr<v1::TraceResult> direct = jobs::RunTrace(request_);
  ASSERT_TRUE(direct.ok());
  drillbif::testing::ExpectSameResult(*fanned, *direct);
  EXPECT_GT(ran, 0);
  EXPECT_GT(runner.run_elsewhere(), 0);
  EXPECT_LE(runner.run_elsewhere(), ran);
  EXPECT_EQ(runner.stored(), runner.batches_stored() * static_cast<int64_t>(kBatch));
  // The budget grew past its start of 2 open batches.
  EXPECT_GT(runner.batches_stored(), 2 + runner.claimed_here() / static_cast<int64_t>(kBatch));
  std::printf("with another worker: %lld tasks, %lld stored, %lld run by it, %lld claimed back\n",
              static_cast<long long>(runner.tasks()), static_cast<long long>(runner.stored()),
              static_cast<long long>(runner.run_elsewhere()),
              static_cast<long long>(runner.claimed_here()));
  ExpectNoChildLeftToRun();
}

// An optimum job's trace fans out like a trace job's: the tasks are stored as children under the
// optimum, another worker runs some, and the optimum equals the one computed on its own thread.
TEST_F(TraceFanOut, AnOptimumsTraceFansOutWithTheSameOptimum) {
  v1::OptimumRequest request;
  *request.mutable_trace() = request_;
  request.add_margin(0.01);
  request.add_margin(0.02);
  request.add_grid(41);
  request.add_grid(41);
  const std::optional<JobRecord> claimed =
      drillbif::testing::SubmitAndClaim(*store_, "optimum", request, "optimum parent");
  ASSERT_TRUE(claimed.has_value());
  const JobRecord optimum = *claimed;
  StatusOr<jobs::LocalTraceTasks> local =
      jobs::LocalTraceTasks::ForJob(v1::OPTIMUM, optimum.request);
  ASSERT_TRUE(local.ok()) << local.status().ToString();
  // The children carry the optimum's trace request, not the optimum's own.
  EXPECT_EQ(local->trace_request(), jobs::DeterministicBytes(request_));
  StoreTaskRunner runner(*store_, optimum, "optimum parent", *local, FanOutOptions{},
                         [&](const JobRecord& child) { return RunChild(child, /*keep=*/true); },
                         {});
  int ran = 0;
  StatusOr<v1::OptimumResult> fanned =
      WithAnotherWorker([&] { return jobs::RunOptimum(request, {.trace_tasks = &runner}); }, &ran);
  ASSERT_TRUE(fanned.ok()) << fanned.status().ToString();
  StatusOr<v1::OptimumResult> direct = jobs::RunOptimum(request);
  ASSERT_TRUE(direct.ok());
  EXPECT_EQ(direct->status(), "COMPLETED");
  drillbif::testing::ExpectSameResult(*fanned, *direct);
  EXPECT_GT(runner.tasks(), 10);
  EXPECT_GT(runner.run_elsewhere(), 0);
  EXPECT_LE(runner.run_elsewhere(), ran);
  ExpectNoChildLeftToRun(optimum.id);
}

TEST(TraceTasksOfAJob, OnlyTracesAndOptimaHaveThem) {
  EXPECT_EQ(jobs::LocalTraceTasks::ForJob(v1::SWEEP, "").status().code(), StatusCode::kNotFound);
  const StatusOr<jobs::LocalTraceTasks> garbage =
      jobs::LocalTraceTasks::ForJob(v1::OPTIMUM, std::string("\xff\xff", 2));
  EXPECT_EQ(garbage.status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace drillbif::server
