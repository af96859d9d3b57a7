// The PostgreSQL JobStore's results: streamed chunks, completion and reads (the SQLite store's
// sqlite_store_results.cc has the reasoning behind each step).
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

Status PostgresStoreImpl::DropRunChunks(Tx& tx, std::string_view id) {
  tx.exec_params("DELETE FROM result_chunks WHERE run_id = $1", std::string(id));
  tx.exec_params("UPDATE jobs SET streamed_items = 0, streamed_bytes = 0 WHERE id = $1",
                 std::string(id));
  return Status::Ok();
}

Status PostgresStoreImpl::AppendResultChunk(std::string_view id, int64_t run, int stream,
                                            int64_t first_item, int64_t item_count,
                                            std::string_view bytes) {
  DRILLBIF_RETURN_IF_ERROR(CheckChunk(run, stream, first_item, item_count));
  DRILLBIF_RETURN_IF_ERROR(CheckSize("chunk", bytes.size(), PostgresJobStore::kMaxValueBytes));
  return WriteStatus("append a result chunk", [&](Tx& tx) -> Status {
    DRILLBIF_ASSIGN_OR_RETURN(JobHead head, RunningHead(tx, id, "append a result chunk to", run));
    const pqxx::result r = tx.exec_params(
        "SELECT first_item + item_count FROM result_chunks WHERE run_id = $1 AND stream = $2 "
        "ORDER BY first_item DESC LIMIT 1",
        std::string(id), stream);
    const int64_t stream_end = r.empty() ? 0 : r[0][0].as<int64_t>();
    if (first_item != stream_end) {
      return InvalidArgument("chunk starts at item " + std::to_string(first_item) + " of stream " +
                             std::to_string(stream) + " but job '" + std::string(id) + "' has " +
                             std::to_string(stream_end) +
                             " items there so far (a stream's chunks are contiguous and in order)");
    }
    const std::optional<int64_t> items = CheckedAdd(head.streamed_items, item_count);
    if (!items) return InvalidArgument("result items: beyond 2^63 - 1");
    const std::optional<int64_t> total =
        CheckedAdd(head.streamed_bytes, static_cast<int64_t>(bytes.size()));
    if (!total) return InvalidArgument("result bytes: beyond 2^63 - 1");
    tx.exec_params(
        "INSERT INTO result_chunks (run_id, stream, first_item, item_count, data) "
        "VALUES ($1, $2, $3, $4, $5)",
        std::string(id), stream, first_item, item_count,
        pqxx::binarystring(bytes.data(), bytes.size()));
    return UpdateRunning(
        tx, "UPDATE jobs SET streamed_items = $2, streamed_bytes = $3 WHERE id = $1 AND state = 1",
        id, *items, *total);
  });
}

Status PostgresStoreImpl::Complete(std::string_view id, int64_t run, std::string_view summary,
                                   int64_t points) {
  if (points < 0) return InvalidArgument("points must be >= 0");
  DRILLBIF_RETURN_IF_ERROR(CheckSize("result", summary.size(), PostgresJobStore::kMaxValueBytes));
  return WriteStatus("complete a job", [&](Tx& tx) -> Status {
    DRILLBIF_ASSIGN_OR_RETURN(JobHead head, RunningHead(tx, id, "complete", run));
    const std::optional<int64_t> total_bytes =
        CheckedAdd(static_cast<int64_t>(summary.size()), head.streamed_bytes);
    if (!total_bytes) return InvalidArgument("result bytes: beyond 2^63 - 1");
    const int64_t now = NowMs();
    // A result for this cache key can exist already (a job whose cancel was requested, and so
    // was not shared, completed anyway): keep the first and drop this run's chunks.
    const pqxx::result inserted = tx.exec_params(
        "INSERT INTO results (result_key, data, points, created_ms, run_id, items, bytes) "
        "VALUES ($1, $2, $3, $4, $5, $6, $7) ON CONFLICT (result_key) DO NOTHING",
        head.result_key, pqxx::binarystring(summary.data(), summary.size()), points, now,
        std::string(id), head.streamed_items, *total_bytes);
    if (inserted.affected_rows() == 0) DRILLBIF_RETURN_IF_ERROR(DropRunChunks(tx, id));
    DRILLBIF_RETURN_IF_ERROR(
        UpdateRunning(tx,
                      "UPDATE jobs SET state = 2, progress = 1, points = $2, finished_ms = $3 "
                      "WHERE id = $1 AND state = 1",
                      id, points, now));
    // Tasks still queued or running are no longer needed by anyone.
    DRILLBIF_RETURN_IF_ERROR(CancelChildren(tx, id));
    const pqxx::result followers = tx.exec_params(
        "UPDATE jobs SET state = 2, progress = 1, points = $2, finished_ms = $3, cache_hit = TRUE "
        "WHERE shares = $1 AND state IN (0, 1)",
        std::string(id), points, now);
    if (followers.affected_rows() > 0) {
      tx.exec_params("UPDATE counters SET value = value + $1 WHERE name = 'cache_hits'",
                     static_cast<int64_t>(followers.affected_rows()));
    }
    return Status::Ok();
  });
}

StatusOr<PostgresStoreImpl::ResultRow> PostgresStoreImpl::ReadResultRow(Tx& tx, std::string_view id,
                                                                        bool with_summary) {
  const pqxx::result r = tx.exec_params(
      "SELECT j.state, r.result_key IS NOT NULL, r.run_id, r.items, r.bytes, r.points, "
      "CASE WHEN $2 THEN r.data ELSE ''::bytea END "
      "FROM jobs j LEFT JOIN results r ON r.result_key = j.result_key WHERE j.id = $1",
      std::string(id), with_summary);
  if (r.empty()) return NoJob(id);
  const auto state = static_cast<JobState>(r[0][0].as<int>());
  if (state != JobState::kSucceeded) {
    return FailedPrecondition("job '" + std::string(id) + "' has no result: it is " +
                              JobStateName(state));
  }
  if (!r[0][1].as<bool>()) {
    return Internal("job '" + std::string(id) + "' succeeded but its result is missing");
  }
  ResultRow result;
  result.run_id = r[0][2].as<std::string>();
  result.items = r[0][3].as<int64_t>();
  result.info.total_items = result.items;
  result.info.total_bytes = r[0][4].as<int64_t>();
  result.info.points = r[0][5].as<int64_t>();
  result.info.summary = pqxx::binarystring(r[0][6]).str();
  return result;
}

StatusOr<std::string> PostgresStoreImpl::GetResult(std::string_view id) {
  return Read<std::string>("read a result", [&](Tx& tx) -> StatusOr<std::string> {
    DRILLBIF_ASSIGN_OR_RETURN(ResultRow row, ReadResultRow(tx, id, /*with_summary=*/true));
    std::string bytes = std::move(row.info.summary);
    if (row.items == 0) return bytes;
    // The stored total is trusted only within the store's own size limit.
    if (row.info.total_bytes > 0 && row.info.total_bytes <= PostgresJobStore::kMaxValueBytes) {
      bytes.reserve(static_cast<size_t>(row.info.total_bytes));
    }
    const pqxx::result chunks = tx.exec_params(
        "SELECT data FROM result_chunks WHERE run_id = $1 ORDER BY stream, first_item", row.run_id);
    for (const pqxx::row& chunk : chunks) {
      const pqxx::binarystring data(chunk[0]);
      bytes.append(data.get(), data.size());
    }
    return bytes;
  });
}

StatusOr<ResultInfo> PostgresStoreImpl::GetResultInfo(std::string_view id) {
  return Read<ResultInfo>("read a result", [&](Tx& tx) -> StatusOr<ResultInfo> {
    DRILLBIF_ASSIGN_OR_RETURN(ResultRow row, ReadResultRow(tx, id, /*with_summary=*/true));
    if (row.items == 0) return std::move(row.info);
    const pqxx::result r = tx.exec_params(
        "SELECT stream, SUM(item_count) FROM result_chunks WHERE run_id = $1 "
        "GROUP BY stream ORDER BY stream",
        row.run_id);
    for (const pqxx::row& s : r) {
      const int stream = s[0].as<int>();
      if (stream < 0 || stream >= kMaxResultStreams) {
        return Internal("a stored chunk has a bad stream");
      }
      row.info.stream_items.resize(static_cast<size_t>(stream) + 1, 0);
      row.info.stream_items[static_cast<size_t>(stream)] = s[1].as<int64_t>();
    }
    return std::move(row.info);
  });
}

StatusOr<std::vector<ResultChunk>> PostgresStoreImpl::ReadResultChunks(std::string_view id,
                                                                       int stream,
                                                                       int64_t first_item,
                                                                       int64_t max_bytes) {
  DRILLBIF_RETURN_IF_ERROR(CheckChunkRead(stream, first_item, max_bytes));
  using Chunks = std::vector<ResultChunk>;
  return Read<Chunks>("read result chunks", [&](Tx& tx) -> StatusOr<Chunks> {
    DRILLBIF_ASSIGN_OR_RETURN(ResultRow row, ReadResultRow(tx, id, /*with_summary=*/false));
    Chunks chunks;
    if (first_item >= row.items) return chunks;
    // From the chunk containing first_item (the last one starting at or before it), a chunk at
    // a time through a cursor-like LIMIT: only the chunks returned are read.
    const pqxx::result start = tx.exec_params(
        "SELECT COALESCE(MAX(first_item), 0) FROM result_chunks "
        "WHERE run_id = $1 AND stream = $2 AND first_item <= $3",
        row.run_id, stream, first_item);
    int64_t next = start[0][0].as<int64_t>();
    int64_t bytes = 0;
    while (bytes < max_bytes) {
      const pqxx::result r = tx.exec_params(
          "SELECT first_item, item_count, data FROM result_chunks "
          "WHERE run_id = $1 AND stream = $2 AND first_item >= $3 ORDER BY first_item LIMIT 1",
          row.run_id, stream, next);
      if (r.empty()) break;
      ResultChunk chunk;
      chunk.stream = stream;
      chunk.first_item = r[0][0].as<int64_t>();
      chunk.item_count = r[0][1].as<int64_t>();
      chunk.bytes = pqxx::binarystring(r[0][2]).str();
      bytes = CheckedAdd(bytes, static_cast<int64_t>(chunk.bytes.size()))
                  .value_or(std::numeric_limits<int64_t>::max());
      next = chunk.first_item + chunk.item_count;
      chunks.push_back(std::move(chunk));
    }
    return chunks;
  });
}

}  // namespace drillbif::server
