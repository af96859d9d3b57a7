#include "server/map_fan_out.h"

#include <utility>

namespace drillbif::server {

StoreMapCells::StoreMapCells(JobStore& store, const JobRecord& parent, std::string worker_id,
                             int64_t lease_ms, RunChild run_child, std::function<void()> submitted,
                             std::chrono::milliseconds poll)
    : children_(store, parent, jobs::kMapCellKind, "map", std::move(worker_id), lease_ms,
                std::move(run_child), std::move(submitted), poll) {}

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
  return children_.Run<v1::OptimumRequest, v1::OptimumMapCell>(
      requests, [this](const JobRecord& child) { return CellOf(child); },
      [&](size_t k, v1::OptimumMapCell cell, bool resumed) {
        return done(static_cast<int64_t>(k), std::move(cell), resumed);
      },
      progress);
}

}  // namespace drillbif::server
