// The PostgreSQL JobStore's implementation class (internal to server/store/; users include
// postgres_job_store.h). Its methods are split by topic as the SQLite store's are:
// - postgres_job_store.cc: connecting, the schema, transactions and errors, the job life cycle
//   (submit, claim, finish, cancel, recovery), listing and stats;
// - postgres_store_results.cc: streamed result chunks, completion and result reads;
// - postgres_store_maintenance.cc: health, probe, deletion and retention.
#ifndef DRILLBIF_SERVER_STORE_POSTGRES_STORE_IMPL_H_
#define DRILLBIF_SERVER_STORE_POSTGRES_STORE_IMPL_H_

#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <pqxx/pqxx>
#include <random>
#include <string>
#include <string_view>
#include <vector>

#include "drillbif/common/status.h"
#include "server/store/job_store.h"
#include "server/store/postgres_job_store.h"
#include "server/store/store_checks.h"

namespace drillbif::server {

class PostgresStoreImpl final : public JobStore {
 public:
  PostgresStoreImpl(std::string uri, const PostgresJobStoreOptions& options)
      : uri_(std::move(uri)), options_(options) {}

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
  // A feed on a connection of its own (postgres_change_feed.h).
  StatusOr<std::unique_ptr<JobChangeFeed>> OpenChangeFeed(JobChangeCallback on_change) override;

  // Open's step after construction: connects and creates or checks the schema.
  Status Configure();

 private:
  using Tx = pqxx::transaction_base;

  // Runs `body` in a transaction on the store's connection, with mu_ held: a writing one
  // (read committed, serialized across processes by the store's advisory lock) or a read-only
  // snapshot (repeatable read). Commits when body returns OK; database errors (exceptions)
  // become a Status with a client-readable message, their details going to options_.log.
  // `what` names the operation in those messages.
  template <typename T>
  StatusOr<T> Write(const char* what, const std::function<StatusOr<T>(Tx&)>& body);
  template <typename T>
  StatusOr<T> Read(const char* what, const std::function<StatusOr<T>(Tx&)>& body);
  // A read of one statement, outside a transaction (a statement sees one snapshot by itself):
  // one round trip to the server where a read-only transaction takes three.
  template <typename T>
  StatusOr<T> ReadStatement(const char* what, const std::function<StatusOr<T>(Tx&)>& body);
  // A writing transaction that does not take the store's write lock: claims, which lock the
  // rows they take instead.
  template <typename T>
  StatusOr<T> Claim(const char* what, const std::function<StatusOr<T>(Tx&)>& body);
  // Write for a body that returns only a Status.
  Status WriteStatus(const char* what, const std::function<Status(Tx&)>& body) {
    return Write<bool>(what,
                       [&](Tx& tx) -> StatusOr<bool> {
                         DRILLBIF_RETURN_IF_ERROR(body(tx));
                         return true;
                       })
        .status();
  }
  template <typename T, typename Transaction>
  StatusOr<T> Run(const char* what, bool lock, const std::function<StatusOr<T>(Tx&)>& body);
  // The connection, opened (again) when there is none or it broke.
  pqxx::connection& Connection();
  // The Status for a database error thrown while doing `what`; records faults for Health().
  Status Error(const char* what, const std::exception& error);
  void Log(const std::string& line) const;

  // All helpers below run inside a transaction the caller holds.
  StatusOr<JobHead> Head(Tx& tx, std::string_view id);
  StatusOr<JobHead> RunningHead(Tx& tx, std::string_view id, const char* action, int64_t run);
  // Runs `update` ($1 is the id; its WHERE must check state = 1) with `more` parameters bound
  // after it; FAILED_PRECONDITION unless exactly one row changed.
  template <typename... Args>
  Status UpdateRunning(Tx& tx, const std::string& update, std::string_view id, Args&&... more);
  Status PromoteFollower(Tx& tx, std::string_view id);
  Status RequeueWithFollowers(Tx& tx, std::string_view id, bool count_attempt);
  Status FailWithFollowers(Tx& tx, std::string_view id, StatusCode code, std::string_view message);
  Status CancelRunning(Tx& tx, std::string_view id);
  // Parent `id` leaves RUNNING, or is being cancelled: its QUEUED children become CANCELLED and
  // its RUNNING ones get cancel_requested, including one a concurrent claim takes meanwhile.
  Status CancelChildren(Tx& tx, std::string_view id);
  StatusOr<RecoveryReport> TakeBack(TakenBack why, int64_t now_ms);
  Status CheckQueueLimits(Tx& tx, const SubmitRequest& request);
  Status DropRunChunks(Tx& tx, std::string_view id);
  StatusOr<bool> DeleteJobAndOrphanResult(Tx& tx, std::string_view id,
                                          const std::string& result_key);
  struct ResultRow {
    std::string run_id;  // Whose chunks form the result.
    int64_t items = 0;
    ResultInfo info;
  };
  StatusOr<ResultRow> ReadResultRow(Tx& tx, std::string_view id, bool with_summary);
  // The bytes of the stored data: requests, results (summaries and chunks) and the chunks of
  // runs still going.
  StatusOr<int64_t> UsedBytes(Tx& tx);
  // What the store's tables occupy on disk.
  StatusOr<int64_t> DiskBytes(Tx& tx);
  Status EvictOldest(int64_t finished_before, int64_t max_used_bytes, EvictionReport* report);

  std::mutex mu_;
  std::unique_ptr<pqxx::connection> connection_;
  Status fault_;  // What Health() reports: the last connection or disk fault until Probe().
  const std::string uri_;
  const PostgresJobStoreOptions options_;
  std::random_device random_;
};

// ---------------------------------------------------------------------------------------------
// Template definitions (used by every postgres_*.cc).

// Key of the advisory lock that serializes the store's writing transactions (any 64-bit value
// no other application on the database uses: "DBifJobs" in ASCII).
inline constexpr int64_t kWriteLockKey = 0x444269664a6f6273;

template <typename T, typename Transaction>
StatusOr<T> PostgresStoreImpl::Run(const char* what, bool lock,
                                   const std::function<StatusOr<T>(Tx&)>& body) {
  std::lock_guard<std::mutex> guard(mu_);
  // A transaction the server rolled back to break a deadlock (or a serialization failure) did
  // nothing: it is run again, a few times.
  for (int attempt = 1;; ++attempt) {
    try {
      Transaction tx(Connection());
      if (lock) tx.exec_params("SELECT pg_advisory_xact_lock($1)", kWriteLockKey);
      StatusOr<T> result = body(tx);
      if (result.ok()) tx.commit();
      return result;
    } catch (const pqxx::transaction_rollback& error) {
      if (attempt == 3) return Error(what, error);
      Log(std::string("job store: ") + what + ": retried after " + error.what());
    } catch (const std::exception& error) {
      return Error(what, error);
    }
  }
}

template <typename T>
StatusOr<T> PostgresStoreImpl::Write(const char* what,
                                     const std::function<StatusOr<T>(Tx&)>& body) {
  return Run<T, pqxx::work>(what, /*lock=*/true, body);
}

template <typename T>
StatusOr<T> PostgresStoreImpl::ReadStatement(const char* what,
                                             const std::function<StatusOr<T>(Tx&)>& body) {
  return Run<T, pqxx::nontransaction>(what, /*lock=*/false, body);
}

template <typename T>
StatusOr<T> PostgresStoreImpl::Claim(const char* what,
                                     const std::function<StatusOr<T>(Tx&)>& body) {
  return Run<T, pqxx::work>(what, /*lock=*/false, body);
}

template <typename T>
StatusOr<T> PostgresStoreImpl::Read(const char* what, const std::function<StatusOr<T>(Tx&)>& body) {
  return Run<T, pqxx::transaction<pqxx::repeatable_read, pqxx::read_only>>(what, /*lock=*/false,
                                                                           body);
}

template <typename... Args>
Status PostgresStoreImpl::UpdateRunning(Tx& tx, const std::string& update, std::string_view id,
                                        Args&&... more) {
  const pqxx::result r = tx.exec_params(update, std::string(id), std::forward<Args>(more)...);
  if (r.affected_rows() != 1) {
    return FailedPrecondition("job '" + std::string(id) + "' is no longer RUNNING");
  }
  return Status::Ok();
}

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_STORE_POSTGRES_STORE_IMPL_H_
