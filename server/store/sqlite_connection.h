// A thin RAII layer over SQLite's C API for the job store (internal to server/store/): one
// connection with a cache of prepared statements, queries with bound parameters, transactions,
// and the translation of SQLite errors into Status codes.
//
// Errors: a failing SQLite call becomes a Status whose message a client can read and that never
// holds SQL text or SQLite's own message (MapSqliteCode); the details (the statement, SQLite's
// message and extended code) go to the connection's log callback. Errors that leave the store
// unusable (full disk, I/O error, corruption, read-only file) are recorded as the connection's
// fault, which stays until ClearFault (the store's Probe). After a disk-full error the WAL is
// checkpointed and truncated (best effort) once the failed transaction is rolled back, so that
// the space a failed large write took in the WAL is given back.
#ifndef DRILLBIF_SERVER_STORE_SQLITE_CONNECTION_H_
#define DRILLBIF_SERVER_STORE_SQLITE_CONNECTION_H_

#include <sqlite3.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <unordered_map>

#include "drillbif/common/status.h"

namespace drillbif::server::sqlite {

// Receives one line of detail per SQLite error or notable event (the server routes it to its
// log). Called with the store's lock held: it must not call the store.
using LogFunction = std::function<void(std::string_view)>;

// The Status a client sees for an SQLite result code (primary or extended): SQLITE_FULL ->
// RESOURCE_EXHAUSTED "the job store's disk is full"; SQLITE_CORRUPT, SQLITE_NOTADB -> DATA_LOSS;
// SQLITE_BUSY, SQLITE_LOCKED -> UNAVAILABLE; SQLITE_IOERR*, SQLITE_CANTOPEN, SQLITE_READONLY ->
// UNAVAILABLE "the job store cannot read or write its file"; SQLITE_TOOBIG -> INVALID_ARGUMENT;
// SQLITE_NOMEM -> RESOURCE_EXHAUSTED; anything else INTERNAL "job store error".
Status MapSqliteCode(int rc);

// True for the codes after which the store is unusable until a probe succeeds: FULL, IOERR,
// CANTOPEN, READONLY, CORRUPT, NOTADB.
bool IsFaultCode(int rc);

class Connection;

// A cached prepared statement in use: binds parameters (1-based, as in SQL's ?N), steps, reads
// columns, and resets the statement when it goes out of scope so the cache can hand it out again
// (a statement left mid-step would also keep a read transaction open).
class Query {
 public:
  Query(Connection* connection, sqlite3_stmt* statement)
      : connection_(connection), statement_(statement) {}
  Query(Query&& other) noexcept;
  Query(const Query&) = delete;
  Query& operator=(const Query&) = delete;
  Query& operator=(Query&&) = delete;
  ~Query();

  Query& Bind(int index, int64_t value);
  Query& Bind(int index, int value) { return Bind(index, static_cast<int64_t>(value)); }
  Query& Bind(int index, double value);
  // A double, or NULL when empty.
  Query& Bind(int index, std::optional<double> value);
  // Text (never NULL: an empty string binds '').
  Query& Bind(int index, std::string_view text);
  Query& Bind(int index, const char* text) { return Bind(index, std::string_view(text)); }
  Query& Bind(int index, const std::string& text) { return Bind(index, std::string_view(text)); }
  Query& BindNull(int index);
  // Text, or NULL when empty.
  Query& BindOrNull(int index, std::string_view text) {
    return text.empty() ? BindNull(index) : Bind(index, text);
  }
  Query& BindBlob(int index, std::string_view bytes);

  // Steps once: true with a row to read, false when done.
  StatusOr<bool> Step();
  // Runs a statement that returns no rows (or whose rows are not needed).
  Status Run();

  int64_t Int(int column) const { return sqlite3_column_int64(statement_, column); }
  double Double(int column) const { return sqlite3_column_double(statement_, column); }
  bool IsNull(int column) const { return sqlite3_column_type(statement_, column) == SQLITE_NULL; }
  std::string Text(int column) const;
  std::string Blob(int column) const;
  // Appends a BLOB column to `out` (no temporary copy).
  void AppendBlob(int column, std::string& out) const;

 private:
  // Keeps the first bind error; Step reports it.
  void Check(int rc) {
    if (rc_ == SQLITE_OK) rc_ = rc;
  }

  Connection* connection_;
  sqlite3_stmt* statement_;
  int rc_ = SQLITE_OK;
};

// One connection with a cache of prepared statements (keyed by their SQL text), the error
// translation and the fault record. Not thread-safe except Fault(): the store serializes all
// other use with its own mutex.
class Connection {
 public:
  Connection(sqlite3* db, LogFunction log) : db_(db), log_(std::move(log)) {}
  Connection(const Connection&) = delete;
  Connection& operator=(const Connection&) = delete;
  ~Connection();

  sqlite3* db() const { return db_; }

  StatusOr<Query> Prepare(const std::string& sql);

  // Runs SQL text without parameters (pragmas, migrations; may hold several statements).
  Status Exec(const char* sql);

  // Rows changed by the last INSERT/UPDATE/DELETE.
  int Changes() const { return sqlite3_changes(db_); }

  // The Status for SQLite code `rc` raised while doing `what` (SQL text or an operation name):
  // logs the details, records a fault for IsFaultCode codes, and asks for a WAL checkpoint after
  // a disk-full error.
  Status Error(int rc, std::string_view what);

  // Sends a line to the log callback (if any).
  void Log(std::string_view message) const;

  // OK, or the fault recorded since the last ClearFault (thread-safe). A DATA_LOSS fault is kept
  // over any later one: corruption does not heal by itself.
  Status Fault() const;
  void ClearFault();

  // After a disk-full error, once no transaction is open: PRAGMA wal_checkpoint(TRUNCATE), best
  // effort (logged), so the WAL does not keep the space the failed write took.
  void CheckpointIfRequested();

  // PRAGMA wal_checkpoint(mode) ("PASSIVE", "TRUNCATE"); SQLITE_BUSY (another connection
  // reading) is reported as UNAVAILABLE.
  Status Checkpoint(const char* mode);

 private:
  void RecordFault(const Status& status);

  sqlite3* db_;
  const LogFunction log_;
  std::unordered_map<std::string, std::unique_ptr<sqlite3_stmt, int (*)(sqlite3_stmt*)>>
      statements_;
  bool checkpoint_requested_ = false;
  mutable std::mutex fault_mu_;
  Status fault_;
};

// A transaction: BEGIN IMMEDIATE for writers (take the write lock before reading, so the checks
// and the writes that depend on them are atomic across connections), plain BEGIN for readers
// that need one snapshot across statements. Rolled back unless committed; then runs the
// checkpoint a disk-full error asked for.
class Transaction {
 public:
  static StatusOr<Transaction> Begin(Connection& connection, bool write);
  Transaction(Transaction&& other) noexcept
      : connection_(other.connection_), open_(std::exchange(other.open_, false)) {}
  Transaction(const Transaction&) = delete;
  Transaction& operator=(const Transaction&) = delete;
  Transaction& operator=(Transaction&&) = delete;
  ~Transaction();

  Status Commit();

 private:
  explicit Transaction(Connection& connection) : connection_(&connection) {}

  Connection* connection_;
  bool open_ = true;
};

}  // namespace drillbif::server::sqlite

#endif  // DRILLBIF_SERVER_STORE_SQLITE_CONNECTION_H_
