#include "server/map_fan_out.h"

#include <spdlog/spdlog.h>

#include <utility>

#include "jobs/request_bytes.h"

namespace drillbif::server {

StoreMapCells::StoreMapCells(JobStore& store, const JobRecord& parent, std::string worker_id,
                             int64_t lease_ms, RunChild run_child, std::function<void()> submitted,
                             std::chrono::milliseconds poll)
    : children_(store, parent, jobs::kMapCellKind, "map", std::move(worker_id), lease_ms,
                std::move(run_child), std::move(submitted), poll),
      parent_id_(parent.id) {}

StatusOr<v1::OptimumMapCell> StoreMapCells::CellOf(const JobRecord& child) {
  if (child.state == JobState::kFailed) {
    // The cell's run failed (not its optimum, which is a result): the cell says so.
    v1::OptimumMapCell cell;
    cell.mutable_optimum()->set_status("FAILED");
    cell.mutable_optimum()->set_message(child.error_message);
    return cell;
  }
  DRILLBIF_ASSIGN_OR_RETURN(const std::string bytes, children_.ResultOf(child));
  v1::OptimumMapCell cell;
  if (!cell.ParseFromString(bytes)) {
    return Internal("map cell " + child.id + ": its stored result does not parse");
  }
  return cell;
}

Status StoreMapCells::Run(const std::vector<v1::OptimumRequest>& requests, const CellDone& done,
                          const ProgressCallback& progress) {
  std::vector<std::string> keys;
  for (const v1::OptimumRequest& r : requests) keys.push_back(jobs::DeterministicBytes(r));
  return children_.Run(
      keys,
      [&](size_t k, const JobRecord& child, bool resumed) -> StatusOr<bool> {
        StatusOr<v1::OptimumMapCell> cell = CellOf(child);
        if (!cell.ok() && resumed) {
          spdlog::warn("job {}: map cell {} not resumed: {}", parent_id_, child.id,
                       cell.status().ToString());
          return false;
        }
        if (!cell.ok()) return cell.status();
        DRILLBIF_RETURN_IF_ERROR(done(static_cast<int64_t>(k), *std::move(cell), resumed));
        return true;
      },
      progress);
}

}  // namespace drillbif::server
