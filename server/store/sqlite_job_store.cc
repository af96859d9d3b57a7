// The SQLite JobStore: opening and migrations, the job life cycle, listing and stats. Results
// are in sqlite_store_results.cc, health and retention in sqlite_store_maintenance.cc. Schema
// and semantics: docs/store.md.
#include "server/store/sqlite_job_store.h"

#include <sqlite3.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <iterator>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "drillbif/common/checked.h"
#include "server/store/sqlite_connection.h"
#include "server/store/sqlite_store_impl.h"

namespace drillbif::server {
namespace {

using sqlite::Query;
using sqlite::Transaction;

// ---------------------------------------------------------------------------------------------
// Schema migrations, in order. Migration i brings the file from user_version i to i + 1; Open
// applies the missing ones in one transaction. Never edit a migration once released: append one.
//
// jobs.seq orders jobs (FIFO claims, List pages) and is never shown to users; AUTOINCREMENT so
// that a seq is never reused after the newest job is deleted (a page token stays meaningful).
// jobs.result_key names the results row holding the job's result: "c:" + cache_key for cached
// jobs (content-addressed: identical requests share one row), "j:" + id otherwise.
// jobs.shares is the job this one follows (runs for it); SET NULL when that job is deleted,
// which only happens once both are finished.
constexpr const char* kMigrations[] = {
    // 0 -> 1: jobs, results, counters.
    R"sql(
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
)sql",
    // 1 -> 2: clients and lanes, run fencing, streamed result chunks, retention.
    //
    // jobs.client / jobs.lane: who submitted and the cost lane (fair claims, queue limits).
    // jobs.run: claims ever made (never decremented, unlike attempts): fences stale workers.
    // jobs.streamed_items / streamed_bytes: what the current run appended so far.
    // result_chunks: the chunks of a run, keyed by the id of the job that ran (run_id), in
    // streams (one per repeated field of the result, numbered by the caller). They
    // are never moved: Complete points results.run_id at them, so completing a large result
    // rewrites no chunk, and two runs of one cache key (the rare double completion) cannot mix.
    // results.items / bytes: totals (GetResultInfo without reading the chunks). Existing results
    // hold their whole message in data, with no chunks.
    // Indexes: claimable jobs by client (fair claims, queue limits), running jobs by client,
    // finished jobs by age (eviction), chunks by (run_id, stream, first_item) (page reads).
    R"sql(
ALTER TABLE jobs ADD COLUMN client TEXT NOT NULL DEFAULT '';
ALTER TABLE jobs ADD COLUMN lane INTEGER NOT NULL DEFAULT 0 CHECK (lane >= 0);
ALTER TABLE jobs ADD COLUMN run INTEGER NOT NULL DEFAULT 0;
ALTER TABLE jobs ADD COLUMN streamed_items INTEGER NOT NULL DEFAULT 0;
ALTER TABLE jobs ADD COLUMN streamed_bytes INTEGER NOT NULL DEFAULT 0;
UPDATE jobs SET run = attempts;
CREATE INDEX jobs_claimable ON jobs(client, lane, seq) WHERE state = 0 AND shares IS NULL;
CREATE INDEX jobs_running ON jobs(client, lane) WHERE state = 1 AND shares IS NULL;
CREATE INDEX jobs_finished ON jobs(finished_ms, seq) WHERE state IN (2, 3, 4);
ALTER TABLE results ADD COLUMN run_id TEXT NOT NULL DEFAULT '';
ALTER TABLE results ADD COLUMN items INTEGER NOT NULL DEFAULT 0;
ALTER TABLE results ADD COLUMN bytes INTEGER NOT NULL DEFAULT 0;
UPDATE results SET bytes = length(data);
CREATE TABLE result_chunks (
  run_id TEXT NOT NULL,
  stream INTEGER NOT NULL CHECK (stream >= 0),
  first_item INTEGER NOT NULL CHECK (first_item >= 0),
  item_count INTEGER NOT NULL CHECK (item_count >= 1),
  data BLOB NOT NULL
);
CREATE UNIQUE INDEX result_chunks_by_run ON result_chunks(run_id, stream, first_item);
INSERT INTO counters(name, value) VALUES ('probes', 0);
)sql",
    // 2 -> 3: leases. jobs.lease_expires_ms: when the current run's lease expires (0: no lease);
    // the index finds the expired ones among the running jobs.
    R"sql(
ALTER TABLE jobs ADD COLUMN lease_expires_ms INTEGER NOT NULL DEFAULT 0;
CREATE INDEX jobs_leased ON jobs(lease_expires_ms) WHERE state = 1 AND lease_expires_ms > 0;
)sql",
    // 3 -> 4: child jobs. jobs.parent_id: the job that submitted this one as its task ('' for a
    // top-level job; existing jobs are top-level). jobs_claimable is rebuilt for top-level jobs
    // only (fair claims and queue limits are about top-level jobs; children are claimed through
    // their own indexes). jobs_by_parent finds one parent's children by state (its claims, the
    // cascade when it leaves RUNNING, Delete, List); jobs_queued_children walks the queued
    // children oldest first (claims prefer children of running parents; queue depth).
    R"sql(
ALTER TABLE jobs ADD COLUMN parent_id TEXT NOT NULL DEFAULT '';
DROP INDEX jobs_claimable;
CREATE INDEX jobs_claimable ON jobs(client, lane, seq)
  WHERE state = 0 AND shares IS NULL AND parent_id = '';
CREATE INDEX jobs_by_parent ON jobs(parent_id, state, seq) WHERE parent_id <> '';
CREATE INDEX jobs_queued_children ON jobs(seq) WHERE state = 0 AND parent_id <> '';
)sql",
};
static_assert(std::size(kMigrations) == SqliteJobStore::kSchemaVersion,
              "one migration per schema version");

// Columns of a JobRecord, in the order ReadJob expects; %s is the request expression.
constexpr const char* kJobColumns =
    "seq, id, kind, state, %s, cache_key, request_id, shares, progress, current_value, points, "
    "error_code, error_message, created_ms, started_ms, finished_ms, cache_hit, attempts, "
    "cancel_requested, worker_id, client, lane, run, lease_expires_ms, parent_id";

std::string SelectJobs(const char* request_expression, const char* rest) {
  char columns[512];
  std::snprintf(columns, sizeof(columns), kJobColumns, request_expression);
  return std::string("SELECT ") + columns + " FROM jobs " + rest;
}

JobRecord ReadJob(const Query& q) {
  JobRecord job;
  job.id = q.Text(1);
  job.kind = q.Text(2);
  job.state = static_cast<JobState>(q.Int(3));
  job.request = q.Blob(4);
  job.cache_key = q.Text(5);
  job.request_id = q.Text(6);
  job.shared_with = q.Text(7);
  job.progress = q.Double(8);
  if (!q.IsNull(9)) job.current_value = q.Double(9);
  job.points = q.Int(10);
  job.error_code = static_cast<StatusCode>(q.Int(11));
  job.error_message = q.Text(12);
  job.created_ms = q.Int(13);
  job.started_ms = q.Int(14);
  job.finished_ms = q.Int(15);
  job.cache_hit = q.Int(16) != 0;
  job.attempts = static_cast<int>(q.Int(17));
  job.cancel_requested = q.Int(18) != 0;
  job.worker_id = q.Text(19);
  job.client = q.Text(20);
  job.lane = static_cast<int>(q.Int(21));
  job.run = q.Int(22);
  job.lease_expires_ms = q.Int(23);
  job.parent = q.Text(24);
  return job;
}

// Applies the migrations from `version` to kSchemaVersion and sets the ids, in one transaction
// (re-checking the version inside it: another process may have migrated meanwhile).
Status Migrate(sqlite::Connection& connection) {
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection, /*write=*/true));
  int64_t application_id = 0;
  int64_t version = 0;
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q, connection.Prepare("PRAGMA application_id"));
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (row) application_id = q.Int(0);
  }
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q, connection.Prepare("PRAGMA user_version"));
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (row) version = q.Int(0);
  }
  if (application_id != 0 && application_id != SqliteJobStore::kApplicationId) {
    return FailedPrecondition("not a drillbif job store (SQLite application_id " +
                              std::to_string(application_id) + ")");
  }
  if (version > SqliteJobStore::kSchemaVersion) {
    return FailedPrecondition("job store schema version " + std::to_string(version) +
                              " is newer than this build supports (" +
                              std::to_string(SqliteJobStore::kSchemaVersion) +
                              "); use a newer drillbif-server");
  }
  if (version < 0) {
    return FailedPrecondition("job store schema version " + std::to_string(version) +
                              " is invalid");
  }
  for (int64_t v = version; v < SqliteJobStore::kSchemaVersion; ++v) {
    Status status = connection.Exec(kMigrations[v]);
    if (!status.ok()) {
      return Status(status.code(), "migrating the job store from schema version " +
                                       std::to_string(v) + ": " + status.message());
    }
  }
  // Pragmas take no parameters; both values are integers formatted here.
  const std::string set_ids =
      "PRAGMA application_id = " + std::to_string(SqliteJobStore::kApplicationId) +
      "; PRAGMA user_version = " + std::to_string(SqliteJobStore::kSchemaVersion);
  DRILLBIF_RETURN_IF_ERROR(connection.Exec(set_ids.c_str()));
  return tx.Commit();
}

// The first integer of `sql`'s first row (0 when no row).
StatusOr<int64_t> QueryInt(sqlite::Connection& connection, const char* sql) {
  DRILLBIF_ASSIGN_OR_RETURN(Query q, connection.Prepare(sql));
  DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
  return row ? q.Int(0) : int64_t{0};
}

}  // namespace

Status SqliteStoreImpl::Configure() {
  sqlite3_extended_result_codes(connection_.db(), 1);
  sqlite3_busy_timeout(connection_.db(), options_.busy_timeout_ms);
  max_value_bytes_ = sqlite3_limit(connection_.db(), SQLITE_LIMIT_LENGTH, -1);
  // Refuse another program's file, or a newer schema, before changing anything (Migrate checks
  // again inside its transaction).
  DRILLBIF_ASSIGN_OR_RETURN(const int64_t application_id,
                            QueryInt(connection_, "PRAGMA application_id"));
  DRILLBIF_ASSIGN_OR_RETURN(const int64_t version, QueryInt(connection_, "PRAGMA user_version"));
  if (application_id != 0 && application_id != SqliteJobStore::kApplicationId) {
    return FailedPrecondition("not a drillbif job store (SQLite application_id " +
                              std::to_string(application_id) + ")");
  }
  if (version > SqliteJobStore::kSchemaVersion) {
    return FailedPrecondition("job store schema version " + std::to_string(version) +
                              " is newer than this build supports (" +
                              std::to_string(SqliteJobStore::kSchemaVersion) +
                              "); use a newer drillbif-server");
  }
  // auto_vacuum can only be chosen before the first table: new files get INCREMENTAL, so Evict
  // can give freed pages back to the disk (PRAGMA incremental_vacuum). Older files keep NONE:
  // freed pages are reused, the file does not shrink (docs/store.md).
  DRILLBIF_ASSIGN_OR_RETURN(const int64_t tables,
                            QueryInt(connection_, "SELECT COUNT(*) FROM sqlite_master"));
  if (tables == 0) {
    DRILLBIF_RETURN_IF_ERROR(connection_.Exec("PRAGMA auto_vacuum = INCREMENTAL"));
  }
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare("PRAGMA journal_mode = WAL"));
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    const std::string mode = row ? q.Text(0) : std::string();
    if (mode != "wal") {
      return FailedPrecondition("cannot use WAL journal mode (got '" + mode + "')");
    }
  }
  DRILLBIF_RETURN_IF_ERROR(connection_.Exec(options_.full_sync ? "PRAGMA synchronous = FULL"
                                                               : "PRAGMA synchronous = NORMAL"));
  DRILLBIF_RETURN_IF_ERROR(connection_.Exec("PRAGMA foreign_keys = ON"));
  // Freed pages are not overwritten with zeros. Debian's SQLite is built with SECURE_DELETE,
  // which zeroes every page a DELETE frees: dropping a result then writes as much to the WAL as
  // the result took, so on a full disk a failed job's partial result could not be dropped, nor
  // the job be marked FAILED in the same transaction (it stayed RUNNING). FAST zeroes only what
  // costs no extra write; results are computed data, not secrets.
  DRILLBIF_RETURN_IF_ERROR(connection_.Exec("PRAGMA secure_delete = FAST"));
  const std::string size_limit =
      "PRAGMA journal_size_limit = " + std::to_string(options_.wal_size_limit_bytes);
  DRILLBIF_RETURN_IF_ERROR(connection_.Exec(size_limit.c_str()));
  return Migrate(connection_);
}

StatusOr<JobHead> SqliteStoreImpl::Head(std::string_view id) {
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare("SELECT state, shares IS NOT NULL, cancel_requested, attempts, "
                                   "result_key, run, streamed_items, streamed_bytes "
                                   "FROM jobs WHERE id = ?1"));
  q.Bind(1, id);
  DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
  if (!row) return NoJob(id);
  JobHead head;
  head.state = static_cast<int>(q.Int(0));
  head.shares = q.Int(1) != 0;
  head.cancel_requested = q.Int(2) != 0;
  head.attempts = static_cast<int>(q.Int(3));
  head.result_key = q.Text(4);
  head.run = q.Int(5);
  head.streamed_items = q.Int(6);
  head.streamed_bytes = q.Int(7);
  return head;
}

StatusOr<JobHead> SqliteStoreImpl::RunningHead(std::string_view id, const char* action,
                                               int64_t run) {
  DRILLBIF_ASSIGN_OR_RETURN(JobHead head, Head(id));
  DRILLBIF_RETURN_IF_ERROR(CheckRunning(id, action, run, head));
  return head;
}

Status SqliteStoreImpl::UpdateRunning(const std::string& update, std::string_view id,
                                      const std::function<void(Query&)>& bind) {
  DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare(update));
  q.Bind(1, id);
  bind(q);
  DRILLBIF_RETURN_IF_ERROR(q.Run());
  if (connection_.Changes() != 1) {
    return FailedPrecondition("job '" + std::string(id) + "' is no longer RUNNING");
  }
  return Status::Ok();
}

Status SqliteStoreImpl::PromoteFollower(std::string_view id) {
  std::string next;
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT id FROM jobs WHERE shares = ?1 AND state IN (0, 1) "
                                     "ORDER BY seq LIMIT 1"));
    q.Bind(1, id);
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (!row) return Status::Ok();
    next = q.Text(0);
  }
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("UPDATE jobs SET shares = NULL, state = 0, started_ms = 0, "
                                     "progress = 0, current_value = NULL, points = 0 "
                                     "WHERE id = ?1"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, next).Run());
  }
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare("UPDATE jobs SET shares = ?2, state = 0, started_ms = 0, "
                                   "progress = 0, current_value = NULL, points = 0 "
                                   "WHERE shares = ?1 AND state IN (0, 1)"));
  return q.Bind(1, id).Bind(2, next).Run();
}

Status SqliteStoreImpl::RequeueWithFollowers(std::string_view id, bool count_attempt) {
  DRILLBIF_RETURN_IF_ERROR(UpdateRunning(
      "UPDATE jobs SET state = 0, started_ms = 0, progress = 0, current_value = NULL, "
      "points = 0, worker_id = '', attempts = attempts - ?2 WHERE id = ?1 AND state = 1",
      id, [&](Query& q) { q.Bind(2, count_attempt ? 0 : 1); }));
  DRILLBIF_RETURN_IF_ERROR(DropRunChunks(id));
  // The next run submits its own tasks: this run's are no longer wanted.
  DRILLBIF_RETURN_IF_ERROR(CancelChildren(id));
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare("UPDATE jobs SET state = 0, started_ms = 0, progress = 0, "
                                   "current_value = NULL, points = 0 "
                                   "WHERE shares = ?1 AND state IN (0, 1)"));
  return q.Bind(1, id).Run();
}

Status SqliteStoreImpl::FailWithFollowers(std::string_view id, StatusCode code,
                                          std::string_view message) {
  const int64_t now = NowMs();
  DRILLBIF_RETURN_IF_ERROR(UpdateRunning(
      "UPDATE jobs SET state = 3, error_code = ?2, error_message = ?3, finished_ms = ?4 "
      "WHERE id = ?1 AND state = 1",
      id, [&](Query& q) { q.Bind(2, static_cast<int>(code)).Bind(3, message).Bind(4, now); }));
  DRILLBIF_RETURN_IF_ERROR(DropRunChunks(id));
  DRILLBIF_RETURN_IF_ERROR(CancelChildren(id));
  DRILLBIF_ASSIGN_OR_RETURN(Query q,
                            connection_.Prepare("UPDATE jobs SET state = 3, error_code = ?2, "
                                                "error_message = ?3, finished_ms = ?4 "
                                                "WHERE shares = ?1 AND state IN (0, 1)"));
  return q.Bind(1, id).Bind(2, static_cast<int>(code)).Bind(3, message).Bind(4, now).Run();
}

Status SqliteStoreImpl::CancelRunning(std::string_view id) {
  const int64_t now = NowMs();
  DRILLBIF_RETURN_IF_ERROR(
      UpdateRunning("UPDATE jobs SET state = 4, finished_ms = ?2 WHERE id = ?1 AND state = 1", id,
                    [&](Query& q) { q.Bind(2, now); }));
  DRILLBIF_RETURN_IF_ERROR(DropRunChunks(id));
  DRILLBIF_RETURN_IF_ERROR(CancelChildren(id));
  return PromoteFollower(id);
}

Status SqliteStoreImpl::CancelChildren(std::string_view id) {
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("UPDATE jobs INDEXED BY jobs_by_parent SET state = 4, "
                                     "finished_ms = ?2 WHERE parent_id = ?1 AND parent_id <> '' "
                                     "AND state = 0"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, id).Bind(2, NowMs()).Run());
  }
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare("UPDATE jobs INDEXED BY jobs_by_parent SET cancel_requested = 1 "
                                   "WHERE parent_id = ?1 AND parent_id <> '' AND state = 1"));
  return q.Bind(1, id).Run();
}

Status SqliteStoreImpl::CheckQueueLimits(const SubmitRequest& request) {
  int64_t waiting_of_client = 0;
  int64_t waiting = 0;
  if (request.max_queued_per_client > 0) {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT COUNT(*) FROM jobs INDEXED BY jobs_claimable "
                                     "WHERE state = 0 AND shares IS NULL AND parent_id = '' "
                                     "AND client = ?1"));
    q.Bind(1, request.client);
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    waiting_of_client = row ? q.Int(0) : 0;
  }
  if (request.max_queued > 0) {
    DRILLBIF_ASSIGN_OR_RETURN(waiting,
                              QueryInt(connection_,
                                       "SELECT COUNT(*) FROM jobs INDEXED BY jobs_claimable "
                                       "WHERE state = 0 AND shares IS NULL AND parent_id = ''"));
  }
  return server::CheckQueueLimits(request, waiting_of_client, waiting);
}

StatusOr<SubmitResult> SqliteStoreImpl::Submit(const SubmitRequest& request) {
  DRILLBIF_RETURN_IF_ERROR(CheckSubmit(request));
  DRILLBIF_RETURN_IF_ERROR(CheckSize("request", request.request.size(), max_value_bytes_));
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));

  SubmitResult result;
  if (!request.request_id.empty()) {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT id, kind, request, cache_hit, shares, parent_id "
                                     "FROM jobs WHERE request_id = ?1"));
    q.Bind(1, request.request_id);
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (row) {
      if (q.Text(1) != request.kind || q.Blob(2) != request.request ||
          q.Text(5) != request.parent) {
        return RequestIdReused(request.request_id, q.Text(0));
      }
      result.id = q.Text(0);
      result.deduplicated = true;
      result.cache_hit = q.Int(3) != 0;
      result.shared_with = q.Text(4);
      return result;  // Nothing written: the transaction rolls back.
    }
  }
  if (!request.parent.empty()) {
    // Parents leave RUNNING only in writing transactions, which this one excludes: the parent
    // cannot finish between this check and the insert.
    StatusOr<JobHead> parent = Head(request.parent);
    if (!parent.ok() && parent.status().code() != StatusCode::kNotFound) return parent.status();
    DRILLBIF_RETURN_IF_ERROR(
        CheckParent(request.parent, request.parent_run, parent.ok() ? &*parent : nullptr));
  }

  const int64_t now = NowMs();
  const std::string id = NewJobId(random_);
  const std::string result_key = ResultKey(request, id);

  // Values for the new row; a cache hit or a shared job starts in another state.
  int state = kQueued;
  std::string shares;
  double progress = 0;
  std::optional<double> current_value;
  int64_t points = 0;
  int64_t started_ms = 0;
  int64_t finished_ms = 0;
  if (!request.cache_key.empty()) {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT points FROM results WHERE result_key = ?1"));
    q.Bind(1, result_key);
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (row) {
      result.cache_hit = true;
      state = kSucceeded;
      progress = 1;
      points = q.Int(0);
      started_ms = now;
      finished_ms = now;
    }
  }
  if (!request.cache_key.empty() && !result.cache_hit) {
    // A job being cancelled is not shared: it would end without a result.
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare(
                     "SELECT id, state, started_ms, progress, current_value, points FROM jobs "
                     "WHERE cache_key = ?1 AND shares IS NULL AND state IN (0, 1) "
                     "AND cancel_requested = 0 ORDER BY seq LIMIT 1"));
    q.Bind(1, request.cache_key);
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (row) {
      shares = q.Text(0);
      state = static_cast<int>(q.Int(1));
      started_ms = q.Int(2);
      progress = q.Double(3);
      if (!q.IsNull(4)) current_value = q.Double(4);
      points = q.Int(5);
      result.shared_with = shares;
    }
  }
  // Only a job that will run adds work: cache hits and followers are never refused. Nor are
  // children: their parent was admitted with the cost of the whole.
  if (state == kQueued && shares.empty() && request.parent.empty()) {
    DRILLBIF_RETURN_IF_ERROR(CheckQueueLimits(request));
  }
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q,
        connection_.Prepare(
            "INSERT INTO jobs (id, kind, state, request, cache_key, request_id, shares, "
            "result_key, progress, current_value, points, created_ms, started_ms, "
            "finished_ms, cache_hit, client, lane, parent_id) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, "
            "?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15, ?16, ?17, ?18)"));
    q.Bind(1, id)
        .Bind(2, request.kind)
        .Bind(3, state)
        .BindBlob(4, request.request)
        .Bind(5, request.cache_key)
        .BindOrNull(6, request.request_id)
        .BindOrNull(7, shares)
        .Bind(8, result_key)
        .Bind(9, progress)
        .Bind(10, current_value)
        .Bind(11, points)
        .Bind(12, now)
        .Bind(13, started_ms)
        .Bind(14, finished_ms)
        .Bind(15, result.cache_hit ? 1 : 0)
        .Bind(16, request.client)
        .Bind(17, request.lane)
        .Bind(18, request.parent);
    DRILLBIF_RETURN_IF_ERROR(q.Run());
  }
  if (result.cache_hit) {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q,
        connection_.Prepare("UPDATE counters SET value = value + 1 WHERE name = 'cache_hits'"));
    DRILLBIF_RETURN_IF_ERROR(q.Run());
  }
  DRILLBIF_RETURN_IF_ERROR(tx.Commit());
  result.id = id;
  return result;
}

StatusOr<std::optional<JobRecord>> SqliteStoreImpl::ClaimNext(std::string_view worker_id,
                                                              const ClaimOptions& options) {
  DRILLBIF_RETURN_IF_ERROR(options.Validate());
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  std::string id;
  if (!options.parent.empty()) {
    // The parent runs its own tasks: only its children, oldest first.
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT id FROM jobs INDEXED BY jobs_by_parent "
                                     "WHERE parent_id = ?1 AND parent_id <> '' AND state = 0 "
                                     "AND ((?2 >> lane) & 1) = 1 ORDER BY seq LIMIT 1"));
    q.Bind(1, options.parent).Bind(2, LaneMask(options));
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (!row) return std::optional<JobRecord>();
    id = q.Text(0);
  } else {
    // Work already running first: the oldest QUEUED child of a RUNNING parent. Queued children
    // exist only while their parent runs (it cancels them when it stops), so the first entry of
    // the index is normally the one taken.
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT c.id FROM jobs c INDEXED BY jobs_queued_children "
                                     "JOIN jobs p ON p.id = c.parent_id "
                                     "WHERE c.state = 0 AND c.parent_id <> '' AND p.state = 1 "
                                     "AND ((?1 >> c.lane) & 1) = 1 ORDER BY c.seq LIMIT 1"));
    q.Bind(1, LaneMask(options));
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (row) id = q.Text(0);
  }
  if (id.empty()) {
    // Fair across clients: each client's oldest claimable job of the allowed lanes (heads),
    // ordered by how many jobs that client has RUNNING in those lanes, then by age. The clients
    // are walked as a skip scan of jobs_claimable (one index seek per client) and each head is
    // one seek per (client, lane): a claim costs O(clients x lanes x log n), not O(queued jobs).
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q,
        connection_.Prepare(
            "WITH RECURSIVE clients(client) AS ("
            "  SELECT (SELECT MIN(client) FROM jobs INDEXED BY jobs_claimable"
            "          WHERE state = 0 AND shares IS NULL AND parent_id = '')"
            "  UNION ALL"
            "  SELECT (SELECT MIN(client) FROM jobs INDEXED BY jobs_claimable"
            "          WHERE state = 0 AND shares IS NULL AND parent_id = ''"
            "          AND client > c.client)"
            "  FROM clients c WHERE c.client IS NOT NULL),"
            " lanes(lane) AS (SELECT 0 UNION ALL SELECT lane + 1 FROM lanes WHERE lane + 1 < ?2),"
            " heads AS ("
            "  SELECT c.client AS client, MIN((SELECT seq FROM jobs INDEXED BY jobs_claimable"
            "    WHERE state = 0 AND shares IS NULL AND parent_id = '' AND client = c.client"
            "    AND lane = l.lane"
            "    ORDER BY seq LIMIT 1)) AS seq"
            "  FROM clients c JOIN lanes l"
            "  WHERE c.client IS NOT NULL AND ((?1 >> l.lane) & 1) = 1"
            "  GROUP BY c.client),"
            " running AS ("
            "  SELECT client, COUNT(*) AS n FROM jobs INDEXED BY jobs_running"
            "  WHERE state = 1 AND shares IS NULL AND ((?1 >> lane) & 1) = 1"
            "  GROUP BY client)"
            " SELECT j.id FROM heads h JOIN jobs j ON j.seq = h.seq"
            " LEFT JOIN running r ON r.client = h.client"
            " ORDER BY COALESCE(r.n, 0), h.seq LIMIT 1"));
    q.Bind(1, LaneMask(options)).Bind(2, kLaneCount);
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (!row) return std::optional<JobRecord>();
    id = q.Text(0);
  }
  const int64_t now = NowMs();
  const int64_t lease_expires = ClaimedLeaseExpiry(now, options.lease_ms);
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q,
        connection_.Prepare("UPDATE jobs SET state = 1, started_ms = ?2, attempts = attempts + 1, "
                            "run = run + 1, worker_id = ?3, progress = 0, current_value = NULL, "
                            "points = 0, lease_expires_ms = ?4 WHERE id = ?1 AND state = 0"));
    DRILLBIF_RETURN_IF_ERROR(
        q.Bind(1, id).Bind(2, now).Bind(3, StoredText(worker_id)).Bind(4, lease_expires).Run());
  }
  // A new run starts from nothing (there is nothing to drop unless a bug left chunks behind).
  DRILLBIF_RETURN_IF_ERROR(DropRunChunks(id));
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q,
                              connection_.Prepare("UPDATE jobs SET state = 1, started_ms = ?2 "
                                                  "WHERE shares = ?1 AND state = 0"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, id).Bind(2, now).Run());
  }
  JobRecord job;
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare(SelectJobs("request", "WHERE id = ?1")));
    q.Bind(1, id);
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (!row) return Internal("claimed job '" + id + "' vanished");
    job = ReadJob(q);
  }
  DRILLBIF_RETURN_IF_ERROR(tx.Commit());
  return std::optional<JobRecord>(std::move(job));
}

Status SqliteStoreImpl::UpdateProgress(std::string_view id, int64_t run, double fraction,
                                       std::optional<double> current_value, int64_t points) {
  DRILLBIF_RETURN_IF_ERROR(CheckProgress(fraction, current_value, points));
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_RETURN_IF_ERROR(RunningHead(id, "update progress of", run).status());
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q,
      connection_.Prepare("UPDATE jobs SET progress = ?2, current_value = ?3, points = ?4 "
                          "WHERE state = 1 AND ((id = ?1 AND shares IS NULL) OR shares = ?1)"));
  DRILLBIF_RETURN_IF_ERROR(
      q.Bind(1, id).Bind(2, fraction).Bind(3, current_value).Bind(4, points).Run());
  return tx.Commit();
}

Status SqliteStoreImpl::Fail(std::string_view id, int64_t run, StatusCode code,
                             std::string_view message) {
  if (code == StatusCode::kOk) return InvalidArgument("a failed job needs an error code, not OK");
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_RETURN_IF_ERROR(RunningHead(id, "fail", run).status());
  DRILLBIF_RETURN_IF_ERROR(FailWithFollowers(id, code, StoredText(message)));
  return tx.Commit();
}

StatusOr<JobState> SqliteStoreImpl::Cancel(std::string_view id) {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_ASSIGN_OR_RETURN(JobHead head, Head(id));
  const auto state = static_cast<JobState>(head.state);
  const int64_t now = NowMs();
  JobState after = state;
  switch (state) {
    case JobState::kCancelled:
      return JobState::kCancelled;
    case JobState::kSucceeded:
    case JobState::kFailed:
      return AlreadyFinished(id, state);
    case JobState::kQueued:
    case JobState::kRunning:
      if (state == JobState::kRunning && !head.shares) {
        // Its worker stops it: only the worker knows when the engine has let go.
        DRILLBIF_ASSIGN_OR_RETURN(Query q,
                                  connection_.Prepare("UPDATE jobs SET cancel_requested = 1 "
                                                      "WHERE id = ?1 AND state = 1"));
        DRILLBIF_RETURN_IF_ERROR(q.Bind(1, id).Run());
        // Its tasks too: each task's worker sees the cancel on its own poll.
        DRILLBIF_RETURN_IF_ERROR(CancelChildren(id));
        after = JobState::kRunning;
      } else {
        // Nothing runs for it (queued, or following another job): cancelled at once.
        {
          DRILLBIF_ASSIGN_OR_RETURN(
              Query q, connection_.Prepare("UPDATE jobs SET state = 4, finished_ms = ?2 "
                                           "WHERE id = ?1 AND state IN (0, 1)"));
          DRILLBIF_RETURN_IF_ERROR(q.Bind(1, id).Bind(2, now).Run());
        }
        if (!head.shares) DRILLBIF_RETURN_IF_ERROR(PromoteFollower(id));
        after = JobState::kCancelled;
      }
      break;
  }
  DRILLBIF_RETURN_IF_ERROR(tx.Commit());
  return after;
}

StatusOr<bool> SqliteStoreImpl::IsCancelRequested(std::string_view id) {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Query q,
                            connection_.Prepare("SELECT cancel_requested FROM jobs WHERE id = ?1"));
  q.Bind(1, id);
  DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
  if (!row) return NoJob(id);
  return q.Int(0) != 0;
}

Status SqliteStoreImpl::MarkCancelled(std::string_view id, int64_t run) {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_RETURN_IF_ERROR(RunningHead(id, "mark cancelled", run).status());
  DRILLBIF_RETURN_IF_ERROR(CancelRunning(id));
  return tx.Commit();
}

Status SqliteStoreImpl::Requeue(std::string_view id, int64_t run) {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_ASSIGN_OR_RETURN(JobHead head, RunningHead(id, "requeue", run));
  // A cancel asked before the stop wins: the client does not want the job run again.
  if (head.cancel_requested) {
    DRILLBIF_RETURN_IF_ERROR(CancelRunning(id));
  } else {
    DRILLBIF_RETURN_IF_ERROR(RequeueWithFollowers(id, /*count_attempt=*/false));
  }
  return tx.Commit();
}

StatusOr<std::optional<std::string>> SqliteStoreImpl::FindSucceeded(std::string_view cache_key) {
  if (cache_key.empty()) return InvalidArgument("cache_key: must not be empty");
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare("SELECT id FROM jobs INDEXED BY jobs_by_cache_key "
                                   "WHERE cache_key = ?1 AND cache_key <> '' AND state = 2 "
                                   "ORDER BY seq LIMIT 1"));
  q.Bind(1, cache_key);
  DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
  if (!row) return std::optional<std::string>();
  return std::optional<std::string>(q.Text(0));
}

StatusOr<JobRecord> SqliteStoreImpl::Get(std::string_view id, bool include_request) {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q,
      connection_.Prepare(SelectJobs("CASE WHEN ?2 THEN request ELSE x'' END", "WHERE id = ?1")));
  q.Bind(1, id).Bind(2, include_request ? 1 : 0);
  DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
  if (!row) return NoJob(id);
  return ReadJob(q);
}

StatusOr<ListResult> SqliteStoreImpl::List(const ListRequest& request) {
  if (request.page_size < 0) return InvalidArgument("page_size: must be >= 0");
  DRILLBIF_ASSIGN_OR_RETURN(const int64_t after_seq, ParsePageToken(request.page_token));
  const int page_size =
      PageSize(request.page_size, options_.default_page_size, options_.max_page_size);
  std::lock_guard<std::mutex> lock(mu_);
  // Keyset pagination on seq: a page starts after the last seq seen, so jobs submitted or
  // deleted meanwhile never shift the pages (an offset would skip or repeat jobs).
  // One parent's children come from its index (a few hundred rows sorted), not from a walk of
  // every job after the token.
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare(SelectJobs(
                   "CASE WHEN ?4 THEN request ELSE x'' END",
                   request.parent.empty()
                       ? "WHERE seq > ?1 AND (?2 IS NULL OR state = ?2) AND (?3 = '' OR kind = ?3) "
                         "AND parent_id = ?6 ORDER BY seq LIMIT ?5"
                       : "INDEXED BY jobs_by_parent WHERE parent_id = ?6 AND parent_id <> '' "
                         "AND seq > ?1 AND (?2 IS NULL OR state = ?2) AND (?3 = '' OR kind = ?3) "
                         "ORDER BY seq LIMIT ?5")));
  q.Bind(1, after_seq);
  if (request.state) {
    q.Bind(2, static_cast<int>(*request.state));
  } else {
    q.BindNull(2);
  }
  // page_size <= max_page_size (an int), so page_size + 1 is computed in 64 bits.
  q.Bind(3, request.kind)
      .Bind(4, request.include_request ? 1 : 0)
      .Bind(5, static_cast<int64_t>(page_size) + 1)
      .Bind(6, request.parent);
  ListResult result;
  int64_t last_seq = 0;
  for (;;) {
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (!row) break;
    if (static_cast<int>(result.jobs.size()) == page_size) {
      // One row more than the page: there is a next page.
      result.next_page_token = PageToken(last_seq);
      break;
    }
    last_seq = q.Int(0);
    result.jobs.push_back(ReadJob(q));
  }
  return result;
}

StatusOr<RecoveryReport> SqliteStoreImpl::TakeBack(TakenBack why, int64_t now_ms) {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  struct Interrupted {
    std::string id;
  };
  std::vector<Interrupted> interrupted;
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT id FROM jobs "
                                     "WHERE state = 1 AND shares IS NULL AND "
                                     "(?1 OR (lease_expires_ms > 0 AND lease_expires_ms < ?2)) "
                                     "ORDER BY seq"));
    q.Bind(1, why == TakenBack::kRestart ? 1 : 0).Bind(2, now_ms);
    for (;;) {
      DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
      if (!row) break;
      interrupted.push_back({q.Text(0)});
    }
  }
  RecoveryReport report;
  for (const Interrupted& job : interrupted) {
    // Read again: taking back a parent earlier in this loop asked its running children to stop,
    // and such a child must end CANCELLED, not be queued again without a running parent.
    DRILLBIF_ASSIGN_OR_RETURN(const JobHead head, Head(job.id));
    if (head.state != kRunning) continue;
    switch (TakeBackActionOf(head.cancel_requested, head.attempts, options_.max_attempts)) {
      case TakeBackAction::kCancel:
        DRILLBIF_RETURN_IF_ERROR(CancelRunning(job.id));
        ++report.cancelled;
        break;
      case TakeBackAction::kFail:
        DRILLBIF_RETURN_IF_ERROR(
            FailWithFollowers(job.id, StatusCode::kInternal,
                              TooManyAttempts(why, head.attempts, options_.max_attempts)));
        ++report.failed;
        break;
      case TakeBackAction::kRequeue:
        DRILLBIF_RETURN_IF_ERROR(RequeueWithFollowers(job.id, /*count_attempt=*/true));
        ++report.requeued;
        break;
    }
  }
  DRILLBIF_RETURN_IF_ERROR(tx.Commit());
  return report;
}

StatusOr<RecoveryReport> SqliteStoreImpl::RecoverAfterRestart() {
  return TakeBack(TakenBack::kRestart, 0);
}

StatusOr<RecoveryReport> SqliteStoreImpl::ReclaimExpiredLeases(int64_t now_ms) {
  return TakeBack(TakenBack::kLeaseExpired, now_ms);
}

Status SqliteStoreImpl::RenewLease(std::string_view id, int64_t run, int64_t lease_ms) {
  DRILLBIF_ASSIGN_OR_RETURN(const int64_t expires, RenewedLeaseExpiry(lease_ms));
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_RETURN_IF_ERROR(RunningHead(id, "renew the lease of", run).status());
  DRILLBIF_RETURN_IF_ERROR(
      UpdateRunning("UPDATE jobs SET lease_expires_ms = ?2 WHERE id = ?1 AND state = 1", id,
                    [&](Query& q) { q.Bind(2, expires); }));
  return tx.Commit();
}

StatusOr<StoreStats> SqliteStoreImpl::Stats() {
  std::lock_guard<std::mutex> lock(mu_);
  // A read transaction: the counts come from one snapshot.
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/false));
  StoreStats stats;
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT state, COUNT(*) FROM jobs GROUP BY state"));
    for (;;) {
      DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
      if (!row) break;
      const int64_t state = q.Int(0);
      if (state >= 0 && state < kJobStateCount) stats.jobs_by_state[state] = q.Int(1);
    }
  }
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare(
                     "SELECT lane, COUNT(*) FROM jobs INDEXED BY jobs_claimable "
                     "WHERE state = 0 AND shares IS NULL AND parent_id = '' GROUP BY lane "
                     "UNION ALL SELECT lane, COUNT(*) FROM jobs INDEXED BY jobs_queued_children "
                     "WHERE state = 0 AND parent_id <> '' GROUP BY lane"));
    for (;;) {
      DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
      if (!row) break;
      const int64_t lane = q.Int(0);
      if (lane >= 0 && lane < kLaneCount) stats.queue_depth_by_lane[lane] += q.Int(1);
      stats.queue_depth += q.Int(1);
    }
  }
  DRILLBIF_ASSIGN_OR_RETURN(
      stats.cache_hits_total,
      QueryInt(connection_, "SELECT value FROM counters WHERE name = 'cache_hits'"));
  DRILLBIF_ASSIGN_OR_RETURN(stats.used_bytes, UsedBytes());
  DRILLBIF_RETURN_IF_ERROR(tx.Commit());
  return stats;
}

Status SqliteJobStoreOptions::Validate() const {
  if (busy_timeout_ms < 0) return InvalidArgument("busy_timeout_ms: must be >= 0");
  if (max_attempts < 1) return InvalidArgument("max_attempts: must be >= 1");
  if (max_page_size < 1) return InvalidArgument("max_page_size: must be >= 1");
  if (default_page_size < 1 || default_page_size > max_page_size) {
    return InvalidArgument("default_page_size: must be in [1, max_page_size]");
  }
  if (wal_size_limit_bytes < 0) return InvalidArgument("wal_size_limit_bytes: must be >= 0");
  if (min_free_bytes_after_full < 0) {
    return InvalidArgument("min_free_bytes_after_full: must be >= 0");
  }
  return Status::Ok();
}

StatusOr<std::unique_ptr<JobStore>> SqliteJobStore::Open(const std::string& path,
                                                         const SqliteJobStoreOptions& options) {
  DRILLBIF_RETURN_IF_ERROR(options.Validate());
  if (path.empty()) return InvalidArgument("path: must not be empty");
  // Errors name the file (the operator's business), never SQL.
  const auto in_file = [&](const Status& status) {
    return Status(status.code(), status.message() + " (file '" + path + "')");
  };
  if (options.integrity_check_at_open) {
    if (Status s = CheckIntegrity(path, options.log); !s.ok()) return in_file(s);
  }
  sqlite3* db = nullptr;
  // NOMUTEX: the store's own mutex serializes every use of the connection.
  const int rc = sqlite3_open_v2(
      path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX, nullptr);
  if (rc != SQLITE_OK) {
    // The handle (if any) is closed by the connection, which also logs the details.
    sqlite::Connection failed(db, options.log);
    return in_file(failed.Error(rc, "open"));
  }
  auto store = std::make_unique<SqliteStoreImpl>(db, path, options);
  // Another process opening the same file at the same moment can make a step of Configure return
  // SQLITE_BUSY at once, without the busy handler's wait (the kill -9 test's parent, opening while
  // its child did, failed so: "the job store is busy; retry later"; a connection that merely holds
  // the file locked does get the wait, so the two first connections meeting is the likely cause,
  // not reproduced on demand). Every step is idempotent (the migrations run in one transaction),
  // so Configure is retried for up to busy_timeout_ms, as a statement would wait.
  const auto deadline =
      std::chrono::steady_clock::now() + std::chrono::milliseconds(options.busy_timeout_ms);
  Status configured = store->Configure();
  while (configured.code() == StatusCode::kUnavailable &&
         std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
    configured = store->Configure();
  }
  if (!configured.ok()) return in_file(configured);
  return std::unique_ptr<JobStore>(std::move(store));
}

}  // namespace drillbif::server
