// A trace's tasks as values, so that they can run elsewhere: on another thread, in another
// process, on another machine.
//
// TraceCurves (trace.h) computes most of its work in tasks: the curve through one located start,
// the curves that may leave one codimension-2 point (its candidates), and the run of one
// candidate (its step-off and curve). A task reads only its inputs (a TraceTask) and the trace's
// model and options, and gives a TraceTaskResult; the trace applies the results in the order one
// thread computes them, so the network does not depend on who ran a task, when, or how often.
//
// By default the trace runs its tasks on its own threads (TraceOptions::threads). With
// TraceOptions::task_runner it hands them to that runner instead: the service's runner stores
// them as child jobs, which any worker computes with RunTraceTask under the same model and
// options (the parent's request), and the parent computes too while it waits.
#ifndef DRILLBIF_CONTINUATION_TRACE_TASKS_H_
#define DRILLBIF_CONTINUATION_TRACE_TASKS_H_

#include <cstddef>
#include <cstdint>
#include <functional>
#include <utility>
#include <variant>
#include <vector>

#include "drillbif/continuation/curve.h"

namespace drillbif {

struct TraceOptions;  // continuation/trace.h

// A curve to try from a codimension-2 point: its start orbit, the kind of its point and curve.
struct SwitchCandidate {
  StatusOr<PeriodicOrbit> orbit{PeriodicOrbit{}};  // not OK where the point has no such start
  SpecialPointKind seed_kind = SpecialPointKind::kFold;
  CurveKind kind = CurveKind::kFold;
  int step_off = -1;  // a zero-length segment of `orbit` to step off from (-1: none)
};

// What a candidate's run computed: the starts tried in turn, each with its curve; the last one
// decides (a curve that failed, or one that got away from the point).
struct CandidateRun {
  bool deferred = false;  // no regular step-off length gave an admissible start
  bool stopped = false;   // the last try was cut short by a stop
  std::vector<std::pair<SpecialPoint, CurveResult>> tries;
};

// The curve through a located start. `axis` names the start's branch parameter: 0 for the
// trace's param1, 1 for param2 (the curve's values are then in (param2, param1) order).
struct CurveTask {
  SpecialPoint start;
  int axis = 0;
};

// The candidates at codimension-2 point `point` of a curve of kind `from_kind`.
struct CandidatesTask {
  CurveKind from_kind = CurveKind::kFold;
  Codim2Point point;
};

// The run of one candidate at `point`; `last_resort`: the step-off lengths of the last round.
struct CandidateTask {
  Codim2Point point;
  SwitchCandidate candidate;
  bool last_resort = false;
};

using TraceTask = std::variant<CurveTask, CandidatesTask, CandidateTask>;
// The result of each TraceTask alternative, at the same index.
using TraceTaskResult = std::variant<CurveResult, std::vector<SwitchCandidate>, CandidateRun>;

// Computes a task as the trace does, on `propagator` (a stop of the propagator's throttle ends
// it early: the result is then not to be used). Without options.vertex_states, the curves' interior
// vertices come without the states the trace would drop before reading them (less to carry).
TraceTaskResult RunTraceTask(const HybridModel& model, Propagator& propagator,
                             const TraceOptions& options, const TraceTask& task);

// Runs a trace's tasks somewhere else (TraceOptions::task_runner). Called from the trace's
// thread only. The trace submits a task, may ask whether it is done, and takes its result, or
// drops it when the result is no longer needed; every ticket is taken or dropped once.
class TraceTaskRunner {
 public:
  virtual ~TraceTaskRunner() = default;

  // How many tasks the trace may have submitted and not taken or dropped (>= 1).
  virtual size_t window() const = 0;
  // Hands a task out; its ticket. An error ends the trace failed.
  virtual StatusOr<int64_t> Submit(const TraceTask& task) = 0;
  // Whether the task's result is there (Take would not wait).
  virtual bool Ready(int64_t ticket) = 0;
  // The task's result, waiting for it while `keep_going` returns true (polled at least every
  // ~10 ms); CANCELLED once it returns false; another error when the task could not be run
  // (the trace ends failed with it).
  virtual StatusOr<TraceTaskResult> Take(int64_t ticket,
                                         const std::function<bool()>& keep_going) = 0;
  // The result is not needed: the runner may stop computing it.
  virtual void Drop(int64_t ticket) = 0;
};

}  // namespace drillbif

#endif  // DRILLBIF_CONTINUATION_TRACE_TASKS_H_
