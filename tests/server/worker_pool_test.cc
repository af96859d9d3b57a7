// The worker pool tells its run callback (the job-duration metrics) how a run ended before the
// store makes the outcome visible: a client that sees a job done and then reads /metrics finds
// the run counted there (a race rest_gateway_test's metrics check hit about once in a few runs).
#include "server/worker_pool.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <memory>
#include <string>
#include <thread>

#include "drillbif/v1/simulate.pb.h"
#include "server/store/sqlite_job_store.h"
#include "server/watch_hub.h"
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

}  // namespace
}  // namespace drillbif::server
