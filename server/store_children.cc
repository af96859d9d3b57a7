#include "server/store_children.h"

#include <spdlog/spdlog.h>

#include <map>
#include <thread>
#include <utility>

namespace drillbif::server {

StoreChildren::StoreChildren(JobStore& store, const JobRecord& parent, std::string kind,
                             std::string what, std::string worker_id, int64_t lease_ms,
                             RunChild run_child, std::function<void()> submitted,
                             std::chrono::milliseconds poll)
    : store_(store),
      parent_(parent),
      kind_(std::move(kind)),
      what_(std::move(what)),
      worker_id_(std::move(worker_id)),
      lease_ms_(lease_ms),
      run_child_(std::move(run_child)),
      submitted_(std::move(submitted)),
      poll_(poll) {}

StatusOr<std::string> StoreChildren::ResultOf(const JobRecord& child) {
  switch (child.state) {
    case JobState::kQueued:
    case JobState::kRunning:
      return Internal(kind_ + " " + child.id + " has not finished");
    case JobState::kFailed:
      return Status(child.error_code, kind_ + " " + child.id + " failed: " + child.error_message);
    case JobState::kCancelled:
      return Status(StatusCode::kCancelled, kind_ + " " + child.id + " was cancelled");
    case JobState::kSucceeded:
      break;
  }
  return store_.GetResult(child.id);
}

Status StoreChildren::Resume(const std::vector<std::string>& requests, const Take& take,
                             std::vector<bool>* in) {
  std::map<std::string, size_t> part_of;
  for (size_t k = 0; k < requests.size(); ++k) part_of.emplace(requests[k], k);
  ListRequest list;
  list.parent = parent_.id;
  list.state = JobState::kSucceeded;
  list.kind = kind_;
  list.include_request = true;
  list.page_size = 1000;
  do {
    DRILLBIF_ASSIGN_OR_RETURN(const ListResult page, store_.List(list));
    for (const JobRecord& child : page.jobs) {
      const auto it = part_of.find(child.request);
      if (it == part_of.end() || (*in)[it->second]) continue;
      DRILLBIF_ASSIGN_OR_RETURN(const bool taken, take(it->second, child, /*resumed=*/true));
      if (!taken) continue;
      (*in)[it->second] = true;
      ++resumed_;
    }
    list.page_token = page.next_page_token;
  } while (!list.page_token.empty());
  return Status::Ok();
}

StatusOr<bool> StoreChildren::RunOneHere() {
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

void StoreChildren::NotResumed(const JobRecord& child, const Status& why) const {
  spdlog::warn("job {}: {} {} not resumed: {}", parent_.id, kind_, child.id, why.ToString());
}

Status StoreChildren::RunKeys(const std::vector<std::string>& requests, const Take& take,
                              const ProgressCallback& progress) {
  std::vector<bool> in(requests.size(), false);
  DRILLBIF_RETURN_IF_ERROR(Resume(requests, take, &in));
  struct Pending {
    size_t part = 0;
    std::string id;  // the child
  };
  std::vector<Pending> pending;
  for (size_t k = 0; k < requests.size(); ++k) {
    if (in[k]) continue;
    SubmitRequest request;
    request.kind = kind_;
    request.request = requests[k];
    request.client = parent_.client;
    request.lane = parent_.lane;
    request.parent = parent_.id;
    request.parent_run = parent_.run;
    StatusOr<SubmitResult> submitted = store_.Submit(request);
    if (submitted.status().code() == StatusCode::kFailedPrecondition) {
      return Status(StatusCode::kCancelled,
                    "the " + what_ + " was stopped: " + submitted.status().message());
    }
    if (!submitted.ok()) return submitted.status();
    pending.push_back({k, submitted->id});
    ++stored_;
  }
  if (!pending.empty() && submitted_) submitted_();
  const double total = static_cast<double>(requests.size());
  while (!pending.empty()) {
    if (progress && !progress((total - static_cast<double>(pending.size())) / total)) {
      return Status(StatusCode::kCancelled, "the " + what_ + " was stopped");
    }
    DRILLBIF_ASSIGN_OR_RETURN(const bool ran, RunOneHere());
    bool any = ran;
    for (auto it = pending.begin(); it != pending.end();) {
      DRILLBIF_ASSIGN_OR_RETURN(const JobRecord child, store_.Get(it->id, false));
      if (!IsFinished(child.state)) {
        ++it;
        continue;
      }
      DRILLBIF_RETURN_IF_ERROR(take(it->part, child, /*resumed=*/false).status());
      it = pending.erase(it);
      any = true;
    }
    if (!any) std::this_thread::sleep_for(poll_);
  }
  return Status::Ok();
}

}  // namespace drillbif::server
