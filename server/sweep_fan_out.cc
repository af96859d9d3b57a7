#include "server/sweep_fan_out.h"

#include <spdlog/spdlog.h>

#include <utility>

#include "jobs/request_bytes.h"

namespace drillbif::server {

StoreSweepParts::StoreSweepParts(JobStore& store, const JobRecord& parent, std::string worker_id,
                                 int64_t lease_ms, RunChild run_child,
                                 std::function<void()> submitted, std::chrono::milliseconds poll)
    : children_(store, parent, jobs::kSweepPartKind, "sweep", std::move(worker_id), lease_ms,
                std::move(run_child), std::move(submitted), poll),
      parent_id_(parent.id) {}

StatusOr<v1::SweepResult> StoreSweepParts::PartOf(const JobRecord& child) {
  DRILLBIF_ASSIGN_OR_RETURN(const std::string bytes, children_.ResultOf(child));
  v1::SweepResult part;
  if (!part.ParseFromString(bytes)) {
    return Internal("sweep part " + child.id + ": its stored result does not parse");
  }
  return part;
}

Status StoreSweepParts::Run(const std::vector<v1::SweepPartRequest>& parts, const PartDone& done,
                            const ProgressCallback& progress) {
  std::vector<std::string> keys;
  for (const v1::SweepPartRequest& r : parts) keys.push_back(jobs::DeterministicBytes(r));
  return children_.Run(
      keys,
      [&](size_t k, const JobRecord& child, bool resumed) -> StatusOr<bool> {
        StatusOr<v1::SweepResult> part = PartOf(child);
        if (!part.ok() && resumed) {
          spdlog::warn("job {}: sweep part {} not resumed: {}", parent_id_, child.id,
                       part.status().ToString());
          return false;
        }
        if (!part.ok()) return part.status();
        DRILLBIF_RETURN_IF_ERROR(done(static_cast<int>(k), *std::move(part)));
        return true;
      },
      progress);
}

}  // namespace drillbif::server
