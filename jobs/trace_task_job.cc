#include "jobs/trace_task_job.h"

#include <optional>
#include <string>
#include <variant>
#include <vector>

#include "drillbif/continuation/trace_tasks.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/v1/optimum.pb.h"
#include "jobs/job_common.h"
#include "jobs/request_bytes.h"
#include "jobs/trace_job.h"
#include "jobs/trace_task_codec.h"

namespace drillbif::jobs {

namespace {

// INVALID_ARGUMENT naming `field` unless the orbit's parameters are the model's, its signature
// names the model's modes and guards, and it has a start state and a duration per segment.
Status CheckSignature(const std::string& field, const PeriodicOrbit& orbit) {
  if (Status s = internal::Model().ValidateParams(orbit.params); !s.ok()) {
    return InvalidArgument(field + ".params: " + s.message());
  }
  // Indices only: the forms the trace passes between its steps need not be orbits a client may
  // ask for (a candidate's tangent end may be followed by another mode: ValidateSignature refuses
  // that).
  const Signature& signature = orbit.signature;
  if (signature.periods < 1 || signature.segments.empty()) {
    return InvalidArgument(field + ".signature: needs periods >= 1 and a segment");
  }
  for (size_t i = 0; i < signature.segments.size(); ++i) {
    const SegmentSpec& seg = signature.segments[i];
    if (seg.mode < 0 || seg.mode >= internal::Model().num_modes() || seg.guard < -1 ||
        seg.guard >= static_cast<int>(internal::Model().guards(seg.mode).size())) {
      return InvalidArgument(field + ".signature: segment " + std::to_string(i) +
                             " names no mode or guard of the model");
    }
  }
  const size_t n = orbit.signature.segments.size();
  if (orbit.starts.size() != n || orbit.durations.size() != n) {
    return InvalidArgument(field + ": " + std::to_string(n) + " segments need as many starts (" +
                           std::to_string(orbit.starts.size()) + ") and durations (" +
                           std::to_string(orbit.durations.size()) + ")");
  }
  for (const StateVector& x : orbit.starts) {
    if (x.size() != internal::Model().state_dim()) {
      return InvalidArgument(field + ".starts: a state of " + std::to_string(x.size()) +
                             " components, the model has " +
                             std::to_string(internal::Model().state_dim()));
    }
  }
  return Status::Ok();
}

Status CheckOrbits(const TraceTask& task) {
  if (const auto* curve = std::get_if<CurveTask>(&task)) {
    return CheckSignature("curve.start.point.orbit", curve->start.point.orbit);
  }
  if (const auto* at = std::get_if<CandidatesTask>(&task)) {
    return CheckSignature("candidates.point.point.orbit", at->point.point.orbit);
  }
  const auto& run = std::get<CandidateTask>(task);
  if (Status s = CheckSignature("candidate_run.point.point.orbit", run.point.point.orbit);
      !s.ok() || !run.candidate.orbit.ok()) {
    return s;
  }
  return CheckSignature("candidate_run.candidate.orbit", *run.candidate.orbit);
}

// The decoded tasks and the parent's plan.
struct Decoded {
  TracePlan plan;
  std::vector<TraceTask> tasks;
};

StatusOr<Decoded> Decode(const v1::TraceTaskBatch& request) {
  DRILLBIF_ASSIGN_OR_RETURN(DecodedTraceTaskBatch decoded, DecodeTraceTaskBatch(request));
  v1::TraceRequest parent;
  if (!parent.ParseFromString(decoded.trace_request)) {
    return InvalidArgument("trace_request: not a drillbif.v1.TraceRequest");
  }
  StatusOr<TracePlan> plan = PlanTrace(parent);
  if (!plan.ok()) return InvalidArgument("trace_request: " + plan.status().message());
  for (size_t i = 0; i < decoded.tasks.size(); ++i) {
    if (Status s = CheckOrbits(decoded.tasks[i]); !s.ok()) {
      return InvalidArgument("tasks[" + std::to_string(i) + "]." + s.message());
    }
  }
  return Decoded{*std::move(plan), std::move(decoded.tasks)};
}

}  // namespace

StatusOr<TraceTaskPlan> PlanTraceTask(const v1::TraceTaskBatch& request) {
  DRILLBIF_ASSIGN_OR_RETURN(const Decoded decoded, Decode(request));
  return TraceTaskPlan{request};
}

JobCost TraceTaskCost(const TraceTaskPlan&) { return JobCost{}; }

namespace {

// The task under the plan's options on a propagator of its own that polls `progress`; nullopt
// when a stop ended it (or came before it started).
std::optional<TraceTaskResult> RunUnder(const TracePlan& plan, const TraceTask& task,
                                        const ProgressCallback& progress) {
  if (progress && !progress(0.0)) return std::nullopt;
  ExactPropagator propagator(internal::Model());
  ProgressThrottle throttle(progress);
  propagator.set_progress(&throttle);
  TraceTaskResult result = RunTraceTask(internal::Model(), propagator, plan.options, task);
  if (throttle.stopped()) return std::nullopt;
  return result;
}

}  // namespace

StatusOr<v1::TraceTaskBatchResponse> RunTraceTaskJob(const v1::TraceTaskBatch& request,
                                                     const RunContext& context) {
  DRILLBIF_ASSIGN_OR_RETURN(const Decoded decoded, Decode(request));
  std::vector<TraceTaskResult> results;
  const double n = static_cast<double>(decoded.tasks.size());
  for (const TraceTask& task : decoded.tasks) {
    // Each task its share of the child's progress.
    const double done = static_cast<double>(results.size());
    ProgressCallback progress;
    if (context.progress) progress = [&](double f) { return context.progress((done + f) / n); };
    std::optional<TraceTaskResult> result = RunUnder(decoded.plan, task, progress);
    if (!result.has_value()) {
      v1::TraceTaskBatchResponse cancelled;
      cancelled.set_status("CANCELLED");
      return cancelled;
    }
    results.push_back(*std::move(result));
  }
  return TraceTaskBatchResponseOf(results);
}

StatusOr<LocalTraceTasks> LocalTraceTasks::ForRequest(std::string_view trace_request) {
  v1::TraceRequest parent;
  if (!parent.ParseFromArray(trace_request.data(), static_cast<int>(trace_request.size()))) {
    return InvalidArgument("trace_request: not a drillbif.v1.TraceRequest");
  }
  DRILLBIF_ASSIGN_OR_RETURN(TracePlan plan, PlanTrace(parent));
  return LocalTraceTasks(std::move(plan), std::string(trace_request));
}

StatusOr<LocalTraceTasks> LocalTraceTasks::ForJob(v1::JobKind kind, std::string_view request) {
  if (kind == v1::TRACE) return ForRequest(request);
  if (kind != v1::OPTIMUM) {
    return Status(StatusCode::kNotFound,
                  std::string(v1::JobKind_Name(kind)) + " jobs have no trace to fan out");
  }
  v1::OptimumRequest optimum;
  if (!optimum.ParseFromArray(request.data(), static_cast<int>(request.size()))) {
    return InvalidArgument("request: not a drillbif.v1.OptimumRequest");
  }
  return ForRequest(DeterministicBytes(optimum.trace()));
}

StatusOr<TraceTaskResult> LocalTraceTasks::Run(const TraceTask& task,
                                               const std::function<bool()>& keep_going) const {
  std::optional<TraceTaskResult> result =
      RunUnder(plan_, task, [&keep_going](double) { return keep_going(); });
  if (!result.has_value()) return Status(StatusCode::kCancelled, "the trace was stopped");
  return *std::move(result);
}

}  // namespace drillbif::jobs
