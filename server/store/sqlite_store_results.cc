// The SQLite JobStore's results: streamed chunks, completion and reads (docs/store.md, results).
//
// A run's chunks are rows of result_chunks keyed by (run_id, stream, first_item), run_id being the
// id of the job that runs. They stay where they are written: Complete inserts the results row (the
// summary, the totals and run_id) and never copies or rewrites a chunk, so completing a result
// of any size is a small transaction. Readers go from the job to its result_key, from the
// results row to run_id, and through the (run_id, stream, first_item) index to the chunks they
// need.
#include <sqlite3.h>

#include <cstdint>
#include <limits>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "drillbif/common/checked.h"
#include "server/store/sqlite_connection.h"
#include "server/store/sqlite_store_impl.h"

namespace drillbif::server {

using sqlite::Query;
using sqlite::Transaction;

Status SqliteStoreImpl::DropRunChunks(std::string_view id) {
  {
    DRILLBIF_ASSIGN_OR_RETURN(Query q,
                              connection_.Prepare("DELETE FROM result_chunks WHERE run_id = ?1"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, id).Run());
  }
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare("UPDATE jobs SET streamed_items = 0, streamed_bytes = 0 "
                                   "WHERE id = ?1"));
  return q.Bind(1, id).Run();
}

Status SqliteStoreImpl::AppendResultChunk(std::string_view id, int64_t run, int stream,
                                          int64_t first_item, int64_t item_count,
                                          std::string_view bytes) {
  DRILLBIF_RETURN_IF_ERROR(CheckChunk(run, stream, first_item, item_count));
  DRILLBIF_RETURN_IF_ERROR(CheckSize("chunk", bytes.size(), max_value_bytes_));
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_ASSIGN_OR_RETURN(JobHead head, RunningHead(id, "append a result chunk to", run));
  int64_t stream_end = 0;  // the stream's items so far: the end of its last chunk
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT first_item + item_count FROM result_chunks "
                                     "WHERE run_id = ?1 AND stream = ?2 "
                                     "ORDER BY first_item DESC LIMIT 1"));
    q.Bind(1, id).Bind(2, stream);
    DRILLBIF_ASSIGN_OR_RETURN(const bool row, q.Step());
    if (row) stream_end = q.Int(0);
  }
  if (first_item != stream_end) {
    return InvalidArgument("chunk starts at item " + std::to_string(first_item) + " of stream " +
                           std::to_string(stream) + " but job '" + std::string(id) + "' has " +
                           std::to_string(stream_end) +
                           " items there so far (a stream's chunks are contiguous and in order)");
  }
  const std::optional<int64_t> streamed_items = CheckedAdd(head.streamed_items, item_count);
  if (!streamed_items) return InvalidArgument("result items: beyond 2^63 - 1");
  const std::optional<int64_t> streamed_bytes =
      CheckedAdd(head.streamed_bytes, static_cast<int64_t>(bytes.size()));
  if (!streamed_bytes) return InvalidArgument("result bytes: beyond 2^63 - 1");
  {
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("INSERT INTO result_chunks (run_id, stream, first_item, "
                                     "item_count, data) VALUES (?1, ?2, ?3, ?4, ?5)"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, id)
                                 .Bind(2, stream)
                                 .Bind(3, first_item)
                                 .Bind(4, item_count)
                                 .BindBlob(5, bytes)
                                 .Run());
  }
  DRILLBIF_RETURN_IF_ERROR(UpdateRunning(
      "UPDATE jobs SET streamed_items = ?2, streamed_bytes = ?3 WHERE id = ?1 AND state = 1", id,
      [&](Query& q) { q.Bind(2, *streamed_items).Bind(3, *streamed_bytes); }));
  return tx.Commit();
}

Status SqliteStoreImpl::Complete(std::string_view id, int64_t run, std::string_view summary,
                                 int64_t points) {
  if (points < 0) return InvalidArgument("points must be >= 0");
  DRILLBIF_RETURN_IF_ERROR(CheckSize("result", summary.size(), max_value_bytes_));
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/true));
  DRILLBIF_ASSIGN_OR_RETURN(JobHead head, RunningHead(id, "complete", run));
  const std::optional<int64_t> total_bytes =
      CheckedAdd(static_cast<int64_t>(summary.size()), head.streamed_bytes);
  if (!total_bytes) return InvalidArgument("result bytes: beyond 2^63 - 1");
  const int64_t now = NowMs();
  {
    // A result for this cache key can exist already (a job whose cancel was requested, and so
    // was not shared, completed anyway): identical requests give identical results, keep the
    // first and drop this run's chunks.
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("INSERT INTO results (result_key, data, points, created_ms, "
                                     "run_id, items, bytes) VALUES (?1, ?2, ?3, ?4, ?5, ?6, ?7) "
                                     "ON CONFLICT (result_key) DO NOTHING"));
    DRILLBIF_RETURN_IF_ERROR(q.Bind(1, head.result_key)
                                 .BindBlob(2, summary)
                                 .Bind(3, points)
                                 .Bind(4, now)
                                 .Bind(5, id)
                                 .Bind(6, head.streamed_items)
                                 .Bind(7, *total_bytes)
                                 .Run());
  }
  if (connection_.Changes() == 0) DRILLBIF_RETURN_IF_ERROR(DropRunChunks(id));
  DRILLBIF_RETURN_IF_ERROR(
      UpdateRunning("UPDATE jobs SET state = 2, progress = 1, points = ?2, finished_ms = ?3 "
                    "WHERE id = ?1 AND state = 1",
                    id, [&](Query& q) { q.Bind(2, points).Bind(3, now); }));
  // Tasks still queued or running are no longer needed by anyone.
  DRILLBIF_RETURN_IF_ERROR(CancelChildren(id));
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

StatusOr<SqliteStoreImpl::ResultRow> SqliteStoreImpl::ReadResultRow(std::string_view id,
                                                                    bool with_summary) {
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare("SELECT j.state, r.result_key IS NOT NULL, r.run_id, r.items, "
                                   "r.bytes, r.points, CASE WHEN ?2 THEN r.data ELSE x'' END "
                                   "FROM jobs j LEFT JOIN results r ON r.result_key = j.result_key "
                                   "WHERE j.id = ?1"));
  q.Bind(1, id).Bind(2, with_summary ? 1 : 0);
  DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
  if (!row) return NoJob(id);
  const auto state = static_cast<JobState>(q.Int(0));
  if (state != JobState::kSucceeded) {
    return FailedPrecondition("job '" + std::string(id) + "' has no result: it is " +
                              JobStateName(state));
  }
  if (q.Int(1) == 0) {
    return Internal("job '" + std::string(id) + "' succeeded but its result is missing");
  }
  ResultRow result;
  result.run_id = q.Text(2);
  result.items = q.Int(3);
  result.info.total_items = result.items;
  result.info.total_bytes = q.Int(4);
  result.info.points = q.Int(5);
  result.info.summary = q.Blob(6);
  return result;
}

Status SqliteStoreImpl::ReadChunks(const std::string& run_id, int stream, int64_t first_item,
                                   int64_t max_bytes, std::vector<ResultChunk>* chunks) {
  // From the chunk containing first_item (the last one starting at or before it): two index
  // range reads, whatever the number of chunks.
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q,
      connection_.Prepare("SELECT first_item, item_count, data FROM result_chunks "
                          "WHERE run_id = ?1 AND stream = ?3 AND first_item >= COALESCE((SELECT "
                          "  first_item FROM result_chunks WHERE run_id = ?1 AND stream = ?3 "
                          "  AND first_item <= ?2 ORDER BY first_item DESC LIMIT 1), 0) "
                          "ORDER BY first_item"));
  q.Bind(1, run_id).Bind(2, first_item).Bind(3, stream);
  int64_t bytes = 0;
  for (;;) {
    DRILLBIF_ASSIGN_OR_RETURN(bool row, q.Step());
    if (!row) break;
    ResultChunk chunk;
    chunk.stream = stream;
    chunk.first_item = q.Int(0);
    chunk.item_count = q.Int(1);
    chunk.bytes = q.Blob(2);
    // Saturating: the sum of bytes actually held in memory cannot overflow, but stay exact.
    bytes = CheckedAdd(bytes, static_cast<int64_t>(chunk.bytes.size()))
                .value_or(std::numeric_limits<int64_t>::max());
    chunks->push_back(std::move(chunk));
    if (bytes >= max_bytes) break;
  }
  return Status::Ok();
}

StatusOr<std::string> SqliteStoreImpl::GetResult(std::string_view id) {
  std::lock_guard<std::mutex> lock(mu_);
  // One read transaction: the row and its chunks come from one snapshot.
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/false));
  DRILLBIF_ASSIGN_OR_RETURN(ResultRow row, ReadResultRow(id, /*with_summary=*/true));
  std::string bytes = std::move(row.info.summary);
  if (row.items > 0) {
    // The stored total is trusted only within SQLite's own size limit (a damaged value must not
    // make the reservation throw).
    if (row.info.total_bytes > 0 && row.info.total_bytes <= max_value_bytes_) {
      bytes.reserve(static_cast<size_t>(row.info.total_bytes));
    }
    DRILLBIF_ASSIGN_OR_RETURN(
        Query q, connection_.Prepare("SELECT data FROM result_chunks WHERE run_id = ?1 "
                                     "ORDER BY stream, first_item"));
    q.Bind(1, row.run_id);
    for (;;) {
      DRILLBIF_ASSIGN_OR_RETURN(bool more, q.Step());
      if (!more) break;
      q.AppendBlob(0, bytes);
    }
  }
  DRILLBIF_RETURN_IF_ERROR(tx.Commit());
  return bytes;
}

StatusOr<std::vector<int64_t>> SqliteStoreImpl::StreamItems(const std::string& run_id) {
  DRILLBIF_ASSIGN_OR_RETURN(
      Query q, connection_.Prepare("SELECT stream, SUM(item_count) FROM result_chunks "
                                   "WHERE run_id = ?1 GROUP BY stream ORDER BY stream"));
  q.Bind(1, run_id);
  std::vector<int64_t> items;
  for (;;) {
    DRILLBIF_ASSIGN_OR_RETURN(const bool row, q.Step());
    if (!row) break;
    const int64_t stream = q.Int(0);
    if (stream < 0 || stream >= kMaxResultStreams)
      return Internal("a stored chunk has a bad stream");
    items.resize(static_cast<size_t>(stream) + 1, 0);
    items[static_cast<size_t>(stream)] = q.Int(1);
  }
  return items;
}

StatusOr<ResultInfo> SqliteStoreImpl::GetResultInfo(std::string_view id) {
  std::lock_guard<std::mutex> lock(mu_);
  // One read transaction: the row and its streams come from one snapshot.
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/false));
  DRILLBIF_ASSIGN_OR_RETURN(ResultRow row, ReadResultRow(id, /*with_summary=*/true));
  if (row.items > 0) {
    DRILLBIF_ASSIGN_OR_RETURN(row.info.stream_items, StreamItems(row.run_id));
  }
  DRILLBIF_RETURN_IF_ERROR(tx.Commit());
  return std::move(row.info);
}

StatusOr<std::vector<ResultChunk>> SqliteStoreImpl::ReadResultChunks(std::string_view id,
                                                                     int stream, int64_t first_item,
                                                                     int64_t max_bytes) {
  DRILLBIF_RETURN_IF_ERROR(CheckChunkRead(stream, first_item, max_bytes));
  std::lock_guard<std::mutex> lock(mu_);
  DRILLBIF_ASSIGN_OR_RETURN(Transaction tx, Transaction::Begin(connection_, /*write=*/false));
  DRILLBIF_ASSIGN_OR_RETURN(ResultRow row, ReadResultRow(id, /*with_summary=*/false));
  std::vector<ResultChunk> chunks;
  if (first_item < row.items) {
    DRILLBIF_RETURN_IF_ERROR(ReadChunks(row.run_id, stream, first_item, max_bytes, &chunks));
  }
  DRILLBIF_RETURN_IF_ERROR(tx.Commit());
  return chunks;
}

}  // namespace drillbif::server
