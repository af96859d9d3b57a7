// Faults of the SQLite job store, caused for real: a full disk (a 2 MiB tmpfs mounted in a mount
// namespace of the test process), a database file overwritten with garbage (closed, and under
// an open store), a write lock held by another connection. Checks the codes and messages
// clients see (no SQL text), the details in the log callback, Health() and Probe().
#include "support/store_faults.h"

#include <errno.h>
#include <fcntl.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sched.h>
#include <sqlite3.h>
#include <sys/mount.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "server/store/job_store.h"
#include "server/store/sqlite_job_store.h"
#include "support/small_tmpfs.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

using drillbif::testing::ExpectNoSql;
using drillbif::testing::FileSize;
using drillbif::testing::OverwritePages;

using ::testing::HasSubstr;
using ::testing::Not;
using ::testing::StartsWith;

template <typename T>
T Must(StatusOr<T> result) {
  EXPECT_TRUE(result.ok()) << result.status().ToString();
  return result.ok() ? std::move(result).value() : T{};
}

// Collects the store's log lines (the callback runs under the store's lock; the test reads
// them between calls).
struct Log {
  std::mutex mu;
  std::vector<std::string> lines;

  std::function<void(std::string_view)> Callback() {
    return [this](std::string_view line) {
      std::lock_guard<std::mutex> lock(mu);
      lines.emplace_back(line);
    };
  }
  bool Contains(const std::string& text) {
    std::lock_guard<std::mutex> lock(mu);
    for (const std::string& line : lines) {
      if (line.find(text) != std::string::npos) return true;
    }
    return false;
  }
};

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
}

void SqlExec(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  EXPECT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr), SQLITE_OK)
      << sqlite3_errmsg(db);
  sqlite3_close(db);
}

// A closed store file of about 1.5 MB of small jobs (table and index pages, not blobs, so that
// garbage anywhere in the middle lands in b-tree pages that a scan reads).
void MakeStoreWithManyJobs(const std::string& path) {
  {
    StatusOr<std::unique_ptr<JobStore>> store = SqliteJobStore::Open(path);
    ASSERT_TRUE(store.ok()) << store.status().ToString();
  }
  SqlExec(path,
          "WITH RECURSIVE n(i) AS (SELECT 1 UNION ALL SELECT i + 1 FROM n WHERE i < 5000) "
          "INSERT INTO jobs (id, kind, state, request, cache_key, result_key, created_ms, "
          "finished_ms) SELECT printf('%032x', i), 'simulate', 4, randomblob(100), '', "
          "'j:' || printf('%032x', i), i, i FROM n");
}

// ---------------------------------------------------------------------------------------------

TEST(StoreFaultsTest, CorruptFileIsRefusedAtOpenAndLeftUntouched) {
  drillbif::testing::TempDir dir("drillbif_faults");
  const std::string path = dir.path() + "/jobs.db";
  MakeStoreWithManyJobs(path);
  const int64_t pages = FileSize(path) / 4096;
  ASSERT_GT(pages, 200);
  OverwritePages(path, 4096, pages / 2, 8);
  const std::string before = ReadFile(path);

  Log log;
  SqliteJobStoreOptions options;
  options.log = log.Callback();
  StatusOr<std::unique_ptr<JobStore>> store = SqliteJobStore::Open(path, options);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(store.status().message(), StartsWith("the job store failed its integrity check: "));
  EXPECT_THAT(store.status().message(), HasSubstr(path));
  EXPECT_TRUE(log.Contains("integrity check"));
  EXPECT_EQ(ReadFile(path), before) << "a refused file must not be modified";
}

TEST(StoreFaultsTest, CorruptionUnderAnOpenStoreIsDataLossAndStaysInHealth) {
  drillbif::testing::TempDir dir("drillbif_faults");
  const std::string path = dir.path() + "/jobs.db";
  MakeStoreWithManyJobs(path);
  Log log;
  SqliteJobStoreOptions options;
  options.log = log.Callback();
  StatusOr<std::unique_ptr<JobStore>> opened = SqliteJobStore::Open(path, options);
  ASSERT_TRUE(opened.ok()) << opened.status().ToString();
  JobStore& store = **opened;
  EXPECT_TRUE(store.Health().ok());
  EXPECT_TRUE(store.Probe().ok());

  // The middle half of the file becomes garbage behind the store's back; the store has read
  // none of those pages yet (the integrity check used its own connection).
  const int64_t pages = FileSize(path) / 4096;
  OverwritePages(path, 4096, pages / 4, pages / 2);
  Status failure;
  ListRequest list;
  list.page_size = 1000;
  for (int page = 0; page < 10 && failure.ok(); ++page) {
    StatusOr<ListResult> result = store.List(list);
    failure = result.status();
    if (result.ok()) {
      if (result->next_page_token.empty()) break;
      list.page_token = result->next_page_token;
    }
  }
  EXPECT_EQ(failure.code(), StatusCode::kDataLoss);
  EXPECT_EQ(failure.message(), "the job store is corrupt");
  ExpectNoSql(failure.message());
  EXPECT_TRUE(log.Contains("SELECT"));  // The statement is in the log, not in the message.
  EXPECT_EQ(store.Health().code(), StatusCode::kDataLoss);
  // A probe's small write may well succeed, but the full check it runs after a DATA_LOSS fault
  // does not: the fault stays.
  Status probe = store.Probe();
  EXPECT_EQ(probe.code(), StatusCode::kDataLoss);
  EXPECT_THAT(probe.message(), StartsWith("the job store failed its integrity check: "));
  EXPECT_EQ(store.Health().code(), StatusCode::kDataLoss);
}

TEST(StoreFaultsTest, ABusyStoreIsUnavailableWithoutBecomingUnhealthy) {
  drillbif::testing::TempDir dir("drillbif_faults");
  const std::string path = dir.path() + "/jobs.db";
  Log log;
  SqliteJobStoreOptions options;
  options.busy_timeout_ms = 20;
  options.log = log.Callback();
  StatusOr<std::unique_ptr<JobStore>> store = SqliteJobStore::Open(path, options);
  ASSERT_TRUE(store.ok()) << store.status().ToString();
  // Another connection holds the write lock.
  sqlite3* other = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &other), SQLITE_OK);
  ASSERT_EQ(sqlite3_exec(other, "BEGIN IMMEDIATE", nullptr, nullptr, nullptr), SQLITE_OK);
  StatusOr<SubmitResult> submitted = (*store)->Submit({"simulate", "r", "", ""});
  EXPECT_EQ(submitted.status().code(), StatusCode::kUnavailable);
  EXPECT_EQ(submitted.status().message(), "the job store is busy; retry later");
  EXPECT_TRUE(log.Contains("BEGIN IMMEDIATE"));
  EXPECT_TRUE(log.Contains("database is locked"));
  EXPECT_TRUE((*store)->Health().ok()) << "busy is transient, not a fault";
  sqlite3_exec(other, "ROLLBACK", nullptr, nullptr, nullptr);
  sqlite3_close(other);
  EXPECT_TRUE((*store)->Submit({"simulate", "r", "", ""}).ok());
}

// ---------------------------------------------------------------------------------------------
// A full disk.

TEST(StoreFaultsTest, AFullDiskFailsTheWriteButTheJobCanStillBeFailedAndProbeRecovers) {
  drillbif::testing::TempDir dir("drillbif_faults");
  ASSERT_FALSE(dir.path().empty());
  const std::string mount_dir = dir.path() + "/small";
  ASSERT_TRUE(std::filesystem::create_directory(mount_dir));
  constexpr int64_t kDiskBytes = 2 << 20;
  testing::SmallTmpfs tmpfs(mount_dir, kDiskBytes);
  if (!tmpfs.error().empty()) GTEST_SKIP() << "no small file system to fill: " << tmpfs.error();
  const std::string path = mount_dir + "/jobs.db";
  Log log;
  SqliteJobStoreOptions options;
  options.log = log.Callback();
  std::string id;
  {
    // Create, then close: a store that has run a while has its pages in the file, not the WAL.
    std::unique_ptr<JobStore> store = Must(SqliteJobStore::Open(path, options));
    ASSERT_NE(store, nullptr);
    id = Must(store->Submit({"sweep", "r", "K", ""})).id;
  }
  std::unique_ptr<JobStore> store = Must(SqliteJobStore::Open(path, options));
  ASSERT_NE(store, nullptr);
  const JobRecord job = Must(store->ClaimNext("w")).value_or(JobRecord());
  ASSERT_EQ(job.id, id);
  ASSERT_TRUE(store->AppendResultChunk(id, job.run, 0, 0, 1, std::string(1000, 'a')).ok());

  // A chunk larger than the whole disk.
  Status full = store->AppendResultChunk(id, job.run, 0, 1, 1, std::string(kDiskBytes + 1, 'b'));
  EXPECT_EQ(full.code(), StatusCode::kResourceExhausted);
  EXPECT_EQ(full.message(), "the job store's disk is full");
  ExpectNoSql(full.message());
  // SQLite's own words, and the statement that failed (the INSERT, or the COMMIT when the pages
  // stayed in the page cache until then), are in the log only.
  EXPECT_TRUE(log.Contains("database or disk is full"));
  EXPECT_EQ(store->Health().code(), StatusCode::kResourceExhausted);
  // The WAL gave the space back (checkpointed and truncated after the failure).
  EXPECT_LE(FileSize(path + "-wal"), 0);

  // The job is unchanged and its worker can record the failure: a small write fits again.
  EXPECT_EQ(Must(store->Get(id)).state, JobState::kRunning);
  Status failed = store->Fail(id, job.run, StatusCode::kResourceExhausted, "disk full");
  ASSERT_TRUE(failed.ok()) << failed.ToString();
  EXPECT_EQ(Must(store->Get(id)).state, JobState::kFailed);
  EXPECT_EQ(store->Health().code(), StatusCode::kResourceExhausted) << "until a probe succeeds";

  // With the disk filled to the last byte even a probe fails; once space is freed it succeeds.
  const std::string filler = mount_dir + "/filler";
  ASSERT_GT(testing::FillDisk(filler), 0);
  Status probe = store->Probe();
  EXPECT_EQ(probe.code(), StatusCode::kResourceExhausted);
  EXPECT_EQ(store->Health().code(), StatusCode::kResourceExhausted);
  ASSERT_TRUE(std::filesystem::remove(filler));
  probe = store->Probe();
  EXPECT_TRUE(probe.ok()) << probe.ToString();
  EXPECT_TRUE(store->Health().ok());
  EXPECT_TRUE(log.Contains("fault cleared"));

  // And the store works again.
  const std::string next = Must(store->Submit({"sweep", "r2", "", ""})).id;
  const JobRecord again = Must(store->ClaimNext("w")).value_or(JobRecord());
  ASSERT_EQ(again.id, next);
  ASSERT_TRUE(store->AppendResultChunk(next, again.run, 0, 0, 1, "item").ok());
  ASSERT_TRUE(store->Complete(next, again.run, "S", 1).ok());
  EXPECT_EQ(Must(store->GetResult(next)), "Sitem");
  store.reset();
}

}  // namespace
}  // namespace drillbif::server
