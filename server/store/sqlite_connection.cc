#include "server/store/sqlite_connection.h"

#include <string>
#include <utility>

namespace drillbif::server::sqlite {

Status MapSqliteCode(int rc) {
  switch (rc & 0xff) {
    case SQLITE_FULL:
      return ResourceExhausted("the job store's disk is full");
    case SQLITE_NOMEM:
      return ResourceExhausted("the job store ran out of memory");
    case SQLITE_CORRUPT:
      return Status(StatusCode::kDataLoss, "the job store is corrupt");
    case SQLITE_NOTADB:
      return Status(StatusCode::kDataLoss, "the job store is corrupt (its file is not a database)");
    case SQLITE_BUSY:
    case SQLITE_LOCKED:
      return Unavailable("the job store is busy; retry later");
    case SQLITE_IOERR:
    case SQLITE_CANTOPEN:
    case SQLITE_READONLY:
      return Unavailable("the job store cannot read or write its file");
    case SQLITE_TOOBIG:
      return InvalidArgument("a value is larger than the job store accepts");
    default:
      return Internal("job store error");
  }
}

bool IsFaultCode(int rc) {
  switch (rc & 0xff) {
    case SQLITE_FULL:
    case SQLITE_IOERR:
    case SQLITE_CANTOPEN:
    case SQLITE_READONLY:
    case SQLITE_CORRUPT:
    case SQLITE_NOTADB:
      return true;
    default:
      return false;
  }
}

// ---------------------------------------------------------------------------------------------

Query::Query(Query&& other) noexcept
    : connection_(other.connection_),
      statement_(std::exchange(other.statement_, nullptr)),
      rc_(other.rc_) {}

Query::~Query() {
  if (statement_ != nullptr) {
    sqlite3_reset(statement_);
    sqlite3_clear_bindings(statement_);
  }
}

Query& Query::Bind(int index, int64_t value) {
  Check(sqlite3_bind_int64(statement_, index, value));
  return *this;
}

Query& Query::Bind(int index, double value) {
  Check(sqlite3_bind_double(statement_, index, value));
  return *this;
}

Query& Query::Bind(int index, std::optional<double> value) {
  Check(value ? sqlite3_bind_double(statement_, index, *value)
              : sqlite3_bind_null(statement_, index));
  return *this;
}

Query& Query::Bind(int index, std::string_view text) {
  // A null data pointer (empty string_view) would bind NULL, so bind "" explicitly. The 64-bit
  // length cannot wrap; SQLite answers SQLITE_TOOBIG beyond its limit.
  Check(sqlite3_bind_text64(statement_, index, text.empty() ? "" : text.data(),
                            static_cast<sqlite3_uint64>(text.size()), SQLITE_TRANSIENT,
                            SQLITE_UTF8));
  return *this;
}

Query& Query::BindNull(int index) {
  Check(sqlite3_bind_null(statement_, index));
  return *this;
}

Query& Query::BindBlob(int index, std::string_view bytes) {
  Check(bytes.empty()
            ? sqlite3_bind_zeroblob(statement_, index, 0)
            : sqlite3_bind_blob64(statement_, index, bytes.data(),
                                  static_cast<sqlite3_uint64>(bytes.size()), SQLITE_TRANSIENT));
  return *this;
}

StatusOr<bool> Query::Step() {
  if (rc_ != SQLITE_OK) return connection_->Error(rc_, "binding parameters");
  const int rc = sqlite3_step(statement_);
  if (rc == SQLITE_ROW) return true;
  if (rc == SQLITE_DONE) return false;
  return connection_->Error(rc, sqlite3_sql(statement_));
}

Status Query::Run() {
  StatusOr<bool> row = Step();
  return row.status();
}

std::string Query::Text(int column) const {
  const unsigned char* text = sqlite3_column_text(statement_, column);
  if (text == nullptr) return std::string();
  return std::string(reinterpret_cast<const char*>(text),
                     static_cast<size_t>(sqlite3_column_bytes(statement_, column)));
}

std::string Query::Blob(int column) const {
  std::string out;
  AppendBlob(column, out);
  return out;
}

void Query::AppendBlob(int column, std::string& out) const {
  const void* data = sqlite3_column_blob(statement_, column);
  if (data == nullptr) return;
  out.append(static_cast<const char*>(data),
             static_cast<size_t>(sqlite3_column_bytes(statement_, column)));
}

// ---------------------------------------------------------------------------------------------

Connection::~Connection() {
  statements_.clear();  // Finalize before closing, or sqlite3_close fails with SQLITE_BUSY.
  sqlite3_close(db_);
}

StatusOr<Query> Connection::Prepare(const std::string& sql) {
  auto it = statements_.find(sql);
  if (it == statements_.end()) {
    sqlite3_stmt* statement = nullptr;
    const int rc = sqlite3_prepare_v3(db_, sql.c_str(), static_cast<int>(sql.size() + 1),
                                      SQLITE_PREPARE_PERSISTENT, &statement, nullptr);
    if (rc != SQLITE_OK) return Error(rc, sql);
    it = statements_
             .emplace(sql, std::unique_ptr<sqlite3_stmt, int (*)(sqlite3_stmt*)>(statement,
                                                                                 &sqlite3_finalize))
             .first;
  }
  return Query(this, it->second.get());
}

Status Connection::Exec(const char* sql) {
  const int rc = sqlite3_exec(db_, sql, nullptr, nullptr, nullptr);
  if (rc != SQLITE_OK) return Error(rc, sql);
  return Status::Ok();
}

Status Connection::Error(int rc, std::string_view what) {
  Status status = MapSqliteCode(rc);
  std::string detail = "job store: SQLite error ";
  detail += std::to_string(rc);
  detail += " (";
  detail += sqlite3_errstr(rc);
  detail += "): ";
  detail += sqlite3_errmsg(db_);
  detail += "; in: ";
  detail += what;
  Log(detail);
  if (IsFaultCode(rc)) RecordFault(status);
  if ((rc & 0xff) == SQLITE_FULL) checkpoint_requested_ = true;
  return status;
}

void Connection::Log(std::string_view message) const {
  if (log_) log_(message);
}

Status Connection::Fault() const {
  std::lock_guard<std::mutex> lock(fault_mu_);
  return fault_;
}

void Connection::RecordFault(const Status& status) {
  std::lock_guard<std::mutex> lock(fault_mu_);
  if (fault_.code() != StatusCode::kDataLoss) fault_ = status;
}

void Connection::ClearFault() {
  std::lock_guard<std::mutex> lock(fault_mu_);
  fault_ = Status::Ok();
}

Status Connection::Checkpoint(const char* mode) {
  const std::string sql = std::string("PRAGMA wal_checkpoint(") + mode + ")";
  DRILLBIF_ASSIGN_OR_RETURN(Query q, Prepare(sql));
  DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
  // Row: busy flag, WAL frames, frames checkpointed. busy = 1 when another connection kept the
  // checkpoint from completing.
  if (row && q.Int(0) != 0) return Unavailable("the job store's WAL is in use; checkpoint later");
  return Status::Ok();
}

void Connection::CheckpointIfRequested() {
  if (!checkpoint_requested_ || sqlite3_get_autocommit(db_) == 0) return;
  checkpoint_requested_ = false;
  if (Status s = Checkpoint("TRUNCATE"); !s.ok()) {
    Log("job store: WAL checkpoint after a full disk failed: " + s.ToString());
  }
}

// ---------------------------------------------------------------------------------------------

StatusOr<Transaction> Transaction::Begin(Connection& connection, bool write) {
  DRILLBIF_RETURN_IF_ERROR(connection.Exec(write ? "BEGIN IMMEDIATE" : "BEGIN"));
  return Transaction(connection);
}

Transaction::~Transaction() {
  if (connection_ == nullptr) return;
  // Some errors (I/O, disk full) already rolled the transaction back; ROLLBACK would fail then.
  if (open_ && sqlite3_get_autocommit(connection_->db()) == 0) {
    // Best effort: the error being returned is the caller's; a failed rollback leaves nothing
    // committed either way.
    connection_->Exec("ROLLBACK").IgnoreError();
  }
  if (open_) connection_->CheckpointIfRequested();
}

Status Transaction::Commit() {
  DRILLBIF_RETURN_IF_ERROR(connection_->Exec("COMMIT"));
  open_ = false;
  return Status::Ok();
}

}  // namespace drillbif::server::sqlite
