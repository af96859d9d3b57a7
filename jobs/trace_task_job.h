// The child jobs of a fanned-out trace: each a batch of consecutive tasks of the parent's trace
// (continuation/trace_tasks.h), its request the parent's TraceRequest and the tasks, its result
// the tasks' results in order (jobs/trace_task_codec.h, proto/drillbif/v1/trace_task.proto).
// Workers run them like any job (the registry's child kind, FindChildKind); clients never submit
// them.
#ifndef DRILLBIF_JOBS_TRACE_TASK_JOB_H_
#define DRILLBIF_JOBS_TRACE_TASK_JOB_H_

#include <functional>
#include <string>
#include <string_view>
#include <utility>

#include "drillbif/common/status.h"
#include "drillbif/continuation/trace_tasks.h"
#include "drillbif/v1/service.pb.h"
#include "drillbif/v1/trace_task.pb.h"
#include "jobs/job_cost.h"
#include "jobs/run_context.h"
#include "jobs/trace_job.h"

namespace drillbif::jobs {

// The store's kind string of a trace's child jobs.
inline constexpr char kTraceTaskKind[] = "trace_task";

// A child job's request checked: the parent's trace request plans (PlanTrace), the batch holds
// 1 .. kMaxTraceTaskBatch tasks and their orbits name the model's modes and guards.
// INVALID_ARGUMENT naming the field otherwise ("tasks[2].curve.start.point.orbit...").
struct TraceTaskPlan {
  v1::TraceTaskBatch request;
};
StatusOr<TraceTaskPlan> PlanTraceTask(const v1::TraceTaskBatch& request);
// Nothing is admitted on it: the parent was admitted with the whole trace's cost.
JobCost TraceTaskCost(const TraceTaskPlan& plan);

// Runs the batch's tasks in order under the parent's options, as the parent's trace would
// (RunTraceTask), each on a propagator of its own that polls `context.progress` (each task its
// share of the progress): a stop gives status "CANCELLED" and no results; else "COMPLETED" with
// one result per task. Errors: INVALID_ARGUMENT for a malformed request.
StatusOr<v1::TraceTaskBatchResponse> RunTraceTaskJob(const v1::TraceTaskBatch& request,
                                                     const RunContext& context);

// A fanned-out trace's tasks run in the parent's own process, as their child jobs would run them
// (the same results): for the tasks the parent keeps rather than store.
class LocalTraceTasks {
 public:
  // INVALID_ARGUMENT when the parent's serialized TraceRequest does not plan.
  static StatusOr<LocalTraceTasks> ForRequest(std::string_view trace_request);
  // The tasks of a job of `kind` whose trace fans out: a trace (its request), an optimum (its
  // request's trace). INVALID_ARGUMENT for a request that does not plan, NOT_FOUND for a kind
  // with no trace of its own.
  static StatusOr<LocalTraceTasks> ForJob(v1::JobKind kind, std::string_view request);
  // The serialized TraceRequest the tasks run under: what a child job's request carries.
  const std::string& trace_request() const { return trace_request_; }
  // The task's result; CANCELLED once `keep_going` (polled every few ms) returns false.
  StatusOr<TraceTaskResult> Run(const TraceTask& task,
                                const std::function<bool()>& keep_going) const;

 private:
  LocalTraceTasks(TracePlan plan, std::string trace_request)
      : plan_(std::move(plan)), trace_request_(std::move(trace_request)) {}
  TracePlan plan_;
  std::string trace_request_;
};

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_TRACE_TASK_JOB_H_
