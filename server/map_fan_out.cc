#include "server/map_fan_out.h"

#include <spdlog/spdlog.h>

#include <map>
#include <thread>
#include <utility>

#include "jobs/request_bytes.h"

namespace drillbif::server {

StoreMapCells::StoreMapCells(JobStore& store, const JobRecord& parent, std::string worker_id,
                             int64_t lease_ms, RunChild run_child, std::function<void()> submitted,
                             std::chrono::milliseconds poll)
    : store_(store),
      parent_(parent),
      worker_id_(std::move(worker_id)),
      lease_ms_(lease_ms),
      run_child_(std::move(run_child)),
      submitted_(std::move(submitted)),
      poll_(poll) {}

StatusOr<v1::OptimumMapCell> StoreMapCells::CellOf(const JobRecord& child) {
  if (child.state == JobState::kFailed) {
    // The cell's run failed (not its optimum, which is a result): the cell says so.
    v1::OptimumMapCell cell;
    cell.mutable_optimum()->set_status("FAILED");
    cell.mutable_optimum()->set_message(child.error_message);
    return cell;
  }
  if (child.state == JobState::kCancelled) {
    return Status(StatusCode::kCancelled, "map cell " + child.id + " was cancelled");
  }
  DRILLBIF_ASSIGN_OR_RETURN(const std::string bytes, store_.GetResult(child.id));
  v1::OptimumMapCell cell;
  if (!cell.ParseFromString(bytes)) {
    return Internal("map cell " + child.id + ": its stored result does not parse");
  }
  return cell;
}

Status StoreMapCells::Resume(const std::vector<std::string>& keys, const CellDone& done,
                             std::vector<bool>* in) {
  std::map<std::string, int64_t> cell_of;
  for (size_t k = 0; k < keys.size(); ++k) cell_of.emplace(keys[k], static_cast<int64_t>(k));
  ListRequest list;
  list.parent = parent_.id;
  list.state = JobState::kSucceeded;
  list.kind = jobs::kMapCellKind;
  list.include_request = true;
  list.page_size = 1000;
  do {
    DRILLBIF_ASSIGN_OR_RETURN(const ListResult page, store_.List(list));
    for (const JobRecord& child : page.jobs) {
      const auto it = cell_of.find(child.request);
      if (it == cell_of.end() || (*in)[it->second]) continue;
      StatusOr<v1::OptimumMapCell> cell = CellOf(child);
      if (!cell.ok()) {
        spdlog::warn("job {}: map cell {} not resumed: {}", parent_.id, child.id,
                     cell.status().ToString());
        continue;
      }
      (*in)[it->second] = true;
      ++resumed_;
      DRILLBIF_RETURN_IF_ERROR(done(it->second, *std::move(cell), /*resumed=*/true));
    }
    list.page_token = page.next_page_token;
  } while (!list.page_token.empty());
  return Status::Ok();
}

StatusOr<bool> StoreMapCells::RunOneHere() {
  ClaimOptions claim;
  claim.lease_ms = lease_ms_;
  claim.parent = parent_.id;
  DRILLBIF_ASSIGN_OR_RETURN(const std::optional<JobRecord> claimed,
                            store_.ClaimNext(worker_id_, claim));
  if (!claimed.has_value()) return false;
  ++run_here_;
  run_child_(*claimed);  // its outcome is in the store, read with the others'
  return true;
}

Status StoreMapCells::Run(const std::vector<v1::OptimumRequest>& requests, const CellDone& done,
                          const ProgressCallback& progress) {
  std::vector<std::string> keys;
  for (const v1::OptimumRequest& r : requests) keys.push_back(jobs::DeterministicBytes(r));
  std::vector<bool> in(requests.size(), false);
  DRILLBIF_RETURN_IF_ERROR(Resume(keys, done, &in));
  std::vector<Pending> pending;
  for (size_t k = 0; k < keys.size(); ++k) {
    if (in[k]) continue;
    SubmitRequest request;
    request.kind = jobs::kMapCellKind;
    request.request = keys[k];
    request.client = parent_.client;
    request.lane = parent_.lane;
    request.parent = parent_.id;
    request.parent_run = parent_.run;
    StatusOr<SubmitResult> submitted = store_.Submit(request);
    if (submitted.status().code() == StatusCode::kFailedPrecondition) {
      return Status(StatusCode::kCancelled, "the map was stopped: " + submitted.status().message());
    }
    if (!submitted.ok()) return submitted.status();
    pending.push_back({static_cast<int64_t>(k), submitted->id});
    ++stored_;
  }
  if (!pending.empty() && submitted_) submitted_();
  const double total = static_cast<double>(requests.size());
  while (!pending.empty()) {
    if (progress && !progress((total - pending.size()) / total)) {
      return Status(StatusCode::kCancelled, "the map was stopped");
    }
    DRILLBIF_ASSIGN_OR_RETURN(const bool ran, RunOneHere());
    bool any = ran;
    for (auto it = pending.begin(); it != pending.end();) {
      DRILLBIF_ASSIGN_OR_RETURN(const JobRecord child, store_.Get(it->id, false));
      if (!IsFinished(child.state)) {
        ++it;
        continue;
      }
      DRILLBIF_ASSIGN_OR_RETURN(v1::OptimumMapCell cell, CellOf(child));
      DRILLBIF_RETURN_IF_ERROR(done(it->cell, std::move(cell), /*resumed=*/false));
      it = pending.erase(it);
      any = true;
    }
    if (!any) std::this_thread::sleep_for(poll_);
  }
  return Status::Ok();
}

}  // namespace drillbif::server
