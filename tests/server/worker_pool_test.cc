// The worker pool: its run callback (the job-duration metrics) hears how a run ended before the
// store makes the outcome visible (a client that sees a job done and then reads /metrics finds the
// run counted there); runs stopped at their kind's time limit (DEADLINE_EXCEEDED) and at their
// result-size limit (RESOURCE_EXHAUSTED), enforced while they run, whatever admission estimated;
// workers reserved for short jobs take nothing else; results stored in pages.
#include "server/worker_pool.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <thread>

#include "drillbif/v1/simulate.pb.h"
#include "drillbif/v1/sweep.pb.h"
#include "jobs/request_bytes.h"
#include "server/store/sqlite_job_store.h"
#include "server/watch_hub.h"
#include "support/small_requests.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

TEST(WorkerPool, RunCallbackSeesTheJobBeforeItsOutcomeIsRecorded) {
  testing::TempDir dir("drillbif_pool");
  ASSERT_FALSE(dir.path().empty());
  StatusOr<std::unique_ptr<JobStore>> opened = SqliteJobStore::Open(dir.path() + "/jobs.db");
  ASSERT_TRUE(opened.ok()) << opened.status().ToString();
  std::unique_ptr<JobStore> store = std::move(opened).value();
  ASSERT_TRUE(store->RecoverAfterRestart().ok());
  WatchHub hub(store.get(), 10);

  std::atomic<bool> called{false};
  std::atomic<int> state_seen{-1};
  std::string outcome_seen;
  WorkerPoolOptions options;
  options.workers = 1;
  options.idle_poll_ms = 10;
  WorkerPool pool(store.get(), &hub, options, {},
                  [&](const JobRecord& job, std::string_view outcome, double) {
                    const StatusOr<JobRecord> now = store->Get(job.id);
                    state_seen = now.ok() ? static_cast<int>(now->state) : -2;
                    outcome_seen = std::string(outcome);
                    called = true;
                  });
  v1::SimulateRequest request;
  request.set_sample_periods(3);
  const StatusOr<SubmitResult> submitted =
      store->Submit({"simulate", request.SerializeAsString(), "", ""});
  ASSERT_TRUE(submitted.ok()) << submitted.status().ToString();
  pool.Start();
  pool.Wake();
  for (int i = 0; i < 1000 && !called; ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  ASSERT_TRUE(called.load());
  EXPECT_EQ(outcome_seen, "succeeded");
  EXPECT_EQ(state_seen.load(), static_cast<int>(JobState::kRunning));
  // And then it is recorded.
  JobState final_state = JobState::kRunning;
  for (int i = 0; i < 1000 && final_state == JobState::kRunning; ++i) {
    const StatusOr<JobRecord> job = store->Get(submitted->id);
    ASSERT_TRUE(job.ok());
    final_state = job->state;
    if (final_state == JobState::kRunning)
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
  EXPECT_EQ(final_state, JobState::kSucceeded);
  pool.Shutdown();
}

// A store, a hub and a pool started with `options`, submitting straight to the store (no
// admission control: what the pool enforces by itself is what these tests check).
class PoolTest : public ::testing::Test {
 protected:
  void Start(WorkerPoolOptions options) {
    ASSERT_FALSE(dir_.path().empty());
    StatusOr<std::unique_ptr<JobStore>> opened = SqliteJobStore::Open(dir_.path() + "/jobs.db");
    ASSERT_TRUE(opened.ok()) << opened.status().ToString();
    store_ = std::move(opened).value();
    hub_ = std::make_unique<WatchHub>(store_.get(), 10);
    options.idle_poll_ms = 10;
    pool_ = std::make_unique<WorkerPool>(store_.get(), hub_.get(), options);
    pool_->Start();
  }
  void TearDown() override {
    if (pool_) pool_->Shutdown();
    if (hub_) hub_->Stop();
  }

  std::string Submit(const std::string& kind, const google::protobuf::Message& request,
                     int lane = kLaneLong) {
    SubmitRequest submit{kind, jobs::DeterministicBytes(request), "", ""};
    submit.lane = lane;
    StatusOr<SubmitResult> submitted = store_->Submit(submit);
    EXPECT_TRUE(submitted.ok()) << submitted.status().ToString();
    pool_->Wake();
    return submitted.ok() ? submitted->id : std::string();
  }

  // The job once finished, or as it is after `seconds`.
  JobRecord WaitFinished(const std::string& id, double seconds = 30) {
    const auto end = std::chrono::steady_clock::now() + std::chrono::duration<double>(seconds);
    StatusOr<JobRecord> job = store_->Get(id);
    while (job.ok() && !IsFinished(job->state) && std::chrono::steady_clock::now() < end) {
      std::this_thread::sleep_for(std::chrono::milliseconds(5));
      job = store_->Get(id);
    }
    EXPECT_TRUE(job.ok());
    return job.ok() ? *job : JobRecord();
  }

  testing::TempDir dir_{"drillbif_pool"};
  std::unique_ptr<JobStore> store_;
  std::unique_ptr<WatchHub> hub_;
  std::unique_ptr<WorkerPool> pool_;
};

// The time limit is checked at every progress callback, which the sweep calls about every 10 ms:
// the job fails within a second of reaching its limit (1 s of margin for a loaded machine).
TEST_F(PoolTest, ARunAtItsTimeLimitFailsWithDeadlineExceeded) {
  WorkerPoolOptions options;
  options.limits["sweep"] = {0.3, 0, 0};
  Start(options);
  const auto started = std::chrono::steady_clock::now();
  const JobRecord job = WaitFinished(Submit("sweep", testing::LongSweep()));
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
  EXPECT_EQ(job.state, JobState::kFailed);
  EXPECT_EQ(job.error_code, StatusCode::kDeadlineExceeded);
  EXPECT_THAT(job.error_message, ::testing::HasSubstr("max_seconds of sweep jobs"));
  EXPECT_LT(seconds, 0.3 + 1.0);
  EXPECT_GE(seconds, 0.3);
}

// A result that grows past its kind's size limit fails the run, even one admission let through.
TEST_F(PoolTest, AResultAtItsSizeLimitFailsWithResourceExhausted) {
  WorkerPoolOptions options;
  options.limits["simulate"] = {0, 4000, 0};
  Start(options);
  v1::SimulateRequest request;
  request.set_transient_periods(0);
  request.set_sample_periods(1000);  // 1000 samples of ~35 bytes
  const JobRecord job = WaitFinished(Submit("simulate", request));
  EXPECT_EQ(job.state, JobState::kFailed);
  EXPECT_EQ(job.error_code, StatusCode::kResourceExhausted);
  EXPECT_THAT(job.error_message, ::testing::HasSubstr("max_result_bytes of simulate jobs"));
}

// A worker reserved for short jobs never takes a long one.
TEST_F(PoolTest, ShortWorkersTakeShortJobsOnly) {
  WorkerPoolOptions options;
  options.workers = 1;
  options.short_workers = 1;
  Start(options);
  v1::SweepRequest second = testing::LongSweep();
  second.set_min(0.001);
  const std::string first_id = Submit("sweep", testing::LongSweep());
  const std::string second_id = Submit("sweep", second);
  v1::SimulateRequest short_request;
  short_request.set_transient_periods(3);
  short_request.set_sample_periods(3);
  const JobRecord short_job = WaitFinished(Submit("simulate", short_request, kLaneShort), 10);
  EXPECT_EQ(short_job.state, JobState::kSucceeded);
  EXPECT_EQ(short_job.worker_id, "worker-short-0");
  // The second long job still waits: the short worker did not take it.
  std::this_thread::sleep_for(std::chrono::milliseconds(200));
  const StatusOr<JobRecord> waiting = store_->Get(second_id);
  ASSERT_TRUE(waiting.ok());
  EXPECT_EQ(waiting->state, JobState::kQueued);
  EXPECT_EQ(pool_->running(), 1);
}

// A finished run's result is in the store as pages: its items in chunks, the summary apart.
TEST_F(PoolTest, AFinishedRunsItemsAreStoredInChunks) {
  WorkerPoolOptions options;
  options.chunk_bytes = 1024;
  Start(options);
  v1::SimulateRequest request;
  request.set_sample_periods(200);
  const JobRecord job = WaitFinished(Submit("simulate", request));
  ASSERT_EQ(job.state, JobState::kSucceeded) << job.error_message;
  EXPECT_EQ(job.points, 200);
  const StatusOr<ResultInfo> info = store_->GetResultInfo(job.id);
  ASSERT_TRUE(info.ok());
  EXPECT_EQ(info->total_items, 200);
  v1::SimulateResult summary;
  ASSERT_TRUE(summary.ParseFromString(info->summary));
  EXPECT_EQ(summary.poincare_size(), 0);
  EXPECT_EQ(summary.status(), "COMPLETED");
  const StatusOr<std::vector<ResultChunk>> chunks = store_->ReadResultChunks(job.id, 0, 0, 1 << 30);
  ASSERT_TRUE(chunks.ok());
  // ~7 kB of samples in chunks of about 1 kB: a chunk is flushed once it holds 1 kB, so it
  // holds at most 1 kB plus the batch that crossed it (the runner streams batches of
  // ItemBatcher::kItems = 64 samples of ~35 bytes: 2.2 kB; 40 bytes a sample bounds them).
  EXPECT_GT(chunks->size(), 2u);
  for (const ResultChunk& chunk : *chunks) EXPECT_LE(chunk.bytes.size(), 1024u + 64u * 40u);
  const StatusOr<std::string> whole = store_->GetResult(job.id);
  ASSERT_TRUE(whole.ok());
  v1::SimulateResult result;
  ASSERT_TRUE(result.ParseFromString(*whole));
  ASSERT_EQ(result.poincare_size(), 200);
  for (int i = 0; i < 200; ++i) EXPECT_EQ(result.poincare(i).period(), 501 + i);
}

// With leases, a run whose lease is taken back (here by another process's reclaimer, played by
// the test) stops at its next heartbeat and records nothing: the job runs again in a new run,
// which alone finishes it.
TEST_F(PoolTest, ARunThatLosesItsLeaseStopsAndTheJobRunsAgain) {
  std::mutex mutex;
  std::vector<std::string> outcomes;
  ASSERT_FALSE(dir_.path().empty());
  store_ = SqliteJobStore::Open(dir_.path() + "/jobs.db").value();
  hub_ = std::make_unique<WatchHub>(store_.get(), 10);
  WorkerPoolOptions options;
  options.workers = 1;
  options.short_workers = 0;
  options.idle_poll_ms = 10;
  options.lease_ms = 300;
  pool_ = std::make_unique<WorkerPool>(store_.get(), hub_.get(), options, OptimumDoneCallback{},
                                       [&](const JobRecord&, std::string_view outcome, double) {
                                         std::lock_guard<std::mutex> lock(mutex);
                                         outcomes.emplace_back(outcome);
                                       });
  pool_->Start();
  v1::SweepRequest sweep = testing::SmallSweep(0.0, 300);  // about a second of engine time
  const std::string id = Submit("sweep", sweep);
  StatusOr<JobRecord> job = store_->Get(id);
  for (int i = 0; i < 2000 && job.ok() && !(job->state == JobState::kRunning && job->progress > 0);
       ++i) {
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
    job = store_->Get(id);
  }
  ASSERT_TRUE(job.ok() && job->state == JobState::kRunning) << "the job never ran";
  ASSERT_GT(job->lease_expires_ms, 0);
  // Taken back as if its lease had expired.
  ASSERT_EQ(store_->ReclaimExpiredLeases(INT64_MAX).value().requeued, 1);
  const JobRecord done = WaitFinished(id);
  EXPECT_EQ(done.state, JobState::kSucceeded);
  EXPECT_EQ(done.run, job->run + 1);
  EXPECT_EQ(done.attempts, 2);
  std::lock_guard<std::mutex> lock(mutex);
  EXPECT_EQ(outcomes, (std::vector<std::string>{"lease_lost", "succeeded"}));
}

}  // namespace
}  // namespace drillbif::server
