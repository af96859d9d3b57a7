#include "server/trace_fan_out.h"

#include <spdlog/spdlog.h>

#include <thread>
#include <utility>

#include "jobs/trace_task_codec.h"
#include "jobs/trace_task_job.h"

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
                                 const FanOutOptions& options, RunClaimedChild run_child,
                                 std::function<void()> submitted)
    : store_(store),
      parent_(parent),
      worker_id_(std::move(worker_id)),
      options_(options),
      run_child_(std::move(run_child)),
      submitted_callback_(std::move(submitted)) {}

StoreTaskRunner::~StoreTaskRunner() {
  // The trace takes or drops every ticket; what is left (a trace that threw) is cancelled.
  for (const auto& [ticket, child] : children_) Forget(child.id);
}

StatusOr<int64_t> StoreTaskRunner::Submit(const TraceTask& task) {
  SubmitRequest request;
  request.kind = jobs::kTraceTaskKind;
  request.request = jobs::EncodeTraceTaskRequest(parent_.request, task);
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
  ++submitted_;
  children_[next_] = Child{submitted->id};
  if (submitted_callback_) submitted_callback_();
  return next_++;
}

StatusOr<std::optional<TraceTaskResult>> StoreTaskRunner::ResultOf(Child& child) {
  Timed timed(store_seconds_);
  // Run here and completed: succeeded, its result in memory.
  if (const auto kept = kept_.find(child.id); kept != kept_.end()) {
    const std::string bytes = std::move(kept->second);
    kept_.erase(kept);
    return Decoded(child, bytes);
  }
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
  StatusOr<std::string> bytes = store_.GetResult(child.id);
  if (!bytes.ok()) {
    return Status(bytes.status().code(),
                  "trace task " + child.id + ": " + bytes.status().message());
  }
  return Decoded(child, *bytes);
}

StatusOr<std::optional<TraceTaskResult>> StoreTaskRunner::Decoded(Child& child,
                                                                  const std::string& bytes) {
  child.finished = true;
  StatusOr<TraceTaskResult> result = jobs::DecodeTraceTaskResult(bytes);
  if (!result.ok()) {
    return Internal("trace task " + child.id +
                    ": its stored result does not decode: " + result.status().message());
  }
  return std::optional<TraceTaskResult>(*std::move(result));
}

bool StoreTaskRunner::Ready(int64_t ticket) {
  Child& child = children_.at(ticket);
  if (child.finished || kept_.count(child.id) > 0) return true;
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

bool StoreTaskRunner::RunOneHere() {
  ClaimOptions claim;
  claim.lease_ms = options_.lease_ms;
  claim.parent = parent_.id;
  StatusOr<std::optional<JobRecord>> claimed = [&] {
    Timed timed(store_seconds_);
    return store_.ClaimNext(worker_id_, claim);
  }();
  if (!claimed.ok() || !claimed->has_value()) return false;
  ++ran_here_;
  Timed timed(run_seconds_);
  std::optional<std::string> result = run_child_(**claimed);
  if (result.has_value()) kept_[(*claimed)->id] = *std::move(result);
  return true;
}

StatusOr<TraceTaskResult> StoreTaskRunner::Take(int64_t ticket,
                                                const std::function<bool()>& keep_going) {
  const std::string id = children_.at(ticket).id;
  for (;;) {
    StatusOr<std::optional<TraceTaskResult>> result = ResultOf(children_.at(ticket));
    if (!result.ok() || result->has_value()) {
      children_.erase(ticket);
      if (result.ok()) {
        Timed timed(store_seconds_);
        (void)store_.Delete(id);  // succeeded: nothing to cancel
      } else {
        Forget(id);
      }
      if (!result.ok()) return result.status();
      return **std::move(result);
    }
    if (!keep_going()) return Status(StatusCode::kCancelled, "the trace was stopped");
    if (!RunOneHere()) {
      Timed timed(sleep_seconds_);
      std::this_thread::sleep_for(options_.poll);
    }
  }
}

void StoreTaskRunner::Drop(int64_t ticket) {
  const auto it = children_.find(ticket);
  if (it == children_.end()) return;
  const std::string id = it->second.id;
  children_.erase(it);
  kept_.erase(id);
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
