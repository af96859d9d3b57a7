// SqliteJobStore: the embedded JobStore, one SQLite file (docs/store.md: schema, transactions).
//
// - WAL journal: readers never block the writer, and a commit is one append to the WAL.
// - Every writing transaction starts with BEGIN IMMEDIATE: it takes the write lock up front, so
//   two connections (threads of another store object, or another process) never both read and
//   then fail to upgrade to a writer; a waiting writer retries for busy_timeout_ms.
// - The schema is versioned by PRAGMA user_version and migrated on Open (one list of migrations
//   in sqlite_job_store.cc). A file written by a newer build is refused.
// - Thread safety: one connection, every method holds one mutex for its whole duration (Evict
//   takes it per batch). SQLite serializes writers anyway, and the statements are short (no
//   engine work happens inside), so a connection pool would add complexity without throughput.
// - Errors carry client-readable messages without SQL; the details go to options.log.
#ifndef DRILLBIF_SERVER_STORE_SQLITE_JOB_STORE_H_
#define DRILLBIF_SERVER_STORE_SQLITE_JOB_STORE_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>

#include "drillbif/common/status.h"
#include "server/store/job_store.h"

namespace drillbif::server {

// How to open the SQLite store.
struct SqliteJobStoreOptions {
  // How long a writer waits for another connection's write lock before giving up (UNAVAILABLE
  // "the job store is busy"). 5 s: far above any transaction of this store (they take
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
  // Run PRAGMA quick_check on an existing file before using it; a file that fails is refused
  // with DATA_LOSS and left untouched. It reads the whole file (about 0.1 s per 100 MB measured,
  // docs/store.md), once per start: cheap next to serving a corrupt store.
  bool integrity_check_at_open = true;
  // PRAGMA journal_size_limit, in bytes: after a checkpoint resets the WAL it is truncated to
  // this size, so a burst of large writes does not keep its disk space. 16 MiB: the WAL is
  // checkpointed every 1000 pages (4 MiB), so normal use never truncates.
  int64_t wal_size_limit_bytes = 16 << 20;
  // After a full disk, Probe() succeeds only once the file system holding the store has at least
  // this many bytes free (statvfs): a write of a page or two fits in what the failed write left,
  // so a probe that only writes would report recovery while the next result chunk still fails,
  // and health would flap. 1 MiB: a result chunk of the worker pool
  // (WorkerPoolOptions::chunk_bytes), the largest write the server makes routinely. 0: none.
  int64_t min_free_bytes_after_full = 1 << 20;
  // Details of every SQLite error (statement, SQLite's message and code) and of faults and their
  // recovery, one line per call; empty: dropped. Status messages never hold them. Called with the
  // store's lock held: it must not call the store.
  std::function<void(std::string_view)> log;

  // INVALID_ARGUMENT naming the field when a value is out of range.
  Status Validate() const;
};

// Factory for the SQLite JobStore.
class SqliteJobStore {
 public:
  // Highest schema version (PRAGMA user_version) this build knows.
  static constexpr int kSchemaVersion = 4;
  // PRAGMA application_id of drillbif store files ("DBif"), so that another program's SQLite
  // file is refused instead of being migrated.
  static constexpr int kApplicationId = 0x44426966;

  // Opens (creating if needed) the store at `path` and migrates its schema to kSchemaVersion.
  // A new file gets auto_vacuum = INCREMENTAL (Evict gives freed space back to the disk).
  // Errors: INVALID_ARGUMENT for bad options or an empty path; DATA_LOSS for a file that fails
  // the integrity check or is not a database (nothing modified); FAILED_PRECONDITION for a file
  // of a newer schema version or another application, or when WAL mode cannot be enabled (e.g.
  // a file system without shared memory); UNAVAILABLE when the file cannot be opened;
  // RESOURCE_EXHAUSTED for a full disk. Messages name the path, never SQL. Does not recover
  // RUNNING jobs: call RecoverAfterRestart when this process owns it.
  static StatusOr<std::unique_ptr<JobStore>> Open(const std::string& path,
                                                  const SqliteJobStoreOptions& options = {});
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_STORE_SQLITE_JOB_STORE_H_
