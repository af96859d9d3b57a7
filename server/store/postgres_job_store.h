// PostgresJobStore: the JobStore on a PostgreSQL server (docs/store.md, PostgreSQL), for
// deployments where several server processes on several machines share one store. The embedded
// SQLite file (sqlite_job_store.h) stays the default for one machine.
//
// - The same contract as the SQLite store (job_store.h), checked by the same contract tests
//   (tests/server/job_store_test.cc and the store_*_test.cc suites run on both).
// - Writing transactions are serialized across every process by a transaction-scoped advisory
//   lock (pg_advisory_xact_lock), as SQLite's BEGIN IMMEDIATE serializes them on one file: each
//   transaction reads, checks and writes as if alone, so the state checks (exactly-once
//   completion, queue limits, request_id idempotency, sharing) hold across processes without
//   retry loops. The statements are short (no engine work happens inside).
// - Reads run in REPEATABLE READ read-only transactions: a result and its chunks, or the
//   counters, come from one snapshot; they never wait for writers.
// - Thread safety: one connection per store object, every method holds one mutex for its whole
//   duration. A lost connection is reported as UNAVAILABLE and reopened by the next call.
// - The schema is versioned by a row of drillbif_schema and created on Open; a database written
//   by a newer build is refused.
// - Errors carry client-readable messages without SQL; the details go to options.log.
// - Change feed (OpenChangeFeed): triggers on the jobs table notify every process that listens
//   of each submit, requeue and watched change as it commits (postgres_change_feed.h), so that
//   processes sharing the store need not poll it to hear of each other's work.
#ifndef DRILLBIF_SERVER_STORE_POSTGRES_JOB_STORE_H_
#define DRILLBIF_SERVER_STORE_POSTGRES_JOB_STORE_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "drillbif/common/status.h"
#include "server/store/job_store.h"

namespace drillbif::server {

// How to open the PostgreSQL store.
struct PostgresJobStoreOptions {
  // A job found RUNNING by RecoverAfterRestart after this many claims is failed, not requeued
  // (as SqliteJobStoreOptions::max_attempts).
  int max_attempts = 3;
  // List page size when the request gives 0.
  int default_page_size = 50;
  // Largest List page (larger requests are capped, as AIP-158 suggests).
  int max_page_size = 1000;
  // The server ends a session of this store that sits inside a transaction for this long
  // (idle_in_transaction_session_timeout), rolling it back. The store's transactions take
  // milliseconds; a process paused inside one (SIGSTOP, a frozen VM) would hold the store's
  // write lock, and every other process would wait on it until the pause ends. Milliseconds;
  // 2000: far above any transaction, far below a lease.
  int idle_in_transaction_timeout_ms = 2000;
  // The password, when the URI has none; never part of the URI given on a command line (it
  // would show in the process list). Empty: none (trust, peer or .pgpass authentication).
  std::string password;
  // Details of every database error (SQLSTATE and the server's message) and of faults and their
  // recovery, one line per call; empty: dropped. Status messages never hold them. Called with
  // the store's lock held: it must not call the store.
  std::function<void(std::string_view)> log;

  // INVALID_ARGUMENT naming the field when a value is out of range.
  Status Validate() const;
};

// Factory for the PostgreSQL JobStore.
class PostgresJobStore {
 public:
  // Highest schema version this build knows.
  static constexpr int kSchemaVersion = 3;
  // Bytes of the largest value (request, chunk, summary) the store accepts: PostgreSQL's limit
  // on one bytea field is 1 GiB; a little less leaves room for the protocol's framing.
  static constexpr int64_t kMaxValueBytes = 1'000'000'000;

  // Connects to the database named by `uri` (a libpq connection URI,
  // postgresql://USER@HOST:PORT/DB?..., or key=value pairs) and creates or checks the schema.
  // Errors: INVALID_ARGUMENT for bad options or an empty URI; UNAVAILABLE when the server cannot
  // be reached or refuses the login; FAILED_PRECONDITION for a schema of a newer version.
  // Messages never hold the password. Does not recover RUNNING jobs: call RecoverAfterRestart
  // when this process owns them.
  static StatusOr<std::unique_ptr<JobStore>> Open(const std::string& uri,
                                                  const PostgresJobStoreOptions& options = {});
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_STORE_POSTGRES_JOB_STORE_H_
