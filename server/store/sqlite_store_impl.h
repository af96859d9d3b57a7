// The SQLite JobStore's implementation class (internal to server/store/; users include
// sqlite_job_store.h). Its methods are split by topic:
// - sqlite_job_store.cc: opening, migrations, the job life cycle (submit, claim, finish, cancel,
//   recovery), listing and stats;
// - sqlite_store_results.cc: streamed result chunks, completion and result reads;
// - sqlite_store_maintenance.cc: health, probe, integrity check, deletion and retention.
// Schema and semantics: docs/store.md.
#ifndef DRILLBIF_SERVER_STORE_SQLITE_STORE_IMPL_H_
#define DRILLBIF_SERVER_STORE_SQLITE_STORE_IMPL_H_

#include <sqlite3.h>

#include <cstdint>
#include <functional>
#include <mutex>
#include <optional>
#include <random>
#include <string>
#include <string_view>

#include "drillbif/common/status.h"
#include "server/store/job_store.h"
#include "server/store/sqlite_connection.h"
#include "server/store/sqlite_job_store.h"
#include "server/store/store_checks.h"

namespace drillbif::server {

// PRAGMA quick_check on the existing file at `path`, through a read-only connection (nothing is
// written, not even a WAL checkpoint): OK for a missing or empty file or a sound one; DATA_LOSS
// "the job store failed its integrity check: <first problem>" otherwise.
Status CheckIntegrity(const std::string& path, const sqlite::LogFunction& log);

class SqliteStoreImpl final : public JobStore {
 public:
  SqliteStoreImpl(sqlite3* db, std::string path, const SqliteJobStoreOptions& options)
      : connection_(db, options.log), path_(std::move(path)), options_(options) {}

  using JobStore::ClaimNext;
  using JobStore::Complete;
  using JobStore::Fail;
  using JobStore::Get;
  using JobStore::MarkCancelled;
  using JobStore::Requeue;
  using JobStore::UpdateProgress;

  StatusOr<SubmitResult> Submit(const SubmitRequest& request) override;
  StatusOr<std::optional<JobRecord>> ClaimNext(std::string_view worker_id,
                                               const ClaimOptions& options) override;
  Status UpdateProgress(std::string_view id, int64_t run, double fraction,
                        std::optional<double> current_value, int64_t points) override;
  Status AppendResultChunk(std::string_view id, int64_t run, int stream, int64_t first_item,
                           int64_t item_count, std::string_view bytes) override;
  Status Complete(std::string_view id, int64_t run, std::string_view summary,
                  int64_t points) override;
  Status Fail(std::string_view id, int64_t run, StatusCode code, std::string_view message) override;
  StatusOr<JobState> Cancel(std::string_view id) override;
  StatusOr<bool> IsCancelRequested(std::string_view id) override;
  Status MarkCancelled(std::string_view id, int64_t run) override;
  Status Requeue(std::string_view id, int64_t run) override;
  StatusOr<JobRecord> Get(std::string_view id, bool include_request) override;
  StatusOr<ListResult> List(const ListRequest& request) override;
  Status Delete(std::string_view id) override;
  StatusOr<std::optional<std::string>> FindSucceeded(std::string_view cache_key) override;
  StatusOr<std::string> GetResult(std::string_view id) override;
  StatusOr<ResultInfo> GetResultInfo(std::string_view id) override;
  StatusOr<std::vector<ResultChunk>> ReadResultChunks(std::string_view id, int stream,
                                                      int64_t first_item,
                                                      int64_t max_bytes) override;
  StatusOr<RecoveryReport> RecoverAfterRestart() override;
  Status RenewLease(std::string_view id, int64_t run, int64_t lease_ms) override;
  StatusOr<RecoveryReport> ReclaimExpiredLeases(int64_t now_ms) override;
  StatusOr<StoreStats> Stats() override;
  Status Health() override;
  Status Probe() override;
  StatusOr<EvictionReport> Evict(const RetentionOptions& options, int64_t now_ms) override;

  // Open's steps after the connection is open, before the store is shared: pragmas and schema
  // migration.
  Status Configure();

 private:
  // All helpers below run inside a transaction the caller holds, with mu_ locked.
  StatusOr<JobHead> Head(std::string_view id);
  // The job must be RUNNING, run itself (not share another) and, unless run is kAnyRun, be at
  // that run: only the worker of its current run acts on it.
  StatusOr<JobHead> RunningHead(std::string_view id, const char* action, int64_t run);
  // Changes `id` from RUNNING by `update` (its ?1 is the id); FAILED_PRECONDITION unless exactly
  // one row changed. The state check sits in the UPDATE's WHERE, so even a bug in the checks
  // before it cannot finish a job twice.
  Status UpdateRunning(const std::string& update, std::string_view id,
                       const std::function<void(sqlite::Query&)>& bind);
  // The jobs following `id` are no longer served by it (it was cancelled): the oldest becomes a
  // QUEUED job of its own and the others follow it.
  Status PromoteFollower(std::string_view id);
  // The jobs following `id` go back to QUEUED with it; its run's chunks are dropped.
  Status RequeueWithFollowers(std::string_view id, bool count_attempt);
  Status FailWithFollowers(std::string_view id, StatusCode code, std::string_view message);
  Status CancelRunning(std::string_view id);
  // Parent `id` leaves RUNNING, or is being cancelled: its QUEUED children become CANCELLED and
  // its RUNNING ones get cancel_requested (their workers stop them and call MarkCancelled).
  Status CancelChildren(std::string_view id);
  // RecoverAfterRestart (every RUNNING job) and ReclaimExpiredLeases (those whose lease expired
  // before now_ms).
  StatusOr<RecoveryReport> TakeBack(TakenBack why, int64_t now_ms);
  // RESOURCE_EXHAUSTED when a new QUEUED job would exceed the request's queue limits.
  Status CheckQueueLimits(const SubmitRequest& request);
  // Deletes the chunks appended by the current run of `id` (a run that will not complete).
  Status DropRunChunks(std::string_view id);
  // Deletes job `id` (finished) and, when no job holds it any more, its result and chunks.
  // Returns whether the result went too.
  StatusOr<bool> DeleteJobAndOrphanResult(std::string_view id, const std::string& result_key);
  // The row of a SUCCEEDED job's result: NOT_FOUND / FAILED_PRECONDITION as GetResult.
  struct ResultRow {
    std::string run_id;  // Whose chunks form the result.
    int64_t items = 0;
    ResultInfo info;
  };
  StatusOr<ResultRow> ReadResultRow(std::string_view id, bool with_summary);
  // Appends the chunks of stream `stream` of `run_id` from the one containing `first_item`, until
  // `max_bytes` is reached (at least one chunk).
  Status ReadChunks(const std::string& run_id, int stream, int64_t first_item, int64_t max_bytes,
                    std::vector<ResultChunk>* chunks);
  // Items of each stream of `run_id`'s chunks.
  StatusOr<std::vector<int64_t>> StreamItems(const std::string& run_id);
  // (page_count - freelist_count) * page_size.
  StatusOr<int64_t> UsedBytes();
  // Bytes free for this process on the file system that holds the store (statvfs); -1 when
  // unknown.
  int64_t FreeDiskBytes() const;
  // The database file plus its WAL, in bytes (0 for missing files).
  int64_t DiskBytes() const;
  // Eviction steps; each takes mu_ per transaction, not for its whole duration.
  // Deletes evictable jobs finished before `finished_before`, oldest first, until none is left
  // or (max_used_bytes > 0) the used size is at most max_used_bytes.
  Status EvictOldest(int64_t finished_before, int64_t max_used_bytes, EvictionReport* report);
  // Incremental vacuum in bounded steps (files with auto_vacuum = INCREMENTAL), then a WAL
  // checkpoint with TRUNCATE.
  Status FreeSpace();
  // SQLite's limit on one string or BLOB (SQLITE_MAX_LENGTH, 10^9 bytes by default), read once
  // by Configure (reading it later would race with the connection's use by another thread).
  int64_t max_value_bytes_ = 0;

  std::mutex mu_;
  sqlite::Connection connection_;
  const std::string path_;
  const SqliteJobStoreOptions options_;
  std::random_device random_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_STORE_SQLITE_STORE_IMPL_H_
