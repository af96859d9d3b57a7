// SqliteJobStore: the embedded JobStore, one SQLite file (docs/store.md: schema, transactions).
//
// - WAL journal: readers never block the writer, and a commit is one append to the WAL.
// - Every writing transaction starts with BEGIN IMMEDIATE: it takes the write lock up front, so
//   two connections (threads of another store object, or another process) never both read and
//   then fail to upgrade to a writer; a waiting writer retries for busy_timeout_ms.
// - The schema is versioned by PRAGMA user_version and migrated on Open (one list of migrations
//   in sqlite_job_store.cc). A file written by a newer build is refused.
// - Thread safety: one connection, every method holds one mutex for its whole duration. SQLite
//   serializes writers anyway, and the statements are short (no engine work happens inside), so
//   a connection pool would add complexity without throughput.
#ifndef DRILLBIF_SERVER_STORE_SQLITE_JOB_STORE_H_
#define DRILLBIF_SERVER_STORE_SQLITE_JOB_STORE_H_

#include <memory>
#include <string>

#include "drillbif/common/status.h"
#include "server/store/job_store.h"

namespace drillbif::server {

// How to open the SQLite store.
struct SqliteJobStoreOptions {
  // How long a writer waits for another connection's write lock before giving up (INTERNAL
  // "database is locked"). 5 s: far above any transaction of this store (they take
  // microseconds to a few milliseconds), so it only fires when something is stuck.
  int busy_timeout_ms = 5000;
  // PRAGMA synchronous: true = FULL (every commit is fsynced: a finished result survives a power
  // loss, not only kill -9); false = NORMAL (in WAL mode a commit survives kill -9 of the process,
  // since it is in the OS page cache, but the last commits can roll back on power loss; faster).
  // FULL by default because the service promises that no finished result is lost.
  bool full_sync = true;
  // A job found RUNNING by RecoverAfterRestart after this many claims is failed, not requeued:
  // a request that crashes the process must not crash it forever. 3 tolerates two unrelated
  // crashes.
  int max_attempts = 3;
  // List page size when the request gives 0.
  int default_page_size = 50;
  // Largest List page (larger requests are capped, as AIP-158 suggests).
  int max_page_size = 1000;

  // INVALID_ARGUMENT naming the field when a value is out of range.
  Status Validate() const;
};

// Factory for the SQLite JobStore.
class SqliteJobStore {
 public:
  // Highest schema version (PRAGMA user_version) this build knows.
  static constexpr int kSchemaVersion = 1;
  // PRAGMA application_id of drillbif store files ("DBif"), so that another program's SQLite
  // file is refused instead of being migrated.
  static constexpr int kApplicationId = 0x44426966;

  // Opens (creating if needed) the store at `path` and migrates its schema to kSchemaVersion.
  // Errors: INVALID_ARGUMENT for bad options or an empty path; FAILED_PRECONDITION for a file of
  // a newer schema version or another application, or when WAL mode cannot be enabled (e.g. a
  // file system without shared memory); INTERNAL for I/O and SQLite errors (the message says
  // which). Does not recover RUNNING jobs: call RecoverAfterRestart when this process owns it.
  static StatusOr<std::unique_ptr<JobStore>> Open(const std::string& path,
                                                  const SqliteJobStoreOptions& options = {});
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_STORE_SQLITE_JOB_STORE_H_
