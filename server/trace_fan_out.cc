#include "server/trace_fan_out.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <thread>
#include <utility>

#include "jobs/trace_task_codec.h"

namespace drillbif::server {

namespace {

// Adds the time from its construction to its end to `total` (seconds).
class Timed {
 public:
  explicit Timed(double& total) : total_(total), start_(std::chrono::steady_clock::now()) {}
  ~Timed() {
    total_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  }
  Timed(const Timed&) = delete;
  Timed& operator=(const Timed&) = delete;

 private:
  double& total_;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace

StoreTaskRunner::StoreTaskRunner(JobStore& store, const JobRecord& parent, std::string worker_id,
                                 const jobs::LocalTraceTasks& local, const FanOutOptions& options,
                                 RunClaimedChild run_child, std::function<void()> submitted)
    : store_(store),
      parent_(parent),
      worker_id_(std::move(worker_id)),
      local_(local),
      options_(options),
      batch_size_(std::clamp<size_t>(
          options.batch, 1,
          std::min<size_t>(std::max<size_t>(options.window, 1), jobs::kMaxTraceTaskBatch))),
      max_batches_(std::max<size_t>(1, options.window / batch_size_)),
      run_child_(std::move(run_child)),
      submitted_callback_(std::move(submitted)) {
  budget_ = std::min(budget_, max_batches_);
}

StoreTaskRunner::~StoreTaskRunner() {
  // The trace takes or drops every ticket; what is left (a trace that threw) is cancelled.
  for (const auto& [key, batch] : batches_) Forget(batch.id);
}

StatusOr<int64_t> StoreTaskRunner::Submit(const TraceTask& task) {
  const int64_t ticket = next_++;
  children_[ticket].task = task;
  // Gathered for a batch while the budget has room for one more (the one gathered counts),
  // else kept: run here when needed.
  if (gathered_.empty() && open_batches_ >= std::min(budget_, max_batches_)) return ticket;
  gathered_.push_back(ticket);
  if (gathered_.size() >= batch_size_) DRILLBIF_RETURN_IF_ERROR(StoreBatch());
  return ticket;
}

Status StoreTaskRunner::StoreBatch() {
  std::vector<const TraceTask*> tasks;
  for (const int64_t t : gathered_) tasks.push_back(&*children_.at(t).task);
  SubmitRequest request;
  request.kind = jobs::kTraceTaskKind;
  request.request = jobs::EncodeTraceTaskBatch(local_.trace_request(), tasks);
  request.client = parent_.client;
  request.lane = parent_.lane;
  request.parent = parent_.id;
  request.parent_run = parent_.run;
  StatusOr<SubmitResult> submitted = [&] {
    Timed timed(store_seconds_);
    return store_.Submit(request);
  }();
  if (submitted.status().code() == StatusCode::kFailedPrecondition) {
    // The parent is no longer this run's or its cancel was asked: the trace stops as cancelled
    // (a run that lost its lease records nothing anyway).
    return Status(StatusCode::kCancelled, "the trace was stopped: " + submitted.status().message());
  }
  if (!submitted.ok()) {
    return Status(submitted.status().code(),
                  "trace tasks could not be stored: " + submitted.status().message());
  }
  const int64_t key = gathered_.front();
  Batch& batch = batches_[key];
  batch.id = submitted->id;
  batch.tickets = gathered_;
  batch.open = gathered_.size();
  for (size_t i = 0; i < gathered_.size(); ++i) {
    Child& child = children_.at(gathered_[i]);
    child.task.reset();
    child.batch = key;
    child.index = static_cast<int>(i);
  }
  stored_ += static_cast<int64_t>(gathered_.size());
  ++batches_stored_, ++open_batches_;
  gathered_.clear();
  if (submitted_callback_) submitted_callback_();
  return Status::Ok();
}

Status StoreTaskRunner::HandOut(Batch& batch, std::string_view bytes, bool run_elsewhere) {
  if (batch.results_in) return Status::Ok();
  StatusOr<std::vector<TraceTaskResult>> results = jobs::DecodeTraceTaskBatchResponse(bytes);
  if (results.ok() && results->size() != batch.tickets.size()) {
    results = InvalidArgument(std::to_string(results->size()) + " results for " +
                              std::to_string(batch.tickets.size()) + " tasks");
  }
  if (!results.ok()) {
    return Internal("trace tasks " + batch.id +
                    ": their stored results do not decode: " + results.status().message());
  }
  for (size_t i = 0; i < batch.tickets.size(); ++i) {
    const auto it = children_.find(batch.tickets[i]);
    if (it != children_.end()) it->second.result = std::move((*results)[i]);
  }
  batch.results_in = batch.finished = true;
  --open_batches_;
  Closed(run_elsewhere);
  (run_elsewhere ? run_elsewhere_ : claimed_here_) += static_cast<int64_t>(batch.tickets.size());
  return Status::Ok();
}

StatusOr<bool> StoreTaskRunner::CollectResults(Batch& batch) {
  Timed timed(store_seconds_);
  StatusOr<JobRecord> record = store_.Get(batch.id, /*include_request=*/false);
  if (!record.ok()) {
    return Status(record.status().code(),
                  "trace tasks " + batch.id + ": " + record.status().message());
  }
  switch (record->state) {
    case JobState::kQueued:
    case JobState::kRunning:
      return false;
    case JobState::kFailed:
      return Status(record->error_code,
                    "trace tasks " + batch.id + " failed: " + record->error_message);
    case JobState::kCancelled:
      return Status(StatusCode::kCancelled, "trace tasks " + batch.id + " were cancelled");
    case JobState::kSucceeded:
      break;
  }
  batch.finished = true;
  StatusOr<std::string> bytes = store_.GetResult(batch.id);
  if (!bytes.ok()) {
    return Status(bytes.status().code(),
                  "trace tasks " + batch.id + ": " + bytes.status().message());
  }
  DRILLBIF_RETURN_IF_ERROR(HandOut(batch, *bytes, /*run_elsewhere=*/true));
  return true;
}

bool StoreTaskRunner::Ready(int64_t ticket) {
  Child& child = children_.at(ticket);
  if (child.result.has_value()) return true;
  if (child.batch < 0) return false;  // kept or gathered, not run yet
  Batch& batch = batches_.at(child.batch);
  if (batch.finished) return true;
  // At most one look per poll interval per batch: the trace asks for every queued point at each
  // step it applies.
  const auto now = std::chrono::steady_clock::now();
  if (now - batch.looked < options_.poll) return false;
  batch.looked = now;
  Timed timed(store_seconds_);
  StatusOr<JobRecord> record = store_.Get(batch.id, /*include_request=*/false);
  batch.finished = !record.ok() || IsFinished(record->state);
  return batch.finished;
}

StatusOr<bool> StoreTaskRunner::ClaimOneHere() {
  ClaimOptions claim;
  claim.lease_ms = options_.lease_ms;
  claim.parent = parent_.id;
  StatusOr<std::optional<JobRecord>> claimed = [&] {
    Timed timed(store_seconds_);
    return store_.ClaimNext(worker_id_, claim);
  }();
  if (!claimed.ok() || !claimed->has_value()) return false;
  std::optional<std::string> bytes = [&] {
    Timed timed(run_seconds_);
    return run_child_(**claimed);
  }();
  if (!bytes.has_value()) return true;  // not completed here: read from the store
  const auto it = std::find_if(batches_.begin(), batches_.end(),
                               [&](const auto& b) { return b.second.id == (*claimed)->id; });
  if (it == batches_.end()) return true;  // dropped meanwhile
  DRILLBIF_RETURN_IF_ERROR(HandOut(it->second, *bytes, /*run_elsewhere=*/false));
  return true;
}

StatusOr<bool> StoreTaskRunner::RunOneHere(const std::function<bool()>& keep_going) {
  for (auto& [ticket, child] : children_) {
    if (!child.task.has_value() || child.result.has_value() ||
        std::find(gathered_.begin(), gathered_.end(), ticket) != gathered_.end()) {
      continue;
    }
    Timed timed(run_seconds_);
    StatusOr<TraceTaskResult> result = local_.Run(*child.task, keep_going);
    if (!result.ok()) return result.status();
    child.task.reset();
    child.result = *std::move(result);
    return true;
  }
  return ClaimOneHere();
}

StatusOr<TraceTaskResult> StoreTaskRunner::Take(int64_t ticket,
                                                const std::function<bool()>& keep_going) {
  Child& child = children_.at(ticket);
  if (child.batch >= 0) return TakeStored(ticket, keep_going);
  // The trace caught up with the tasks gathered for a batch: they are kept, run here.
  if (std::find(gathered_.begin(), gathered_.end(), ticket) != gathered_.end()) gathered_.clear();
  if (!child.result.has_value()) {
    Timed timed(run_seconds_);
    StatusOr<TraceTaskResult> result = local_.Run(*child.task, keep_going);
    if (!result.ok()) {
      children_.erase(ticket);
      return result.status();
    }
    child.result = *std::move(result);
  }
  TraceTaskResult result = *std::move(child.result);
  children_.erase(ticket);
  return result;
}

StatusOr<TraceTaskResult> StoreTaskRunner::TakeStored(int64_t ticket,
                                                      const std::function<bool()>& keep_going) {
  for (;;) {
    Child& child = children_.at(ticket);
    if (child.result.has_value()) {
      TraceTaskResult result = *std::move(child.result);
      Release(ticket);
      return result;
    }
    StatusOr<bool> in = CollectResults(batches_.at(child.batch));
    if (!in.ok()) {
      Release(ticket);
      return in.status();
    }
    if (*in) continue;
    if (!keep_going()) return Status(StatusCode::kCancelled, "the trace was stopped");
    StatusOr<bool> ran = RunOneHere(keep_going);
    if (!ran.ok()) return ran.status();
    if (!*ran) {
      Timed timed(sleep_seconds_);
      std::this_thread::sleep_for(options_.poll);
    }
  }
}

void StoreTaskRunner::Release(int64_t ticket) {
  const auto child = children_.find(ticket);
  const int64_t key = child->second.batch;
  children_.erase(child);
  const auto it = batches_.find(key);
  Batch& batch = it->second;
  if (--batch.open > 0) return;
  if (!batch.results_in) {
    --open_batches_;  // dropped whole before its results came: the budget stays
    Forget(batch.id);
  } else {
    Timed timed(store_seconds_);
    (void)store_.Delete(batch.id);  // its results are in: nothing to cancel
  }
  batches_.erase(it);
}

void StoreTaskRunner::Closed(bool run_elsewhere) {
  if (run_elsewhere) {
    budget_ = std::min(budget_ + 1, max_batches_);
  } else if (budget_ > 1) {
    --budget_;
  }
}

void StoreTaskRunner::Drop(int64_t ticket) {
  const auto it = children_.find(ticket);
  if (it == children_.end()) return;
  if (it->second.batch >= 0) return Release(ticket);
  std::erase(gathered_, ticket);
  children_.erase(it);
}

// Cancels the child unless it finished, and deletes it once it has (a running one is deleted
// by the retention once its worker stops).
void StoreTaskRunner::Forget(const std::string& id) {
  Timed timed(store_seconds_);
  StatusOr<JobState> state = store_.Cancel(id);
  if (!state.ok() && state.status().code() != StatusCode::kFailedPrecondition) {
    spdlog::debug("trace task {}: not cancelled: {}", id, state.status().ToString());
    return;
  }
  if (!state.ok() || IsFinished(*state)) (void)store_.Delete(id);
}

}  // namespace drillbif::server
