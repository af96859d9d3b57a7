// The PostgreSQL JobStore's maintenance: health and probe, deletion and retention.
#include <cstdint>
#include <limits>
#include <optional>
#include <pqxx/pqxx>
#include <string>
#include <string_view>
#include <vector>

#include "drillbif/common/checked.h"
#include "server/store/postgres_store_impl.h"
#include "server/store/store_checks.h"

namespace drillbif::server {
namespace {

// An eviction transaction deletes at most kEvictBatch jobs and stops once it freed
// kEvictTransactionBytes, so that the write lock is released between transactions (as in the
// SQLite store).
constexpr int kEvictBatch = 256;
constexpr int64_t kEvictTransactionBytes = 4 << 20;

}  // namespace

Status PostgresStoreImpl::Health() {
  std::lock_guard<std::mutex> lock(mu_);
  return fault_;
}

Status PostgresStoreImpl::Probe() {
  // A small write and a read, on a connection opened again if it broke.
  Status probed = WriteStatus("probe the store", [&](Tx& tx) -> Status {
    tx.exec("UPDATE counters SET value = value + 1 WHERE name = 'probes'");
    tx.exec("SELECT COUNT(*) FROM jobs");
    return Status::Ok();
  });
  std::lock_guard<std::mutex> lock(mu_);
  if (!probed.ok()) return probed;
  if (!fault_.ok()) Log("job store: probe succeeded, fault cleared: " + fault_.ToString());
  fault_ = Status::Ok();
  return Status::Ok();
}

StatusOr<bool> PostgresStoreImpl::DeleteJobAndOrphanResult(Tx& tx, std::string_view id,
                                                           const std::string& result_key) {
  tx.exec_params("DELETE FROM jobs WHERE id = $1", std::string(id));
  // The result goes with its last job, and its chunks with it.
  const pqxx::result r = tx.exec_params(
      "DELETE FROM results WHERE result_key = $1 AND NOT EXISTS "
      "(SELECT 1 FROM jobs WHERE result_key = $1) RETURNING run_id",
      result_key);
  if (r.empty()) return false;
  const std::string run_id = r[0][0].as<std::string>();
  if (!run_id.empty()) tx.exec_params("DELETE FROM result_chunks WHERE run_id = $1", run_id);
  return true;
}

Status PostgresStoreImpl::Delete(std::string_view id) {
  return WriteStatus("delete a job", [&](Tx& tx) -> Status {
    DRILLBIF_ASSIGN_OR_RETURN(JobHead head, Head(tx, id));
    const auto state = static_cast<JobState>(head.state);
    if (!IsFinished(state)) return NotFinished(id, state);
    DRILLBIF_RETURN_IF_ERROR(DeleteJobAndOrphanResult(tx, id, head.result_key).status());
    // Its finished children go with it; any still stopping after its cancel are left to Evict,
    // which takes them once they finish (their parent is gone).
    const pqxx::result children = tx.exec_params(
        "SELECT id, result_key FROM jobs WHERE parent_id = $1 AND parent_id <> '' "
        "AND state IN (2, 3, 4)",
        std::string(id));
    for (const pqxx::row& child : children) {
      DRILLBIF_RETURN_IF_ERROR(
          DeleteJobAndOrphanResult(tx, child[0].as<std::string>(), child[1].as<std::string>())
              .status());
    }
    return Status::Ok();
  });
}

StatusOr<int64_t> PostgresStoreImpl::UsedBytes(Tx& tx) {
  // The data's own bytes, not the tables' pages: PostgreSQL gives a deleted row's space back
  // only when (auto)vacuum has run, so page counts would not follow an eviction.
  const pqxx::result r = tx.exec(
      "SELECT (SELECT COALESCE(SUM(octet_length(request)), 0) FROM jobs)"
      " + (SELECT COALESCE(SUM(bytes), 0) FROM results)"
      " + (SELECT COALESCE(SUM(streamed_bytes), 0) FROM jobs WHERE state = 1)");
  return r[0][0].as<int64_t>();
}

StatusOr<int64_t> PostgresStoreImpl::DiskBytes(Tx& tx) {
  const pqxx::result r = tx.exec(
      "SELECT pg_total_relation_size('jobs') + pg_total_relation_size('results')"
      " + pg_total_relation_size('result_chunks') + pg_total_relation_size('counters')");
  return r[0][0].as<int64_t>();
}

Status PostgresStoreImpl::EvictOldest(int64_t finished_before, int64_t max_used_bytes,
                                      EvictionReport* report) {
  for (;;) {
    int64_t jobs = 0, results = 0;  // this transaction's, counted once it commits
    // Whether the data fits after this transaction (then, or with nothing left to delete, done).
    StatusOr<bool> done = Write<bool>("evict jobs", [&](Tx& tx) -> StatusOr<bool> {
      jobs = results = 0;
      DRILLBIF_ASSIGN_OR_RETURN(const int64_t used_at_start, UsedBytes(tx));
      if (max_used_bytes > 0 && used_at_start <= max_used_bytes) return true;
      // The oldest finished jobs that no QUEUED or RUNNING job follows and whose parent (if
      // any) is not QUEUED or RUNNING (it may still read their results).
      const pqxx::result batch = tx.exec_params(
          "SELECT id, result_key FROM jobs j WHERE state IN (2, 3, 4) AND finished_ms < $1 "
          "AND NOT EXISTS (SELECT 1 FROM jobs f WHERE f.shares = j.id AND f.state IN (0, 1)) "
          "AND NOT EXISTS (SELECT 1 FROM jobs p WHERE p.id = j.parent_id AND p.state IN (0, 1)) "
          "ORDER BY finished_ms, seq LIMIT $2",
          finished_before, kEvictBatch);
      if (batch.empty()) return true;  // Nothing (more) that may go.
      // One job at a time, measuring after each: stop as soon as the data fits, or when this
      // transaction has freed enough to let others in.
      for (const pqxx::row& job : batch) {
        DRILLBIF_ASSIGN_OR_RETURN(
            const bool result_deleted,
            DeleteJobAndOrphanResult(tx, job[0].as<std::string>(), job[1].as<std::string>()));
        ++jobs;
        results += result_deleted;
        DRILLBIF_ASSIGN_OR_RETURN(const int64_t used, UsedBytes(tx));
        if (max_used_bytes > 0 && used <= max_used_bytes) return true;
        if (used_at_start - used >= kEvictTransactionBytes) break;
      }
      return false;
    });
    if (!done.ok()) return done.status();
    report->jobs_deleted += jobs;
    report->results_deleted += results;
    if (*done) return Status::Ok();
  }
}

StatusOr<EvictionReport> PostgresStoreImpl::Evict(const RetentionOptions& options, int64_t now_ms) {
  DRILLBIF_RETURN_IF_ERROR(options.Validate());
  EvictionReport report;
  auto sizes = [&](int64_t* used, int64_t* disk) {
    return Read<bool>("measure the store",
                      [&](Tx& tx) -> StatusOr<bool> {
                        DRILLBIF_ASSIGN_OR_RETURN(*used, UsedBytes(tx));
                        DRILLBIF_ASSIGN_OR_RETURN(*disk, DiskBytes(tx));
                        return true;
                      })
        .status();
  };
  DRILLBIF_RETURN_IF_ERROR(sizes(&report.used_bytes_before, &report.disk_bytes_before));
  if (options.max_age_ms > 0) {
    // now_ms - max_age_ms; a cutoff below INT64_MIN means nothing is that old.
    const std::optional<int64_t> cutoff = CheckedAdd(now_ms, -options.max_age_ms);
    if (cutoff) DRILLBIF_RETURN_IF_ERROR(EvictOldest(*cutoff, /*max_used_bytes=*/0, &report));
  }
  if (options.max_db_bytes > 0) {
    DRILLBIF_RETURN_IF_ERROR(
        EvictOldest(std::numeric_limits<int64_t>::max(), options.max_db_bytes, &report));
  }
  // The freed space is reused by new rows and given back by autovacuum; nothing to do here.
  DRILLBIF_RETURN_IF_ERROR(sizes(&report.used_bytes_after, &report.disk_bytes_after));
  report.size_limit_met =
      options.max_db_bytes == 0 || report.used_bytes_after <= options.max_db_bytes;
  return report;
}

}  // namespace drillbif::server
