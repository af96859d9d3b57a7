// The SQLite JobStore's maintenance: health and probe, the integrity check at open, deletion and
// retention (docs/store.md, faults and retention).
#include <sqlite3.h>
#include <sys/statvfs.h>

#include <cstdint>
#include <filesystem>
#include <limits>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

#include "drillbif/common/checked.h"
#include "server/store/sqlite_connection.h"
#include "server/store/sqlite_store_impl.h"

namespace drillbif::server {
namespace {

using sqlite::Query;
using sqlite::Transaction;

// An eviction transaction deletes at most kEvictBatch jobs and stops once it freed
// kEvictTransactionBytes: the store's lock is released between transactions, so that workers
// and clients wait at most about one transaction (docs/store.md has the measured figures), and
// each transaction's WAL stays small.
constexpr int kEvictBatch = 256;

// A finished job to delete, with its result's key (the result goes with its last job).
struct Evictable {
  std::string id;
  std::string result_key;
};
constexpr int64_t kEvictTransactionBytes = 4 << 20;
// Pages PRAGMA incremental_vacuum frees per step (4 MiB at 4 KiB pages): a step moves at most
// that many pages, bounding both the lock hold and the WAL it writes before the checkpoint that
// follows.
constexpr int kVacuumStepPages = 1024;

Status DataLoss(std::string message) { return Status(StatusCode::kDataLoss, std::move(message)); }

// "; "-joined lines: quick_check reports a problem over several lines.
std::string OneLine(const std::string& text) {
  std::string line;
  for (const char c : text) {
    if (c == '\n') {
      line += "; ";
    } else {
      line += c;
    }
  }
  return line;
}

// The first problem `PRAGMA quick_check(1)` finds through `connection`, or OK. A file too
// damaged to run the check at all (no schema, not a database) reports SQLite's name for the
// error as its problem.
Status QuickCheck(sqlite::Connection& connection) {
  const auto check_failed = [&](const Status& status) {
    if (status.code() != StatusCode::kDataLoss) return status;
    return DataLoss(std::string("the job store failed its integrity check: ") +
                    sqlite3_errstr(sqlite3_extended_errcode(connection.db())));
  };
  StatusOr<Query> q = connection.Prepare("PRAGMA quick_check(1)");
  if (!q.ok()) return check_failed(q.status());
  StatusOr<bool> row = q->Step();
  if (!row.ok()) return check_failed(row.status());
  const std::string verdict = *row ? q->Text(0) : std::string("no answer");
  if (verdict != "ok") {
    return DataLoss("the job store failed its integrity check: " + OneLine(verdict));
  }
  return Status::Ok();
}

}  // namespace

Status CheckIntegrity(const std::string& path, const sqlite::LogFunction& log) {
  std::error_code error;
  const auto size = std::filesystem::file_size(path, error);
  if (error || size == 0) return Status::Ok();  // Nothing to check yet (Open creates it).
  sqlite3* db = nullptr;
  const int rc =
      sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READONLY | SQLITE_OPEN_NOMUTEX, nullptr);
  sqlite::Connection connection(db, log);  // Closes the handle, also after a failed open.
  if (rc != SQLITE_OK) return connection.Error(rc, "open read-only for the integrity check");
  sqlite3_extended_result_codes(db, 1);
  Status status = QuickCheck(connection);
  if (!status.ok()) connection.Log("job store: " + status.message() + " ('" + path + "')");
  return status;
}

Status SqliteStoreImpl::Health() { return connection_.Fault(); }

Status SqliteStoreImpl::Probe() {
  if (connection_.Fault().code() == StatusCode::kResourceExhausted) {
    // A full disk: first give back what deletions freed since (a failed job's partial result).
    // Its pages are free in the file but still on the disk, and the WAL still holds them until a
    // checkpoint, which cannot grow the file; the vacuum shortens the file first.
    if (Status freed = FreeSpace(); !freed.ok()) {
      std::lock_guard<std::mutex> lock(mu_);
      connection_.Log("job store: probe could not give freed space back: " + freed.ToString());
    }
  }
  std::lock_guard<std::mutex> lock(mu_);
  const Status fault = connection_.Fault();
  if (fault.code() == StatusCode::kResourceExhausted &&
      fault.message() == "the job store's disk is full" && options_.min_free_bytes_after_full > 0) {
    const int64_t free_bytes = FreeDiskBytes();
    if (free_bytes >= 0 && free_bytes < options_.min_free_bytes_after_full) {
      connection_.Log("job store: probe: " + std::to_string(free_bytes) +
                      " bytes free on the store's disk, below " +
                      std::to_string(options_.min_free_bytes_after_full));
      return fault;
    }
  }
  {
    // A write that changes a page (a no-op UPDATE would commit nothing).
    DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("INSERT INTO counters (name, value) VALUES ('probes', 1) "
                                     "ON CONFLICT (name) DO UPDATE SET value = value + 1"));
    DRILLBIF_RETURN_IF_ERROR(q.Run());
    DRILLBIF_RETURN_IF_ERROR(tx.Commit());
  }
  if (fault.code() == StatusCode::kDataLoss) {
    // Corruption does not heal: only a whole check clears it.
    DRILLBIF_RETURN_IF_ERROR(QuickCheck(connection_));
  } else {
    DRILLBIF_ASSIGN_OR_RETURN(Query q,
                              connection_.Prepare("SELECT COUNT(*) FROM jobs WHERE state = 1"));
    DRILLBIF_RETURN_IF_ERROR(q.Run());
  }
  if (!fault.ok())
    connection_.Log("job store: probe succeeded, fault cleared: " + fault.ToString());
  connection_.ClearFault();
  return Status::Ok();
}

StatusOr<bool> SqliteStoreImpl::DeleteJobAndOrphanResult(std::string_view id,
                                                         const std::string& result_key) {
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare("DELETE FROM jobs WHERE id = ?1"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, id).Run());
  }
  // The result goes with its last job (a cached result serves later requests only while some
  // job holds it), and its chunks with it.
  std::string run_id;
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT run_id FROM results WHERE result_key = ?1 AND NOT "
                                     "EXISTS (SELECT 1 FROM jobs WHERE result_key = ?1)"));
    q.Bind(1, result_key);
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (!row) return false;
    run_id = q.Text(0);
  }
  if (!run_id.empty()) {
    DRILLBIF_ASSIGN_OR_RETURN(Query q,
                              connection_.Prepare("DELETE FROM result_chunks WHERE run_id = ?1"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, run_id).Run());
  }
  DRILLBIF_ASSIGN_OR_RETURN(Query q,
                            connection_.Prepare("DELETE FROM results WHERE result_key = ?1"));
  DRILLBIF_RETURN_IF_ERROR(q.Bind(1, result_key).Run());
  return true;
}

Status SqliteStoreImpl::Delete(std::string_view id) {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_ASSIGN_OR_RETURN(JobHead head, Head(id));
  const auto state = static_cast<JobState>(head.state);
  if (!IsFinished(state)) {
    return NotFinished(id, state);
  }
  DRILLBIF_RETURN_IF_ERROR(DeleteJobAndOrphanResult(id, head.result_key).status());
  // Its finished children go with it; any still stopping after its cancel are left to Evict,
  // which takes them once they finish (their parent is gone).
  std::vector<Evictable> children;
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT id, result_key FROM jobs INDEXED BY jobs_by_parent "
                                     "WHERE parent_id = ?1 AND parent_id <> '' "
                                     "AND state IN (2, 3, 4)"));
    q.Bind(1, id);
    for (;;) {
      DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
      if (!row) break;
      children.push_back({q.Text(0), q.Text(1)});
    }
  }
  for (const Evictable& child : children) {
    DRILLBIF_RETURN_IF_ERROR(DeleteJobAndOrphanResult(child.id, child.result_key).status());
  }
  return tx.Commit();
}

StatusOr<int64_t> SqliteStoreImpl::UsedBytes() {
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare("SELECT (SELECT page_count FROM pragma_page_count()) - "
                                   "(SELECT freelist_count FROM pragma_freelist_count()), "
                                   "(SELECT page_size FROM pragma_page_size())"));
  DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
  if (!row) return int64_t{0};
  const std::optional<int64_t> bytes = CheckedMul(q.Int(0), q.Int(1));
  if (!bytes) return Internal("job store size beyond 2^63 - 1 bytes");
  return *bytes;
}

int64_t SqliteStoreImpl::FreeDiskBytes() const {
  const std::filesystem::path dir = std::filesystem::absolute(path_).parent_path();
  struct statvfs fs;
  if (statvfs(dir.c_str(), &fs) != 0) return -1;
  return static_cast<int64_t>(fs.f_bavail) * static_cast<int64_t>(fs.f_frsize);
}

int64_t SqliteStoreImpl::DiskBytes() const {
  int64_t total = 0;
  for (const std::string& file : {path_, path_ + "-wal"}) {
    std::error_code error;
    const auto size = std::filesystem::file_size(file, error);
    if (!error) total = CheckedAdd(total, static_cast<int64_t>(size)).value_or(total);
  }
  return total;
}

namespace {

// The oldest finished jobs (by finished_ms, then submission) that no QUEUED or RUNNING job
// follows and whose parent (if any) is not QUEUED or RUNNING (it may still read their results),
// finished before ?1, at most ?2 of them.
constexpr const char* kEvictableJobs =
    "SELECT id, result_key FROM jobs j INDEXED BY jobs_finished WHERE state IN (2, 3, 4) AND "
    "finished_ms < ?1 "
    "AND NOT EXISTS (SELECT 1 FROM jobs f WHERE f.shares = j.id AND f.state IN (0, 1)) "
    "AND NOT EXISTS (SELECT 1 FROM jobs p WHERE p.id = j.parent_id AND p.state IN (0, 1)) "
    "ORDER BY finished_ms, seq LIMIT ?2";

StatusOr<std::vector<Evictable>> SelectEvictable(sqlite::Connection& connection,
                                                 int64_t finished_before) {
  DRILLBIF_ASSIGN_OR_RETURN(Query q, connection.Prepare(kEvictableJobs));
  q.Bind(1, finished_before).Bind(2, kEvictBatch);
  std::vector<Evictable> jobs;
  for (;;) {
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (!row) break;
    jobs.push_back({q.Text(0), q.Text(1)});
  }
  return jobs;
}

}  // namespace

Status SqliteStoreImpl::EvictOldest(int64_t finished_before, int64_t max_used_bytes,
                                    EvictionReport* report) {
  for (;;) {
    std::lock_guard<std::mutex> lock(mu_);
    DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
    DRILLBIF_ASSIGN_OR_RETURN(const int64_t used_at_start, UsedBytes());
    if (max_used_bytes > 0 && used_at_start <= max_used_bytes) return Status::Ok();
    DRILLBIF_ASSIGN_OR_RETURN(std::vector<Evictable> batch,
                              SelectEvictable(connection_, finished_before));
    if (batch.empty()) return Status::Ok();  // Nothing (more) that may go.
    // One job at a time, measuring after each: stop as soon as the data fits, or when this
    // transaction has freed enough to let others in.
    int64_t jobs = 0;
    int64_t results = 0;
    bool fits = false;
    for (const Evictable& job : batch) {
      DRILLBIF_ASSIGN_OR_RETURN(bool result_deleted,
                                DeleteJobAndOrphanResult(job.id, job.result_key));
      ++jobs;
      results += result_deleted;
      DRILLBIF_ASSIGN_OR_RETURN(const int64_t used, UsedBytes());
      fits = max_used_bytes > 0 && used <= max_used_bytes;
      if (fits || used_at_start - used >= kEvictTransactionBytes) break;
    }
    DRILLBIF_RETURN_IF_ERROR(tx.Commit());
    report->jobs_deleted += jobs;
    report->results_deleted += results;
    if (fits) return Status::Ok();
  }
}

Status SqliteStoreImpl::FreeSpace() {
  int64_t auto_vacuum = 0;
  {
    std::lock_guard<std::mutex> lock(mu_);
    DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare("PRAGMA auto_vacuum"));
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (row) auto_vacuum = q.Int(0);
  }
  // 2 = INCREMENTAL (files created by this schema version): move pages from the end of the file
  // into free ones, a bounded step at a time, checkpointing between steps so the WAL stays
  // small; the checkpoint then shortens the file.
  while (auto_vacuum == 2) {
    std::lock_guard<std::mutex> lock(mu_);
    int64_t free_pages = 0;
    {
      // Scoped: a statement still open on the connection keeps the checkpoints below from
      // running (SQLITE_LOCKED).
      DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare("PRAGMA freelist_count"));
      DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
      if (row) free_pages = q.Int(0);
    }
    if (free_pages == 0) break;
    const std::string step = "PRAGMA incremental_vacuum(" + std::to_string(kVacuumStepPages) + ")";
    Status vacuumed = connection_.Exec(step.c_str());
    connection_.CheckpointIfRequested();
    DRILLBIF_RETURN_IF_ERROR(vacuumed);
    // PASSIVE: never waits for readers; the next step's writes reuse the WAL from its start.
    connection_.Checkpoint("PASSIVE").IgnoreError();
  }
  std::lock_guard<std::mutex> lock(mu_);
  return connection_.Checkpoint("TRUNCATE");
}

StatusOr<EvictionReport> SqliteStoreImpl::Evict(const RetentionOptions& options, int64_t now_ms) {
  DRILLBIF_RETURN_IF_ERROR(options.Validate());
  EvictionReport report;
  {
    std::lock_guard<std::mutex> lock(mu_);
    DRILLBIF_ASSIGN_OR_RETURN(report.used_bytes_before, UsedBytes());
  }
  report.disk_bytes_before = DiskBytes();
  if (options.max_age_ms > 0) {
    // now_ms - max_age_ms; a cutoff below INT64_MIN means nothing is that old.
    const std::optional<int64_t> cutoff = CheckedAdd(now_ms, -options.max_age_ms);
    if (cutoff) DRILLBIF_RETURN_IF_ERROR(EvictOldest(*cutoff, /*max_used_bytes=*/0, &report));
  }
  if (options.max_db_bytes > 0)
    DRILLBIF_RETURN_IF_ERROR(
        EvictOldest(std::numeric_limits<int64_t>::max(), options.max_db_bytes, &report));
  // The deletions are committed whatever happens here: freeing disk space is best effort (a
  // checkpoint waits for readers of other connections; a vacuum step may find the disk full).
  if (Status s = FreeSpace(); !s.ok()) {
    std::lock_guard<std::mutex> lock(mu_);
    connection_.Log("job store: eviction could not give all freed space back: " + s.ToString());
  }
  {
    std::lock_guard<std::mutex> lock(mu_);
    DRILLBIF_ASSIGN_OR_RETURN(report.used_bytes_after, UsedBytes());
  }
  report.disk_bytes_after = DiskBytes();
  report.size_limit_met =
      options.max_db_bytes == 0 || report.used_bytes_after <= options.max_db_bytes;
  return report;
}

}  // namespace drillbif::server
