#include "server/sweep_fan_out.h"

#include <utility>

namespace drillbif::server {

StoreSweepParts::StoreSweepParts(JobStore& store, const JobRecord& parent, std::string worker_id,
                                 int64_t lease_ms, RunChild run_child,
                                 std::function<void()> submitted, std::chrono::milliseconds poll)
    : children_(store, parent, jobs::kSweepPartKind, "sweep", std::move(worker_id), lease_ms,
                std::move(run_child), std::move(submitted), poll) {}

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
  return children_.Run<v1::SweepPartRequest, v1::SweepResult>(
      parts, [this](const JobRecord& child) { return PartOf(child); },
      [&](size_t k, v1::SweepResult part, bool /*resumed*/) {
        return done(static_cast<int>(k), std::move(part));
      },
      progress);
}

}  // namespace drillbif::server
