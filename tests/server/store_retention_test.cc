// Retention in the job store (Evict): finished jobs deleted by age and by the size of the data,
// oldest first; queued, running and followed jobs kept; results and chunks deleted with their
// last holder; the space given back to the disk (SQLite). Finish times are set behind the store's
// back (through a separate connection) so that ages do not depend on the clock. Run on every
// store implementation (support/store_under_test.h).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "server/store/job_store.h"
#include "support/store_under_test.h"

namespace drillbif::server {
namespace {

template <typename T>
T Must(StatusOr<T> result) {
  EXPECT_TRUE(result.ok()) << result.status().ToString();
  return result.ok() ? std::move(result).value() : T{};
}

constexpr int64_t kDayMs = 24 * 3600 * 1000;

int64_t FileSize(const std::string& path) {
  std::error_code error;
  const auto size = std::filesystem::file_size(path, error);
  return error ? 0 : static_cast<int64_t>(size);
}

class StoreRetentionTest : public ::testing::TestWithParam<drillbif::testing::StoreKind> {
 protected:
  void SetUp() override {
    ASSERT_TRUE(under_test_.Create());
    store_ = under_test_.Open();
    ASSERT_NE(store_, nullptr);
  }

  bool sqlite() const { return GetParam() == drillbif::testing::StoreKind::kSqlite; }
  // The SQLite file (empty for other stores).
  std::string path() const { return under_test_.path(); }
  int64_t SqlInt(const std::string& sql) { return under_test_.SqlInt(sql); }

  std::string Submit(const std::string& request, const std::string& cache_key = "",
                     const std::string& request_id = "") {
    return Must(store_->Submit({"sweep", request, cache_key, request_id})).id;
  }

  // Claims `id` (it must be the next claimable job) and returns its run.
  int64_t Claim(const std::string& id) {
    std::optional<JobRecord> job = Must(store_->ClaimNext("w"));
    EXPECT_TRUE(job.has_value() && job->id == id);
    return job ? job->run : 0;
  }

  // Runs `id` to success with one chunk of `chunk_bytes` bytes.
  void RunToSuccess(const std::string& id, int64_t chunk_bytes) {
    const int64_t run = Claim(id);
    ASSERT_TRUE(store_
                    ->AppendResultChunk(id, run, 0, 0, 1,
                                        std::string(static_cast<size_t>(chunk_bytes), 'x'))
                    .ok());
    ASSERT_TRUE(store_->Complete(id, run, "summary", 1).ok());
  }

  // Sets when `id` finished (behind the store's back).
  void SetFinished(const std::string& id, int64_t finished_ms) {
    EXPECT_EQ(SqlInt("UPDATE jobs SET finished_ms = " + std::to_string(finished_ms) +
                     " WHERE id = '" + id + "' RETURNING 1"),
              1);
  }

  bool Exists(const std::string& id) { return store_->Get(id).ok(); }

  // What the store counts as its data, computed independently of it: for SQLite the pages in
  // use, for PostgreSQL (whose pages are given back by autovacuum, not by deletion) the bytes of
  // every request, result summary and chunk.
  int64_t UsedBytesBySql() {
    if (!sqlite()) {
      return SqlInt(
          "SELECT (SELECT COALESCE(SUM(octet_length(request)), 0) FROM jobs)"
          " + (SELECT COALESCE(SUM(octet_length(data)), 0) FROM results)"
          " + (SELECT COALESCE(SUM(octet_length(data)), 0) FROM result_chunks)");
    }
    return SqlInt(
        "SELECT ((SELECT page_count FROM pragma_page_count()) - "
        "(SELECT freelist_count FROM pragma_freelist_count())) * "
        "(SELECT page_size FROM pragma_page_size())");
  }

  drillbif::testing::StoreUnderTest under_test_{GetParam()};
  std::unique_ptr<JobStore> store_;
};

INSTANTIATE_TEST_SUITE_P(Stores, StoreRetentionTest,
                         ::testing::ValuesIn(drillbif::testing::kStoreKinds),
                         drillbif::testing::StoreKindName);

TEST_P(StoreRetentionTest, DeletesFinishedJobsOlderThanTheMaxAge) {
  // Finished on day 1: a success with chunks (a cached key and a request_id), a failure, a
  // cancellation, and a cache hit on a result that a recent job also holds.
  const std::string old_done = Submit("a", "Kold", "rid-old");
  RunToSuccess(old_done, 1000);
  const std::string old_failed = Submit("b");
  ASSERT_TRUE(store_->Fail(old_failed, Claim(old_failed), StatusCode::kInternal, "x").ok());
  const std::string old_cancelled = Submit("c");
  ASSERT_EQ(Must(store_->Cancel(old_cancelled)), JobState::kCancelled);
  const std::string recent_done = Submit("d", "Krecent");
  RunToSuccess(recent_done, 1000);
  const std::string old_hit = Submit("d", "Krecent");
  ASSERT_TRUE(Must(store_->Get(old_hit)).cache_hit);
  // Not finished: never evicted.
  const std::string running = Submit("e");
  Claim(running);
  const std::string queued = Submit("f");
  for (const std::string& id : {old_done, old_failed, old_cancelled, old_hit}) {
    SetFinished(id, 1 * kDayMs);
  }
  SetFinished(recent_done, 95 * kDayMs);
  ASSERT_EQ(SqlInt("SELECT COUNT(*) FROM result_chunks"), 2);

  RetentionOptions retention;
  retention.max_age_ms = 10 * kDayMs;
  const EvictionReport report = Must(store_->Evict(retention, 100 * kDayMs));
  EXPECT_EQ(report.jobs_deleted, 4);
  EXPECT_EQ(report.results_deleted, 1);  // old_done's; Krecent's result is still held.
  EXPECT_TRUE(report.size_limit_met);
  for (const std::string& id : {old_done, old_failed, old_cancelled, old_hit}) {
    EXPECT_FALSE(Exists(id)) << id;
  }
  for (const std::string& id : {recent_done, running, queued}) EXPECT_TRUE(Exists(id)) << id;
  EXPECT_EQ(SqlInt("SELECT COUNT(*) FROM result_chunks"), 1);
  EXPECT_EQ(Must(store_->GetResult(recent_done)), "summary" + std::string(1000, 'x'));
  // The evicted job's request_id and cached result are forgotten.
  const SubmitResult again = Must(store_->Submit({"sweep", "a", "Kold", "rid-old"}));
  EXPECT_FALSE(again.deduplicated);
  EXPECT_FALSE(again.cache_hit);

  // Exactly at the age limit is not older than it.
  SetFinished(recent_done, 90 * kDayMs);
  EXPECT_EQ(Must(store_->Evict(retention, 100 * kDayMs)).jobs_deleted, 0);
  EXPECT_EQ(Must(store_->Evict(retention, 100 * kDayMs + 1)).jobs_deleted, 1);
}

TEST_P(StoreRetentionTest, DeletesTheOldestFinishedJobsUntilTheDataFits) {
  constexpr int kJobs = 10;
  constexpr int64_t kChunk = 64 << 10;
  std::vector<std::string> finished;
  for (int i = 0; i < kJobs; ++i) {
    finished.push_back(Submit("job " + std::to_string(i)));
    RunToSuccess(finished.back(), kChunk);
  }
  // Finish times out of submission order: eviction goes by finish time.
  for (int i = 0; i < kJobs; ++i) SetFinished(finished[i], (kJobs - i) * kDayMs);
  const std::string running = Submit("running");
  const int64_t run = Claim(running);
  ASSERT_TRUE(store_->AppendResultChunk(running, run, 0, 0, 1, std::string(kChunk, 'r')).ok());
  const std::string queued = Submit("queued");

  const int64_t used = Must(store_->Stats()).used_bytes;
  EXPECT_EQ(used, UsedBytesBySql());
  // Each deleted job frees its 64 KiB chunk (in SQLite 17 pages of 4 KiB: 4092 usable bytes per
  // overflow page) and a little more; 4.5 chunks over the limit takes 5 deletions (4 free at
  // most 4 * 17 pages = 272 KiB < 288 KiB), 6 if rounding of the b-tree pages goes against it.
  RetentionOptions retention;
  retention.max_db_bytes = used - kChunk * 9 / 2;
  const EvictionReport report = Must(store_->Evict(retention, 0));
  EXPECT_GE(report.jobs_deleted, 5);
  EXPECT_LE(report.jobs_deleted, 6);
  EXPECT_EQ(report.results_deleted, report.jobs_deleted);
  EXPECT_TRUE(report.size_limit_met);
  EXPECT_EQ(report.used_bytes_before, used);
  EXPECT_LE(report.used_bytes_after, retention.max_db_bytes);
  EXPECT_EQ(report.used_bytes_after, UsedBytesBySql());
  // Oldest first: the last-submitted jobs finished first.
  for (int i = 0; i < kJobs; ++i) {
    EXPECT_EQ(Exists(finished[i]), i < kJobs - report.jobs_deleted) << i;
  }
  if (sqlite()) {
    // The freed pages went back to the disk: the file holds only the used pages, and the WAL was
    // checkpointed and truncated. (PostgreSQL reuses and returns them by autovacuum.)
    EXPECT_LT(report.disk_bytes_after, report.disk_bytes_before);
    EXPECT_EQ(SqlInt("PRAGMA freelist_count"), 0);
    EXPECT_EQ(FileSize(path()), report.used_bytes_after);
    EXPECT_EQ(FileSize(path() + "-wal"), 0);
  }

  EXPECT_TRUE(Exists(queued));
  // The running job's chunk was not touched: it completes with it.
  ASSERT_TRUE(store_->Complete(running, run, "S", 1).ok());
  const std::string expected = std::string("S") + std::string(kChunk, 'r');
  EXPECT_EQ(Must(store_->GetResult(running)), expected);
}

TEST_P(StoreRetentionTest, AJobThatAnUnfinishedJobFollowsIsKept) {
  // The store never leaves a finished job with an unfinished follower; make that state by hand
  // to check that eviction would not break the follower's link.
  const std::string leader = Submit("a");
  RunToSuccess(leader, 10);
  const std::string other = Submit("b");
  RunToSuccess(other, 10);
  const std::string follower = Submit("c");
  EXPECT_EQ(
      SqlInt("UPDATE jobs SET shares = '" + leader + "' WHERE id = '" + follower + "' RETURNING 1"),
      1);
  RetentionOptions retention;
  retention.max_age_ms = 1;
  retention.max_db_bytes = 1;
  const EvictionReport report = Must(store_->Evict(retention, INT64_MAX));
  EXPECT_EQ(report.jobs_deleted, 1);
  EXPECT_FALSE(Exists(other));
  EXPECT_TRUE(Exists(leader));
  EXPECT_EQ(Must(store_->Get(follower)).shared_with, leader);
  EXPECT_FALSE(report.size_limit_met);  // What remains cannot go.
}

TEST_P(StoreRetentionTest, ALimitBelowTheUnfinishedJobsDeletesOnlyFinishedOnes) {
  const std::string done = Submit("done");
  RunToSuccess(done, 10);
  const std::string running = Submit("running");
  const int64_t run = Claim(running);
  ASSERT_TRUE(store_->AppendResultChunk(running, run, 0, 0, 1, std::string(100000, 'r')).ok());
  Submit("queued");
  RetentionOptions retention;
  retention.max_db_bytes = 1;
  const EvictionReport report = Must(store_->Evict(retention, 0));
  EXPECT_EQ(report.jobs_deleted, 1);
  EXPECT_FALSE(report.size_limit_met);
  EXPECT_EQ(Must(store_->Stats()).jobs_by_state[static_cast<int>(JobState::kQueued)], 1);
  EXPECT_EQ(Must(store_->Get(running)).state, JobState::kRunning);
  EXPECT_EQ(SqlInt("SELECT COUNT(*) FROM result_chunks"), 1);
}

TEST_P(StoreRetentionTest, BadOptionsAreRejectedAndNoLimitsDeleteNothing) {
  const std::string done = Submit("done");
  RunToSuccess(done, 10);
  RetentionOptions bad;
  bad.max_age_ms = -1;
  EXPECT_EQ(store_->Evict(bad, 0).status().code(), StatusCode::kInvalidArgument);
  bad = RetentionOptions();
  bad.max_db_bytes = -1;
  EXPECT_EQ(store_->Evict(bad, 0).status().code(), StatusCode::kInvalidArgument);
  const EvictionReport report = Must(store_->Evict(RetentionOptions(), INT64_MAX));
  EXPECT_EQ(report.jobs_deleted, 0);
  EXPECT_TRUE(Exists(done));
  // A max age larger than now (the cutoff would be before INT64_MIN) deletes nothing either.
  RetentionOptions huge;
  huge.max_age_ms = INT64_MAX;
  EXPECT_EQ(Must(store_->Evict(huge, -1000)).jobs_deleted, 0);
}

}  // namespace
}  // namespace drillbif::server
