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
      run_child_(std::move(run_child)),
      submitted_callback_(std::move(submitted)) {}

StoreTaskRunner::~StoreTaskRunner() {
  // The trace takes or drops every ticket; what is left (a trace that threw) is cancelled.
  for (const auto& [ticket, child] : children_) {
    if (!child.id.empty()) Forget(child.id);
  }
}

StatusOr<int64_t> StoreTaskRunner::Submit(const TraceTask& task) {
  const int64_t ticket = next_++;
  if (stored_open_ >= std::min(budget_, options_.window)) {
    children_[ticket].task = task;  // kept: run here when needed
    return ticket;
  }
  SubmitRequest request;
  request.kind = jobs::kTraceTaskKind;
  request.request = jobs::EncodeTraceTaskRequest(local_.trace_request(), task);
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
                  "a trace task could not be stored: " + submitted.status().message());
  }
  ++stored_, ++stored_open_;
  children_[ticket].id = submitted->id;
  if (submitted_callback_) submitted_callback_();
  return ticket;
}

StatusOr<std::optional<TraceTaskResult>> StoreTaskRunner::ResultOf(Child& child) {
  Timed timed(store_seconds_);
  StatusOr<JobRecord> record = store_.Get(child.id, /*include_request=*/false);
  if (!record.ok()) {
    return Status(record.status().code(),
                  "trace task " + child.id + ": " + record.status().message());
  }
  switch (record->state) {
    case JobState::kQueued:
    case JobState::kRunning:
      return std::optional<TraceTaskResult>();
    case JobState::kFailed:
      return Status(record->error_code,
                    "trace task " + child.id + " failed: " + record->error_message);
    case JobState::kCancelled:
      return Status(StatusCode::kCancelled, "trace task " + child.id + " was cancelled");
    case JobState::kSucceeded:
      break;
  }
  child.finished = true;
  StatusOr<std::string> bytes = store_.GetResult(child.id);
  if (!bytes.ok()) {
    return Status(bytes.status().code(),
                  "trace task " + child.id + ": " + bytes.status().message());
  }
  StatusOr<TraceTaskResult> result = jobs::DecodeTraceTaskResult(*bytes);
  if (!result.ok()) {
    return Internal("trace task " + child.id +
                    ": its stored result does not decode: " + result.status().message());
  }
  return std::optional<TraceTaskResult>(*std::move(result));
}

bool StoreTaskRunner::Ready(int64_t ticket) {
  Child& child = children_.at(ticket);
  if (child.result.has_value() || child.finished) return true;
  if (child.id.empty()) return false;  // kept, not run yet
  // At most one look per poll interval per child: the trace asks for every queued point at each
  // step it applies.
  const auto now = std::chrono::steady_clock::now();
  if (now - child.looked < options_.poll) return false;
  child.looked = now;
  Timed timed(store_seconds_);
  StatusOr<JobRecord> record = store_.Get(child.id, /*include_request=*/false);
  child.finished = !record.ok() || IsFinished(record->state);
  return child.finished;
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
  ++claimed_here_;
  Timed timed(run_seconds_);
  std::optional<std::string> bytes = run_child_(**claimed);
  if (!bytes.has_value()) return true;  // not completed here: read from the store
  const auto it = std::find_if(children_.begin(), children_.end(),
                               [&](const auto& c) { return c.second.id == (*claimed)->id; });
  if (it == children_.end()) return true;  // dropped meanwhile
  StatusOr<TraceTaskResult> result = jobs::DecodeTraceTaskResult(*bytes);
  if (!result.ok()) return result.status();
  it->second.result = *std::move(result);
  return true;
}

StatusOr<bool> StoreTaskRunner::RunOneHere(const std::function<bool()>& keep_going) {
  for (auto& [ticket, child] : children_) {
    if (!child.task.has_value()) continue;
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
  if (!child.id.empty()) return TakeStored(ticket, keep_going);
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
  const std::string id = children_.at(ticket).id;
  for (;;) {
    Child& child = children_.at(ticket);
    if (child.result.has_value()) {  // claimed and run here
      TraceTaskResult result = *std::move(child.result);
      children_.erase(ticket);
      Closed(/*run_elsewhere=*/false);
      Timed timed(store_seconds_);
      (void)store_.Delete(id);
      return result;
    }
    StatusOr<std::optional<TraceTaskResult>> result = ResultOf(child);
    if (!result.ok() || result->has_value()) {
      children_.erase(ticket);
      Closed(/*run_elsewhere=*/result.ok());
      if (!result.ok()) {
        Forget(id);
        return result.status();
      }
      ++run_elsewhere_;
      Timed timed(store_seconds_);
      (void)store_.Delete(id);  // succeeded: nothing to cancel
      return **std::move(result);
    }
    if (!keep_going()) return Status(StatusCode::kCancelled, "the trace was stopped");
    StatusOr<bool> ran = RunOneHere(keep_going);
    if (!ran.ok()) return ran.status();
    if (!*ran) {
      Timed timed(sleep_seconds_);
      std::this_thread::sleep_for(options_.poll);
    }
  }
}

void StoreTaskRunner::Closed(bool run_elsewhere) {
  --stored_open_;
  if (run_elsewhere) {
    budget_ = std::min(budget_ + 1, options_.window);
  } else if (budget_ > 1) {
    --budget_;
  }
}

void StoreTaskRunner::Drop(int64_t ticket) {
  const auto it = children_.find(ticket);
  if (it == children_.end()) return;
  const std::string id = it->second.id;
  children_.erase(it);
  if (id.empty()) return;  // kept: nothing stored
  --stored_open_;
  Forget(id);
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
