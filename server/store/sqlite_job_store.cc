// The SQLite JobStore. Schema and semantics: docs/store.md.
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
#include <random>
#include <string>
#include <string_view>
#include <unordered_map>
#include <utility>
#include <vector>

namespace drillbif::server {
namespace {

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
};
static_assert(std::size(kMigrations) == SqliteJobStore::kSchemaVersion,
              "one migration per schema version");

constexpr int kQueued = static_cast<int>(JobState::kQueued);
constexpr int kRunning = static_cast<int>(JobState::kRunning);
constexpr int kSucceeded = static_cast<int>(JobState::kSucceeded);
constexpr int kFailed = static_cast<int>(JobState::kFailed);
constexpr int kCancelled = static_cast<int>(JobState::kCancelled);

int64_t NowMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

Status SqliteError(sqlite3* db, int rc, std::string_view what) {
  std::string message = "sqlite: ";
  message += what;
  message += ": ";
  message += db != nullptr ? sqlite3_errmsg(db) : sqlite3_errstr(rc);
  return Internal(std::move(message));
}

Status NoJob(std::string_view id) { return NotFound("no job '" + std::string(id) + "'"); }

// ---------------------------------------------------------------------------------------------
// Thin RAII layer over the C API.

struct StatementDeleter {
  void operator()(sqlite3_stmt* statement) const { sqlite3_finalize(statement); }
};
using StatementPtr = std::unique_ptr<sqlite3_stmt, StatementDeleter>;

// A cached prepared statement in use: binds parameters (1-based, as in SQL's ?N), steps, reads
// columns, and resets the statement when it goes out of scope so the cache can hand it out again
// (a statement left mid-step would also keep a read transaction open).
class Query {
 public:
  Query(sqlite3* db, sqlite3_stmt* statement) : db_(db), statement_(statement) {}
  Query(Query&& other) noexcept
      : db_(other.db_), statement_(std::exchange(other.statement_, nullptr)), rc_(other.rc_) {}
  Query(const Query&) = delete;
  Query& operator=(const Query&) = delete;
  Query& operator=(Query&&) = delete;
  ~Query() {
    if (statement_ != nullptr) {
      sqlite3_reset(statement_);
      sqlite3_clear_bindings(statement_);
    }
  }

  Query& Bind(int index, int64_t value) {
    Check(sqlite3_bind_int64(statement_, index, value));
    return *this;
  }
  Query& Bind(int index, int value) { return Bind(index, static_cast<int64_t>(value)); }
  Query& Bind(int index, double value) {
    Check(sqlite3_bind_double(statement_, index, value));
    return *this;
  }
  Query& Bind(int index, std::optional<double> value) {
    Check(value ? sqlite3_bind_double(statement_, index, *value)
                : sqlite3_bind_null(statement_, index));
    return *this;
  }
  // Text; a null data pointer (empty string_view) would bind NULL, so bind "" explicitly.
  Query& Bind(int index, std::string_view text) {
    Check(sqlite3_bind_text(statement_, index, text.empty() ? "" : text.data(),
                            static_cast<int>(text.size()), SQLITE_TRANSIENT));
    return *this;
  }
  Query& Bind(int index, const char* text) { return Bind(index, std::string_view(text)); }
  Query& Bind(int index, const std::string& text) { return Bind(index, std::string_view(text)); }
  Query& BindNull(int index) {
    Check(sqlite3_bind_null(statement_, index));
    return *this;
  }
  // Text, or NULL when empty.
  Query& BindOrNull(int index, std::string_view text) {
    return text.empty() ? BindNull(index) : Bind(index, text);
  }
  Query& BindBlob(int index, std::string_view bytes) {
    Check(bytes.empty() ? sqlite3_bind_zeroblob(statement_, index, 0)
                        : sqlite3_bind_blob(statement_, index, bytes.data(),
                                            static_cast<int>(bytes.size()), SQLITE_TRANSIENT));
    return *this;
  }

  // Steps once: true with a row to read, false when done.
  StatusOr<bool> Step() {
    if (rc_ != SQLITE_OK) return SqliteError(db_, rc_, "bind");
    const int rc = sqlite3_step(statement_);
    if (rc == SQLITE_ROW) return true;
    if (rc == SQLITE_DONE) return false;
    return SqliteError(db_, rc, sqlite3_sql(statement_));
  }
  // Runs a statement that returns no rows (or whose rows are not needed).
  Status Run() {
    StatusOr<bool> row = Step();
    return row.status();
  }

  int64_t Int(int column) const { return sqlite3_column_int64(statement_, column); }
  double Double(int column) const { return sqlite3_column_double(statement_, column); }
  bool IsNull(int column) const { return sqlite3_column_type(statement_, column) == SQLITE_NULL; }
  std::string Text(int column) const {
    const unsigned char* text = sqlite3_column_text(statement_, column);
    if (text == nullptr) return std::string();
    return std::string(reinterpret_cast<const char*>(text),
                       static_cast<size_t>(sqlite3_column_bytes(statement_, column)));
  }
  std::string Blob(int column) const {
    const void* data = sqlite3_column_blob(statement_, column);
    if (data == nullptr) return std::string();
    return std::string(static_cast<const char*>(data),
                       static_cast<size_t>(sqlite3_column_bytes(statement_, column)));
  }

 private:
  // Keeps the first bind error; Step reports it.
  void Check(int rc) {
    if (rc_ == SQLITE_OK) rc_ = rc;
  }

  sqlite3* db_;
  sqlite3_stmt* statement_;
  int rc_ = SQLITE_OK;
};

// One connection with a cache of prepared statements, keyed by their SQL text.
class Connection {
 public:
  explicit Connection(sqlite3* db) : db_(db) {}
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;
  ~Connection() {
    statements_.clear();  // Finalize before closing, or sqlite3_close fails with SQLITE_BUSY.
    sqlite3_close(db_);
  }

  sqlite3* db() const { return db_; }

  StatusOr<Query> Prepare(const std::string& sql) {
    auto it = statements_.find(sql);
    if (it == statements_.end()) {
      sqlite3_stmt* statement = nullptr;
      const int rc = sqlite3_prepare_v3(db_, sql.c_str(), static_cast<int>(sql.size() + 1),
                                        SQLITE_PREPARE_PERSISTENT, &statement, nullptr);
      if (rc != SQLITE_OK) return SqliteError(db_, rc, "prepare");
      it = statements_.emplace(sql, StatementPtr(statement)).first;
    }
    return Query(db_, it->second.get());
  }

  // Runs SQL text without parameters (pragmas, migrations; may hold several statements).
  Status Exec(const char* sql) {
    const int rc = sqlite3_exec(db_, sql, nullptr, nullptr, nullptr);
    if (rc != SQLITE_OK) return SqliteError(db_, rc, sql);
    return Status::Ok();
  }

  // Rows changed by the last INSERT/UPDATE/DELETE.
  int Changes() const { return sqlite3_changes(db_); }

 private:
  sqlite3* db_;
  std::unordered_map<std::string, StatementPtr> statements_;
};

// A transaction: BEGIN IMMEDIATE for writers (take the write lock before reading, so the checks
// and the writes that depend on them are atomic across connections), plain BEGIN for readers
// that need one snapshot across statements. Rolled back unless committed.
class Transaction {
 public:
  static StatusOr<Transaction> Begin(Connection& connection, bool write) {
    DRILLBIF_RETURN_IF_ERROR(connection.Exec(write ? "BEGIN IMMEDIATE" : "BEGIN"));
    return Transaction(connection);
  }
  Transaction(Transaction&& other) noexcept
      : connection_(other.connection_), open_(std::exchange(other.open_, false)) {}
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;
  Transaction& operator=(Transaction&&) = delete;
  ~Transaction() {
    // Some errors (I/O, disk full) already rolled the transaction back; ROLLBACK would fail then.
    if (open_ && sqlite3_get_autocommit(connection_->db()) == 0) {
      // Best effort: the error being returned is the caller's; a failed rollback leaves nothing
      // committed either way.
      connection_->Exec("ROLLBACK").IgnoreError();
    }
  }

  Status Commit() {
    DRILLBIF_RETURN_IF_ERROR(connection_->Exec("COMMIT"));
    open_ = false;
    return Status::Ok();
  }

 private:
  explicit Transaction(Connection& connection) : connection_(&connection) {}

  Connection* connection_;
  bool open_ = true;
};

// ---------------------------------------------------------------------------------------------

// Columns of a JobRecord, in the order ReadJob expects; %s is the request expression.
constexpr const char* kJobColumns =
    "seq, id, kind, state, %s, cache_key, request_id, shares, progress, current_value, points, "
    "error_code, error_message, created_ms, started_ms, finished_ms, cache_hit, attempts, "
    "cancel_requested, worker_id";

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
  return job;
}

// Page tokens are "p" + the hex seq of the last job returned: opaque to clients, checked on use.
std::string PageToken(int64_t seq) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "p%llx", static_cast<unsigned long long>(seq));
  return buffer;
}

StatusOr<int64_t> ParsePageToken(const std::string& token) {
  if (token.empty()) return int64_t{0};
  const auto bad = [&] { return InvalidArgument("page_token: malformed '" + token + "'"); };
  if (token.size() < 2 || token.size() > 17 || token[0] != 'p') return bad();
  uint64_t seq = 0;
  for (size_t i = 1; i < token.size(); ++i) {
    const char c = token[i];
    int digit;
    if (c >= '0' && c <= '9') {
      digit = c - '0';
    } else if (c >= 'a' && c <= 'f') {
      digit = c - 'a' + 10;
    } else {
      return bad();
    }
    seq = seq * 16 + static_cast<uint64_t>(digit);
  }
  if (seq > static_cast<uint64_t>(INT64_MAX)) return bad();
  return static_cast<int64_t>(seq);
}

// The part of a job the state checks need.
struct JobHead {
  int state = 0;
  bool shares = false;  // It follows another job.
  bool cancel_requested = false;
  int attempts = 0;
  std::string result_key;
};

class SqliteStoreImpl final : public JobStore {
 public:
  SqliteStoreImpl(sqlite3* db, const SqliteJobStoreOptions& options)
      : connection_(db), options_(options) {}

  StatusOr<SubmitResult> Submit(const SubmitRequest& request) override;
  StatusOr<std::optional<JobRecord>> ClaimNext(std::string_view worker_id) override;
  Status UpdateProgress(std::string_view id, double fraction, std::optional<double> current_value,
                        int64_t points) override;
  Status Complete(std::string_view id, std::string_view result, int64_t points) override;
  Status Fail(std::string_view id, StatusCode code, std::string_view message) override;
  StatusOr<JobState> Cancel(std::string_view id) override;
  StatusOr<bool> IsCancelRequested(std::string_view id) override;
  Status MarkCancelled(std::string_view id) override;
  Status Requeue(std::string_view id) override;
  StatusOr<JobRecord> Get(std::string_view id) override;
  StatusOr<ListResult> List(const ListRequest& request) override;
  Status Delete(std::string_view id) override;
  StatusOr<std::string> GetResult(std::string_view id) override;
  StatusOr<RecoveryReport> RecoverAfterRestart() override;
  StatusOr<StoreStats> Stats() override;

  // Migrates the schema (Open calls it once, before the store is shared).
  Status Migrate();
  Connection& connection() { return connection_; }

 private:
  // All helpers below run inside a transaction the caller holds, with mu_ locked.
  StatusOr<JobHead> Head(std::string_view id);
  // The job must be RUNNING and run itself (not share another): only its worker acts on it.
  StatusOr<JobHead> RunningHead(std::string_view id, const char* action);
  // Changes `id` from RUNNING by `update` (its ?1 is the id); FAILED_PRECONDITION unless exactly
  // one row changed. The state check sits in the UPDATE's WHERE, so even a bug in the checks
  // before it cannot finish a job twice.
  Status UpdateRunning(const std::string& update, std::string_view id,
                       const std::function<void(Query&)>& bind);
  // The jobs following `id` are no longer served by it (it was cancelled): the oldest becomes a
  // QUEUED job of its own and the others follow it.
  Status PromoteFollower(std::string_view id);
  // The jobs following `id` go back to QUEUED with it.
  Status RequeueWithFollowers(std::string_view id, bool count_attempt);
  Status FailWithFollowers(std::string_view id, StatusCode code, std::string_view message);
  Status CancelRunning(std::string_view id);
  std::string NewId();

  std::mutex mu_;
  Connection connection_;
  const SqliteJobStoreOptions options_;
  std::random_device random_;
};

Status SqliteStoreImpl::Migrate() {
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  int64_t application_id = 0;
  int64_t version = 0;
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare("PRAGMA application_id"));
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (row) application_id = q.Int(0);
  }
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare("PRAGMA user_version"));
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
    Status status = connection_.Exec(kMigrations[v]);
    if (!status.ok()) {
      return Internal("migrating the job store from schema version " + std::to_string(v) + ": " +
                      status.message());
    }
  }
  // Pragmas take no parameters; both values are integers formatted here.
  const std::string set_ids =
      "PRAGMA application_id = " + std::to_string(SqliteJobStore::kApplicationId) +
      "; PRAGMA user_version = " + std::to_string(SqliteJobStore::kSchemaVersion);
  DRILLBIF_RETURN_IF_ERROR(connection_.Exec(set_ids.c_str()));
  return tx.Commit();
}

std::string SqliteStoreImpl::NewId() {
  // 128 bits from the OS entropy source on every call: no generator state to duplicate across
  // fork() (two processes sharing a file must never draw the same ids).
  char buffer[33];
  std::snprintf(buffer, sizeof(buffer), "%08x%08x%08x%08x", random_(), random_(), random_(),
                random_());
  return std::string(buffer, 32);
}

StatusOr<JobHead> SqliteStoreImpl::Head(std::string_view id) {
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare("SELECT state, shares IS NOT NULL, cancel_requested, attempts, "
                                   "result_key FROM jobs WHERE id = ?1"));
  q.Bind(1, id);
  DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
  if (!row) return NoJob(id);
  JobHead head;
  head.state = static_cast<int>(q.Int(0));
  head.shares = q.Int(1) != 0;
  head.cancel_requested = q.Int(2) != 0;
  head.attempts = static_cast<int>(q.Int(3));
  head.result_key = q.Text(4);
  return head;
}

StatusOr<JobHead> SqliteStoreImpl::RunningHead(std::string_view id, const char* action) {
  DRILLBIF_ASSIGN_OR_RETURN(JobHead head, Head(id));
  if (head.state != kRunning) {
    return FailedPrecondition(std::string("cannot ") + action + " job '" + std::string(id) +
                              "': it is " + JobStateName(static_cast<JobState>(head.state)) +
                              ", not RUNNING");
  }
  if (head.shares) {
    return FailedPrecondition(std::string("cannot ") + action + " job '" + std::string(id) +
                              "': it shares another job's run and is not run by a worker");
  }
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
  DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare("UPDATE jobs SET state = 3, error_code = ?2, "
                                                     "error_message = ?3, finished_ms = ?4 "
                                                     "WHERE shares = ?1 AND state IN (0, 1)"));
  return q.Bind(1, id).Bind(2, static_cast<int>(code)).Bind(3, message).Bind(4, now).Run();
}

Status SqliteStoreImpl::CancelRunning(std::string_view id) {
  const int64_t now = NowMs();
  DRILLBIF_RETURN_IF_ERROR(
      UpdateRunning("UPDATE jobs SET state = 4, finished_ms = ?2 WHERE id = ?1 AND state = 1", id,
                    [&](Query& q) { q.Bind(2, now); }));
  return PromoteFollower(id);
}

StatusOr<SubmitResult> SqliteStoreImpl::Submit(const SubmitRequest& request) {
  if (request.kind.empty()) return InvalidArgument("kind: must not be empty");
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));

  SubmitResult result;
  if (!request.request_id.empty()) {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT id, kind, request, cache_hit, shares FROM jobs "
                                     "WHERE request_id = ?1"));
    q.Bind(1, request.request_id);
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (row) {
      if (q.Text(1) != request.kind || q.Blob(2) != request.request) {
        return FailedPrecondition("request_id '" + request.request_id +
                                  "' was already used for a different request (job '" + q.Text(0) +
                                  "')");
      }
      result.id = q.Text(0);
      result.deduplicated = true;
      result.cache_hit = q.Int(3) != 0;
      result.shared_with = q.Text(4);
      return result;  // Nothing written: the transaction rolls back.
    }
  }

  const int64_t now = NowMs();
  const std::string id = NewId();
  const std::string result_key = request.cache_key.empty() ? "j:" + id : "c:" + request.cache_key;

  // Values for the new row; a cache hit or a shared job starts in another state.
  int state = kQueued;
  std::string shares;
  double progress = 0;
  std::optional<double> current_value;
  int64_t points = 0;
  int64_t started_ms = 0;
  int64_t finished_ms = 0;
  if (!request.cache_key.empty()) {
    DRILLBIF_ASSIGN_OR_RETURN(Query q,
                          connection_.Prepare("SELECT points FROM results WHERE result_key = ?1"));
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
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare(
                     "INSERT INTO jobs (id, kind, state, request, cache_key, request_id, shares, "
                     "result_key, progress, current_value, points, created_ms, started_ms, "
                     "finished_ms, cache_hit) "
                     "VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7, ?8, ?9, ?10, ?11, ?12, ?13, ?14, ?15)"));
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
        .Bind(15, result.cache_hit ? 1 : 0);
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

StatusOr<std::optional<JobRecord>> SqliteStoreImpl::ClaimNext(std::string_view worker_id) {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  std::string id;
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT id FROM jobs WHERE state = 0 AND shares IS NULL "
                                     "ORDER BY seq LIMIT 1"));
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (!row) return std::optional<JobRecord>();
    id = q.Text(0);
  }
  const int64_t now = NowMs();
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q,
        connection_.Prepare("UPDATE jobs SET state = 1, started_ms = ?2, attempts = attempts + 1, "
                            "worker_id = ?3, progress = 0, current_value = NULL, points = 0 "
                            "WHERE id = ?1 AND state = 0"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, id).Bind(2, now).Bind(3, worker_id).Run());
  }
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare("UPDATE jobs SET state = 1, started_ms = ?2 "
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

Status SqliteStoreImpl::UpdateProgress(std::string_view id, double fraction,
                                       std::optional<double> current_value, int64_t points) {
  if (!(fraction >= 0.0 && fraction <= 1.0)) {
    return InvalidArgument("progress fraction must be in [0, 1] (got " + std::to_string(fraction) +
                           ")");
  }
  if (current_value && !std::isfinite(*current_value)) {
    return InvalidArgument("current value must be finite");
  }
  if (points < 0) return InvalidArgument("points must be >= 0");
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_RETURN_IF_ERROR(RunningHead(id, "update progress of").status());
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q,
      connection_.Prepare("UPDATE jobs SET progress = ?2, current_value = ?3, points = ?4 "
                          "WHERE state = 1 AND ((id = ?1 AND shares IS NULL) OR shares = ?1)"));
  DRILLBIF_RETURN_IF_ERROR(
      q.Bind(1, id).Bind(2, fraction).Bind(3, current_value).Bind(4, points).Run());
  return tx.Commit();
}

Status SqliteStoreImpl::Complete(std::string_view id, std::string_view result, int64_t points) {
  if (points < 0) return InvalidArgument("points must be >= 0");
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_ASSIGN_OR_RETURN(JobHead head, RunningHead(id, "complete"));
  const int64_t now = NowMs();
  {
    // A result for this cache key can exist already (a job whose cancel was requested, and so
    // was not shared, completed anyway): identical requests give identical results, keep the
    // first.
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("INSERT INTO results (result_key, data, points, created_ms) "
                                     "VALUES (?1, ?2, ?3, ?4) "
                                     "ON CONFLICT (result_key) DO NOTHING"));
    DRILLBIF_RETURN_IF_ERROR(
        q.Bind(1, head.result_key).BindBlob(2, result).Bind(3, points).Bind(4, now).Run());
  }
  DRILLBIF_RETURN_IF_ERROR(
      UpdateRunning("UPDATE jobs SET state = 2, progress = 1, points = ?2, finished_ms = ?3 "
                    "WHERE id = ?1 AND state = 1",
                    id, [&](Query& q) { q.Bind(2, points).Bind(3, now); }));
  int followers = 0;
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare(
                     "UPDATE jobs SET state = 2, progress = 1, points = ?2, finished_ms = ?3, "
                     "cache_hit = 1 WHERE shares = ?1 AND state IN (0, 1)"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, id).Bind(2, points).Bind(3, now).Run());
    followers = connection_.Changes();
  }
  if (followers > 0) {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q,
        connection_.Prepare("UPDATE counters SET value = value + ?1 WHERE name = 'cache_hits'"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, followers).Run());
  }
  return tx.Commit();
}

Status SqliteStoreImpl::Fail(std::string_view id, StatusCode code, std::string_view message) {
  if (code == StatusCode::kOk) return InvalidArgument("a failed job needs an error code, not OK");
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_RETURN_IF_ERROR(RunningHead(id, "fail").status());
  DRILLBIF_RETURN_IF_ERROR(FailWithFollowers(id, code, message));
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
      return FailedPrecondition("job '" + std::string(id) + "' already finished (" +
                                JobStateName(state) + ")");
    case JobState::kQueued:
    case JobState::kRunning:
      if (state == JobState::kRunning && !head.shares) {
        // Its worker stops it: only the worker knows when the engine has let go.
        DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare("UPDATE jobs SET cancel_requested = 1 "
                                                           "WHERE id = ?1 AND state = 1"));
        DRILLBIF_RETURN_IF_ERROR(q.Bind(1, id).Run());
        after = JobState::kRunning;
      } else {
        // Nothing runs for it (queued, or following another job): cancelled at once.
        {
          DRILLBIF_ASSIGN_OR_RETURN(Query q,
                                connection_.Prepare("UPDATE jobs SET state = 4, finished_ms = ?2 "
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

Status SqliteStoreImpl::MarkCancelled(std::string_view id) {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_RETURN_IF_ERROR(RunningHead(id, "mark cancelled").status());
  DRILLBIF_RETURN_IF_ERROR(CancelRunning(id));
  return tx.Commit();
}

Status SqliteStoreImpl::Requeue(std::string_view id) {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_ASSIGN_OR_RETURN(JobHead head, RunningHead(id, "requeue"));
  // A cancel asked before the stop wins: the client does not want the job run again.
  if (head.cancel_requested) {
    DRILLBIF_RETURN_IF_ERROR(CancelRunning(id));
  } else {
    DRILLBIF_RETURN_IF_ERROR(RequeueWithFollowers(id, /*count_attempt=*/false));
  }
  return tx.Commit();
}

StatusOr<JobRecord> SqliteStoreImpl::Get(std::string_view id) {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare(SelectJobs("request", "WHERE id = ?1")));
  q.Bind(1, id);
  DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
  if (!row) return NoJob(id);
  return ReadJob(q);
}

StatusOr<ListResult> SqliteStoreImpl::List(const ListRequest& request) {
  if (request.page_size < 0) return InvalidArgument("page_size: must be >= 0");
  DRILLBIF_ASSIGN_OR_RETURN(const int64_t after_seq, ParsePageToken(request.page_token));
  const int page_size = request.page_size == 0
                            ? options_.default_page_size
                            : std::min(request.page_size, options_.max_page_size);
  std::lock_guard<std::mutex> lock(mu_);
  // Keyset pagination on seq: a page starts after the last seq seen, so jobs submitted or
  // deleted meanwhile never shift the pages (an offset would skip or repeat jobs).
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare(SelectJobs(
                   "CASE WHEN ?4 THEN request ELSE x'' END",
                   "WHERE seq > ?1 AND (?2 IS NULL OR state = ?2) AND (?3 = '' OR kind = ?3) "
                   "ORDER BY seq LIMIT ?5")));
  q.Bind(1, after_seq);
  if (request.state) {
    q.Bind(2, static_cast<int>(*request.state));
  } else {
    q.BindNull(2);
  }
  q.Bind(3, request.kind).Bind(4, request.include_request ? 1 : 0).Bind(5, page_size + 1);
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

Status SqliteStoreImpl::Delete(std::string_view id) {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_ASSIGN_OR_RETURN(JobHead head, Head(id));
  const auto state = static_cast<JobState>(head.state);
  if (!IsFinished(state)) {
    return FailedPrecondition("job '" + std::string(id) + "' is " + JobStateName(state) +
                              ": cancel it and wait until it is finished before deleting it");
  }
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q, connection_.Prepare("DELETE FROM jobs WHERE id = ?1"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, id).Run());
  }
  {
    // The result goes with its last job (a cached result serves later requests only while some
    // job holds it).
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("DELETE FROM results WHERE result_key = ?1 AND NOT EXISTS "
                                     "(SELECT 1 FROM jobs WHERE result_key = ?1)"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, head.result_key).Run());
  }
  return tx.Commit();
}

StatusOr<std::string> SqliteStoreImpl::GetResult(std::string_view id) {
  std::lock_guard<std::mutex> lock(mu_);
  // One statement, one snapshot: the state and the bytes cannot disagree.
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare("SELECT j.state, r.data IS NOT NULL, r.data FROM jobs j "
                                   "LEFT JOIN results r ON r.result_key = j.result_key "
                                   "WHERE j.id = ?1"));
  q.Bind(1, id);
  DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
  if (!row) return NoJob(id);
  const auto state = static_cast<JobState>(q.Int(0));
  if (state != JobState::kSucceeded) {
    return FailedPrecondition("job '" + std::string(id) + "' has no result: it is " +
                              JobStateName(state));
  }
  if (q.Int(1) == 0)
    return Internal("job '" + std::string(id) + "' succeeded but its result is missing");
  return q.Blob(2);
}

StatusOr<RecoveryReport> SqliteStoreImpl::RecoverAfterRestart() {
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  struct Interrupted {
    std::string id;
    int attempts;
    bool cancel_requested;
  };
  std::vector<Interrupted> interrupted;
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q,
                          connection_.Prepare("SELECT id, attempts, cancel_requested FROM jobs "
                                              "WHERE state = 1 AND shares IS NULL ORDER BY seq"));
    for (;;) {
      DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
      if (!row) break;
      interrupted.push_back({q.Text(0), static_cast<int>(q.Int(1)), q.Int(2) != 0});
    }
  }
  RecoveryReport report;
  for (const Interrupted& job : interrupted) {
    if (job.cancel_requested) {
      DRILLBIF_RETURN_IF_ERROR(CancelRunning(job.id));
      ++report.cancelled;
    } else if (job.attempts >= options_.max_attempts) {
      DRILLBIF_RETURN_IF_ERROR(FailWithFollowers(
          job.id, StatusCode::kInternal,
          "the server stopped while this job ran, " + std::to_string(job.attempts) +
              " times; not retried (max_attempts " + std::to_string(options_.max_attempts) + ")"));
      ++report.failed;
    } else {
      DRILLBIF_RETURN_IF_ERROR(RequeueWithFollowers(job.id, /*count_attempt=*/true));
      ++report.requeued;
    }
  }
  DRILLBIF_RETURN_IF_ERROR(tx.Commit());
  return report;
}

StatusOr<StoreStats> SqliteStoreImpl::Stats() {
  std::lock_guard<std::mutex> lock(mu_);
  // A read transaction: the three counts come from one snapshot.
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/false));
  StoreStats stats;
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q,
                          connection_.Prepare("SELECT state, COUNT(*) FROM jobs GROUP BY state"));
    for (;;) {
      DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
      if (!row) break;
      const int64_t state = q.Int(0);
      if (state >= 0 && state < kJobStateCount) stats.jobs_by_state[state] = q.Int(1);
    }
  }
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q,
        connection_.Prepare("SELECT COUNT(*) FROM jobs WHERE state = 0 AND shares IS NULL"));
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (row) stats.queue_depth = q.Int(0);
  }
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT value FROM counters WHERE name = 'cache_hits'"));
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (row) stats.cache_hits_total = q.Int(0);
  }
  DRILLBIF_RETURN_IF_ERROR(tx.Commit());
  return stats;
}

}  // namespace

Status SqliteJobStoreOptions::Validate() const {
  if (busy_timeout_ms < 0) return InvalidArgument("busy_timeout_ms: must be >= 0");
  if (max_attempts < 1) return InvalidArgument("max_attempts: must be >= 1");
  if (max_page_size < 1) return InvalidArgument("max_page_size: must be >= 1");
  if (default_page_size < 1 || default_page_size > max_page_size) {
    return InvalidArgument("default_page_size: must be in [1, max_page_size]");
  }
  return Status::Ok();
}

StatusOr<std::unique_ptr<JobStore>> SqliteJobStore::Open(const std::string& path,
                                                         const SqliteJobStoreOptions& options) {
  DRILLBIF_RETURN_IF_ERROR(options.Validate());
  if (path.empty()) return InvalidArgument("path: must not be empty");
  sqlite3* db = nullptr;
  // NOMUTEX: the store's own mutex serializes every use of the connection.
  const int rc = sqlite3_open_v2(
      path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_NOMUTEX, nullptr);
  if (rc != SQLITE_OK) {
    Status status = SqliteError(db, rc, "open '" + path + "'");
    sqlite3_close(db);
    return status;
  }
  auto store = std::make_unique<SqliteStoreImpl>(db, options);
  Connection& connection = store->connection();
  sqlite3_extended_result_codes(db, 1);
  sqlite3_busy_timeout(db, options.busy_timeout_ms);
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q, connection.Prepare("PRAGMA journal_mode = WAL"));
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    const std::string mode = row ? q.Text(0) : std::string();
    if (mode != "wal") {
      return FailedPrecondition("cannot use WAL journal mode for '" + path + "' (got '" + mode +
                                "')");
    }
  }
  DRILLBIF_RETURN_IF_ERROR(connection.Exec(options.full_sync ? "PRAGMA synchronous = FULL"
                                                         : "PRAGMA synchronous = NORMAL"));
  DRILLBIF_RETURN_IF_ERROR(connection.Exec("PRAGMA foreign_keys = ON"));
  DRILLBIF_RETURN_IF_ERROR(store->Migrate());
  return std::unique_ptr<JobStore>(std::move(store));
}

}  // namespace drillbif::server
