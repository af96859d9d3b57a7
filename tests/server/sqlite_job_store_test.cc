// SqliteJobStore durability and concurrency: restart recovery, a real kill -9 of a process in
// the middle of its work, several threads and connections claiming at once, and schema
// migration by user_version. Real files in a temporary directory.
#include "server/store/sqlite_job_store.h"

#include <fcntl.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sqlite3.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <latch>
#include <map>
#include <memory>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "server/store/job_store.h"
#include "support/sqlite_sql.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

using ::testing::HasSubstr;

// The value of a StatusOr the test expects to be OK. On an error: a test failure and T{} instead
// of undefined behaviour, so that one wrong result does not crash the checks that follow (and
// skip the temp dir's cleanup).
template <typename T>
T Must(StatusOr<T> result) {
  EXPECT_TRUE(result.ok()) << result.status().ToString();
  return result.ok() ? std::move(result).value() : T{};
}

// The id of the job the store hands out next ("" when none).
std::string ClaimedId(JobStore& store, const std::string& worker) {
  std::optional<JobRecord> job = Must(store.ClaimNext(worker));
  return job ? job->id : std::string();
}

using drillbif::testing::TempDir;

std::unique_ptr<JobStore> OpenOrDie(const std::string& path,
                                    const SqliteJobStoreOptions& options = {}) {
  StatusOr<std::unique_ptr<JobStore>> store = SqliteJobStore::Open(path, options);
  EXPECT_TRUE(store.ok()) << store.status().ToString();
  return store.ok() ? std::move(store).value() : nullptr;
}

using drillbif::testing::SqliteInt;

void SqlExec(const std::string& path, const std::string& sql) {
  sqlite3* db = nullptr;
  ASSERT_EQ(sqlite3_open(path.c_str(), &db), SQLITE_OK);
  EXPECT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr), SQLITE_OK)
      << sqlite3_errmsg(db);
  sqlite3_close(db);
}

class SqliteJobStoreTest : public ::testing::Test {
 protected:
  void SetUp() override { ASSERT_FALSE(dir_.path().empty()) << "mkdtemp failed"; }
  std::string Path(const char* name) const { return dir_.path() + "/" + name; }

  TempDir dir_{"drillbif_sqlite"};
};

TEST_F(SqliteJobStoreTest, OpensInWalModeAtTheCurrentSchemaVersion) {
  const std::string path = Path("jobs.db");
  ASSERT_NE(OpenOrDie(path), nullptr);
  EXPECT_EQ(SqliteInt(path, "PRAGMA user_version"), SqliteJobStore::kSchemaVersion);
  EXPECT_EQ(SqliteInt(path, "PRAGMA application_id"), SqliteJobStore::kApplicationId);
  // journal_mode=WAL is persistent: a plain connection sees it.
  EXPECT_EQ(SqliteInt(path, "SELECT journal_mode = 'wal' FROM pragma_journal_mode"), 1);
  // Reopening an up-to-date file changes nothing.
  ASSERT_NE(OpenOrDie(path), nullptr);
  EXPECT_EQ(SqliteInt(path, "PRAGMA user_version"), SqliteJobStore::kSchemaVersion);
}

TEST_F(SqliteJobStoreTest, MigratesAVersionZeroFile) {
  const std::string path = Path("old.db");
  // An SQLite file at user_version 0, as a build before the store would leave it.
  SqlExec(path,
          "CREATE TABLE unrelated_notes (text TEXT); INSERT INTO unrelated_notes VALUES ('x')");
  ASSERT_EQ(SqliteInt(path, "PRAGMA user_version"), 0);
  std::unique_ptr<JobStore> store = OpenOrDie(path);
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(SqliteInt(path, "PRAGMA user_version"), SqliteJobStore::kSchemaVersion);
  EXPECT_EQ(SqliteInt(path,
                      "SELECT COUNT(*) FROM sqlite_master WHERE name IN "
                      "('jobs', 'results', 'counters', 'result_chunks')"),
            4);
  EXPECT_EQ(SqliteInt(path, "SELECT COUNT(*) FROM unrelated_notes"), 1);  // Left alone.
  StatusOr<SubmitResult> job = store->Submit({"simulate", "r", "k", ""});
  EXPECT_TRUE(job.ok()) << job.status().ToString();
}

// The schema of version 1 as released (migration 0 -> 1), to build a file as that version left it.
constexpr const char* kSchemaVersion1 = R"sql(
CREATE TABLE jobs (
  seq INTEGER PRIMARY KEY AUTOINCREMENT,
  id TEXT NOT NULL UNIQUE,
  kind TEXT NOT NULL CHECK (kind <> ''),
  state INTEGER NOT NULL CHECK (state BETWEEN 0 AND 4),
  request BLOB NOT NULL,
  cache_key TEXT NOT NULL,
  request_id TEXT,
  shares TEXT REFERENCES jobs(id) ON DELETE SET NULL,
  result_key TEXT NOT NULL,
  progress REAL NOT NULL DEFAULT 0,
  current_value REAL,
  points INTEGER NOT NULL DEFAULT 0,
  error_code INTEGER NOT NULL DEFAULT 0,
  error_message TEXT NOT NULL DEFAULT '',
  created_ms INTEGER NOT NULL,
  started_ms INTEGER NOT NULL DEFAULT 0,
  finished_ms INTEGER NOT NULL DEFAULT 0,
  cache_hit INTEGER NOT NULL DEFAULT 0,
  attempts INTEGER NOT NULL DEFAULT 0,
  cancel_requested INTEGER NOT NULL DEFAULT 0,
  worker_id TEXT NOT NULL DEFAULT ''
);
CREATE UNIQUE INDEX jobs_by_request_id ON jobs(request_id) WHERE request_id IS NOT NULL;
CREATE INDEX jobs_by_state ON jobs(state, seq);
CREATE INDEX jobs_by_cache_key ON jobs(cache_key, seq) WHERE cache_key <> '';
CREATE INDEX jobs_by_shares ON jobs(shares) WHERE shares IS NOT NULL;
CREATE INDEX jobs_by_result_key ON jobs(result_key);
CREATE TABLE results (
  result_key TEXT PRIMARY KEY,
  data BLOB NOT NULL,
  points INTEGER NOT NULL,
  created_ms INTEGER NOT NULL
);
CREATE TABLE counters (
  name TEXT PRIMARY KEY,
  value INTEGER NOT NULL
);
INSERT INTO counters(name, value) VALUES ('cache_hits', 0);
)sql";

TEST_F(SqliteJobStoreTest, MigratesAVersionOneFileKeepingItsJobsAndResults) {
  const std::string path = Path("v1.db");
  SqlExec(path, std::string("PRAGMA journal_mode = WAL;") + kSchemaVersion1 +
                    "PRAGMA application_id = 1145203046; PRAGMA user_version = 1;"
                    // A finished job with its result, a job that ran twice, a queued job.
                    "INSERT INTO jobs (id, kind, state, request, cache_key, result_key, "
                    "  points, created_ms, finished_ms, attempts) VALUES "
                    "  ('done', 'simulate', 2, x'01', 'K', 'c:K', 3, 1, 2, 1),"
                    "  ('running', 'sweep', 1, x'02', '', 'j:running', 0, 1, 0, 2),"
                    "  ('queued', 'sweep', 0, x'03', '', 'j:queued', 0, 1, 0, 0);"
                    "INSERT INTO results VALUES ('c:K', x'0a0b0c', 3, 2);");
  ASSERT_EQ(SqliteInt(path, "PRAGMA user_version"), 1);
  std::unique_ptr<JobStore> store = OpenOrDie(path);
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(SqliteInt(path, "PRAGMA user_version"), SqliteJobStore::kSchemaVersion);
  // Existing jobs: anonymous, short lane, run = attempts (the claims they had), no lease (the
  // running one is recovered at the next start, as before).
  const JobRecord running = Must(store->Get("running"));
  EXPECT_EQ(running.lease_expires_ms, 0);
  EXPECT_EQ(running.client, "");
  EXPECT_EQ(running.lane, kLaneShort);
  EXPECT_EQ(running.attempts, 2);
  EXPECT_EQ(running.run, 2);
  // An existing result is all summary, no chunks.
  EXPECT_EQ(Must(store->GetResult("done")), "\x0a\x0b\x0c");
  const ResultInfo info = Must(store->GetResultInfo("done"));
  EXPECT_EQ(info.summary, "\x0a\x0b\x0c");
  EXPECT_EQ(info.total_items, 0);
  EXPECT_EQ(info.total_bytes, 3);
  EXPECT_EQ(info.points, 3);
  EXPECT_TRUE(Must(store->ReadResultChunks("done", 0, 0, 100)).empty());
  // A cache hit on the old result, and the old jobs run on.
  EXPECT_TRUE(Must(store->Submit({"simulate", "x", "K", ""})).cache_hit);
  ASSERT_EQ(Must(store->RecoverAfterRestart()).requeued, 1);
  std::optional<JobRecord> again = Must(store->ClaimNext("w"));
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->id, "running");  // Requeued, oldest.
  EXPECT_EQ(again->run, 3);
  ASSERT_TRUE(store->AppendResultChunk("running", 3, 0, 0, 1, "item").ok());
  ASSERT_TRUE(store->Complete("running", 3, "sum", 1).ok());
  EXPECT_EQ(Must(store->GetResult("running")), "sumitem");
  // An old file keeps auto_vacuum NONE (it cannot change without a VACUUM); a new one is
  // INCREMENTAL.
  EXPECT_EQ(SqliteInt(path, "PRAGMA auto_vacuum"), 0);
  ASSERT_NE(OpenOrDie(Path("new.db")), nullptr);
  EXPECT_EQ(SqliteInt(Path("new.db"), "PRAGMA auto_vacuum"), 2);
}

TEST_F(SqliteJobStoreTest, RefusesAFileFromANewerSchema) {
  const std::string path = Path("future.db");
  SqlExec(path, "PRAGMA user_version = 99");
  StatusOr<std::unique_ptr<JobStore>> store = SqliteJobStore::Open(path);
  ASSERT_FALSE(store.ok());
  EXPECT_EQ(store.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(store.status().message(), HasSubstr("schema version 99 is newer"));
  EXPECT_EQ(SqliteInt(path, "PRAGMA user_version"), 99);  // Untouched.
  EXPECT_EQ(SqliteInt(path, "SELECT COUNT(*) FROM sqlite_master"), 0);
}

TEST_F(SqliteJobStoreTest, RefusesAnotherApplicationsFile) {
  const std::string path = Path("other.db");
  SqlExec(path, "PRAGMA application_id = 1234");
  StatusOr<std::unique_ptr<JobStore>> store = SqliteJobStore::Open(path);
  EXPECT_EQ(store.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(store.status().message(), HasSubstr("not a drillbif job store"));
}

TEST_F(SqliteJobStoreTest, RefusesAFileThatIsNotSqlite) {
  const std::string path = Path("garbage.db");
  std::ofstream(path) << std::string(4096, 'z');
  StatusOr<std::unique_ptr<JobStore>> store = SqliteJobStore::Open(path);
  EXPECT_EQ(store.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(store.status().message(), HasSubstr("failed its integrity check"));
  EXPECT_THAT(store.status().message(), HasSubstr("not a database"));
  // Without the integrity check the first read finds it.
  SqliteJobStoreOptions unchecked;
  unchecked.integrity_check_at_open = false;
  store = SqliteJobStore::Open(path, unchecked);
  EXPECT_EQ(store.status().code(), StatusCode::kDataLoss);
  EXPECT_THAT(store.status().message(), HasSubstr("not a database"));
}

TEST_F(SqliteJobStoreTest, RestartRequeuesRunningJobsAndKeepsFinishedResults) {
  const std::string path = Path("jobs.db");
  std::string done, running, cancelling, queued, follower;
  {
    std::unique_ptr<JobStore> store = OpenOrDie(path);
    ASSERT_NE(store, nullptr);
    done = Must(store->Submit({"simulate", "1", "", ""})).id;
    running = Must(store->Submit({"sweep", "2", "K", ""})).id;
    cancelling = Must(store->Submit({"sweep", "3", "", ""})).id;
    queued = Must(store->Submit({"sweep", "4", "", ""})).id;
    follower = Must(store->Submit({"sweep", "2", "K", ""})).id;
    ASSERT_EQ(ClaimedId(*store, "w"), done);
    ASSERT_TRUE(store->Complete(done, "result 1", 5).ok());
    ASSERT_EQ(ClaimedId(*store, "w"), running);
    ASSERT_TRUE(store->UpdateProgress(running, 0.5, 0.2, 9).ok());
    ASSERT_EQ(ClaimedId(*store, "w"), cancelling);
    ASSERT_EQ(Must(store->Cancel(cancelling)), JobState::kRunning);
    // The process ends here with two jobs RUNNING (the store is closed without any cleanup).
  }
  std::unique_ptr<JobStore> store = OpenOrDie(path);
  ASSERT_NE(store, nullptr);
  EXPECT_EQ(Must(store->Get(running)).state, JobState::kRunning);  // Open alone does not recover.
  StatusOr<RecoveryReport> report = store->RecoverAfterRestart();
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_EQ(report->requeued, 1);
  EXPECT_EQ(report->cancelled, 1);
  EXPECT_EQ(report->failed, 0);

  JobRecord requeued = Must(store->Get(running));
  EXPECT_EQ(requeued.state, JobState::kQueued);
  EXPECT_EQ(requeued.attempts, 1);
  EXPECT_EQ(requeued.progress, 0.0);  // The interrupted run's progress is gone.
  EXPECT_EQ(Must(store->Get(follower)).state, JobState::kQueued);
  EXPECT_EQ(Must(store->Get(follower)).shared_with, running);
  EXPECT_EQ(Must(store->Get(cancelling)).state, JobState::kCancelled);
  EXPECT_EQ(Must(store->Get(queued)).state, JobState::kQueued);
  EXPECT_EQ(Must(store->Get(done)).state, JobState::kSucceeded);
  EXPECT_EQ(Must(store->GetResult(done)), "result 1");

  // The requeued job runs again, first (it is the oldest), and its follower finishes with it.
  StatusOr<std::optional<JobRecord>> again = store->ClaimNext("w2");
  ASSERT_TRUE(again.ok() && again->has_value());
  EXPECT_EQ((*again)->id, running);
  EXPECT_EQ((*again)->attempts, 2);
  ASSERT_TRUE(store->Complete(running, "result 2", 1).ok());
  EXPECT_EQ(Must(store->GetResult(follower)), "result 2");
  EXPECT_EQ(Must(store->RecoverAfterRestart()).requeued, 0);  // Nothing left running.
}

TEST_F(SqliteJobStoreTest, AJobThatKeepsKillingTheProcessFailsAfterMaxAttempts) {
  const std::string path = Path("jobs.db");
  SqliteJobStoreOptions options;
  options.max_attempts = 2;
  std::string poison, follower;
  for (int restart = 0; restart < 3; ++restart) {
    std::unique_ptr<JobStore> store = OpenOrDie(path, options);
    ASSERT_NE(store, nullptr);
    StatusOr<RecoveryReport> report = store->RecoverAfterRestart();
    ASSERT_TRUE(report.ok());
    if (restart == 0) {
      poison = Must(store->Submit({"trace", "poison", "P", ""})).id;
      follower = Must(store->Submit({"trace", "poison", "P", ""})).id;
    } else if (restart == 1) {
      EXPECT_EQ(report->requeued, 1);
    } else {
      EXPECT_EQ(report->failed, 1);
      break;
    }
    ASSERT_EQ(ClaimedId(*store, "w"), poison);  // ... and the process dies.
  }
  std::unique_ptr<JobStore> store = OpenOrDie(path, options);
  for (const std::string& id : {poison, follower}) {
    JobRecord job = Must(store->Get(id));
    EXPECT_EQ(job.state, JobState::kFailed);
    EXPECT_EQ(job.error_code, StatusCode::kInternal);
    EXPECT_THAT(job.error_message, HasSubstr("2 times"));
  }
}

// The result a worker stores for a request: tagged with who computed it, so that a job
// completed by one process and then again by another would show.
std::string ResultFor(const std::string& who, const std::string& request) {
  return who + ":" + request;
}

// A child process opens the store, claims one job and keeps it running, then claims and
// completes the others one by one, logging each completion after its commit; the parent kills it
// with SIGKILL at an arbitrary moment. Afterwards no logged result may be missing or changed,
// and after recovery every job completes exactly once.
TEST_F(SqliteJobStoreTest, Kill9LosesNoFinishedResultAndCompletesNothingTwice) {
  const std::string path = Path("jobs.db");
  const std::string log_path = Path("completed.log");
  constexpr int kJobs = 60;
  std::map<std::string, std::string> request_of;  // id -> request
  {
    std::unique_ptr<JobStore> store = OpenOrDie(path);
    ASSERT_NE(store, nullptr);
    for (int i = 0; i < kJobs; ++i) {
      const std::string request = std::string("request-") + std::to_string(i);
      StatusOr<SubmitResult> r = store->Submit({"simulate", request, "key-" + request, ""});
      ASSERT_TRUE(r.ok());
      request_of[r->id] = request;
    }
  }  // Closed: the child must not inherit an open connection.

  const pid_t child = fork();
  ASSERT_NE(child, -1);
  if (child == 0) {
    // Child: no gtest here, report through the exit code (the parent expects SIGKILL instead).
    StatusOr<std::unique_ptr<JobStore>> opened = SqliteJobStore::Open(path);
    if (!opened.ok()) _exit(2);
    JobStore& store = **opened;
    const int log = open(log_path.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    if (log < 0) _exit(3);
    StatusOr<std::optional<JobRecord>> held = store.ClaimNext("child-held");
    if (!held.ok() || !held->has_value()) _exit(4);
    for (int completed = 0;; ++completed) {
      StatusOr<std::optional<JobRecord>> job = store.ClaimNext("child");
      if (!job.ok()) _exit(5);
      if (!job->has_value()) _exit(6);  // Ran out of jobs: the parent did not kill in time.
      const JobRecord& record = **job;
      if (!store.UpdateProgress(record.id, 0.5, std::nullopt, 1).ok()) _exit(7);
      // "Computing": most kills land while a job is RUNNING. Once the parent may kill (15 jobs
      // done), 20 ms per job: the remaining 44 jobs then take at least 0.88 s, time enough for a
      // parent descheduled on a loaded machine to see the count and kill before the child runs
      // out of jobs.
      usleep(completed < 15 ? 1000 : 20000);
      if (!store.Complete(record.id, ResultFor("child", record.request), 1).ok()) _exit(8);
      const std::string line = record.id + "\n";
      if (write(log, line.data(), line.size()) != static_cast<ssize_t>(line.size())) _exit(9);
    }
  }

  // Parent: watch through its own connection until the child has done a fair share, then kill.
  std::unique_ptr<JobStore> watcher = OpenOrDie(path);
  ASSERT_NE(watcher, nullptr);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(20);
  int64_t succeeded = 0;
  while (std::chrono::steady_clock::now() < deadline) {
    StatusOr<StoreStats> stats = watcher->Stats();
    ASSERT_TRUE(stats.ok()) << stats.status().ToString();
    succeeded = stats->jobs_by_state[static_cast<int>(JobState::kSucceeded)];
    if (succeeded >= 15) break;
    usleep(500);
  }
  ASSERT_EQ(kill(child, SIGKILL), 0);
  int wait_status = 0;
  ASSERT_EQ(waitpid(child, &wait_status, 0), child);
  ASSERT_TRUE(WIFSIGNALED(wait_status))
      << "the child exited by itself with code " << WEXITSTATUS(wait_status);
  ASSERT_EQ(WTERMSIG(wait_status), SIGKILL);
  ASSERT_GE(succeeded, 15) << "the child was too slow";
  watcher.reset();

  // Every completion the child logged (after its commit) is in the file, with its result.
  std::vector<std::string> logged;
  {
    std::ifstream log(log_path);
    for (std::string id; std::getline(log, id);) logged.push_back(id);
  }
  const std::set<std::string> logged_set(logged.begin(), logged.end());
  EXPECT_EQ(logged_set.size(), logged.size()) << "a job was logged as completed twice";

  // Restart.
  std::unique_ptr<JobStore> store = OpenOrDie(path);
  ASSERT_NE(store, nullptr);
  int running_before = 0;
  int succeeded_before = 0;
  for (const auto& [id, request] : request_of) {
    const JobRecord job = Must(store->Get(id));
    running_before += job.state == JobState::kRunning;
    succeeded_before += job.state == JobState::kSucceeded;
    if (logged_set.count(id)) {
      EXPECT_EQ(job.state, JobState::kSucceeded) << id;
      EXPECT_EQ(Must(store->GetResult(id)), ResultFor("child", request)) << id;
    }
  }
  // The held job, and maybe the one being computed; at most one commit may be unlogged.
  EXPECT_GE(running_before, 1);
  EXPECT_LE(running_before, 2);
  EXPECT_GE(succeeded_before, static_cast<int>(logged.size()));
  EXPECT_LE(succeeded_before, static_cast<int>(logged.size()) + 1);

  StatusOr<RecoveryReport> report = store->RecoverAfterRestart();
  ASSERT_TRUE(report.ok()) << report.status().ToString();
  EXPECT_EQ(report->requeued, running_before);

  // The restarted worker finishes the rest; finished jobs cannot be completed again.
  int parent_completed = 0;
  for (;;) {
    StatusOr<std::optional<JobRecord>> job = store->ClaimNext("parent");
    ASSERT_TRUE(job.ok());
    if (!job->has_value()) break;
    ASSERT_TRUE(store->Complete((*job)->id, ResultFor("parent", (*job)->request), 1).ok());
    ++parent_completed;
  }
  EXPECT_EQ(succeeded_before + parent_completed, kJobs);
  for (const auto& [id, request] : request_of) {
    EXPECT_EQ(Must(store->Get(id)).state, JobState::kSucceeded) << id;
    const std::string result = Must(store->GetResult(id));
    if (logged_set.count(id)) {
      EXPECT_EQ(result, ResultFor("child", request)) << id;
    }
    EXPECT_TRUE(result == ResultFor("child", request) || result == ResultFor("parent", request))
        << id << ": " << result;
    EXPECT_EQ(store->Complete(id, "again", 1).code(), StatusCode::kFailedPrecondition);
  }
}

// Four workers on two store objects (two SQLite connections, so BEGIN IMMEDIATE and the busy
// timeout arbitrate between them, and each store's mutex between its two threads) drain 200
// jobs: each is claimed once and completed once.
TEST_F(SqliteJobStoreTest, ConcurrentWorkersCompleteEveryJobExactlyOnce) {
  const std::string path = Path("jobs.db");
  constexpr int kJobs = 200;
  std::unique_ptr<JobStore> first = OpenOrDie(path);
  std::unique_ptr<JobStore> second = OpenOrDie(path);
  ASSERT_NE(first, nullptr);
  ASSERT_NE(second, nullptr);
  std::set<std::string> submitted;
  for (int i = 0; i < kJobs; ++i) {
    submitted.insert(Must(first->Submit({"simulate", std::to_string(i), "", ""})).id);
  }
  ASSERT_EQ(submitted.size(), static_cast<size_t>(kJobs));

  struct Worker {
    std::vector<std::string> completed;
    int errors = 0;
  };
  std::vector<Worker> workers(4);
  std::latch start(4);
  std::vector<std::thread> threads;
  for (int w = 0; w < 4; ++w) {
    threads.emplace_back([&, w] {
      JobStore& store = w % 2 == 0 ? *first : *second;
      Worker& me = workers[w];
      const std::string name = std::string("worker-") + std::to_string(w);
      start.arrive_and_wait();
      for (;;) {
        StatusOr<std::optional<JobRecord>> job = store.ClaimNext(name);
        if (!job.ok()) {
          ++me.errors;
          return;
        }
        if (!job->has_value()) return;
        // "Computing" outside the store, as a real worker does: lets the others claim.
        std::this_thread::sleep_for(std::chrono::microseconds(200));
        if (!store.Complete((*job)->id, ResultFor(name, (*job)->request), 0).ok()) ++me.errors;
        me.completed.push_back((*job)->id);
      }
    });
  }
  for (std::thread& t : threads) t.join();

  std::multiset<std::string> completed;
  for (const Worker& worker : workers) {
    EXPECT_EQ(worker.errors, 0);
    completed.insert(worker.completed.begin(), worker.completed.end());
  }
  EXPECT_EQ(completed.size(), static_cast<size_t>(kJobs));
  EXPECT_EQ(std::set<std::string>(completed.begin(), completed.end()), submitted);
  for (const std::string& id : submitted) {
    const JobRecord job = Must(first->Get(id));
    EXPECT_EQ(job.state, JobState::kSucceeded);
    EXPECT_EQ(job.attempts, 1) << id << " was claimed twice";
    EXPECT_EQ(Must(first->GetResult(id)), ResultFor(job.worker_id, job.request));
  }
  // The claims did interleave (at least both threads of one store; SQLite's busy handler backs
  // off, so the other connection may get few or none: docs/store.md, fairness).
  int busy_workers = 0;
  for (const Worker& worker : workers) busy_workers += !worker.completed.empty();
  EXPECT_GE(busy_workers, 2);
}

}  // namespace
}  // namespace drillbif::server
