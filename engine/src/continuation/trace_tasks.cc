// RunTraceTask (continuation/trace_tasks.h): each task as the trace computes it on its threads.
#include "drillbif/continuation/trace_tasks.h"

#include <utility>

#include "continuation/trace_internal.h"

namespace drillbif {

namespace internal {

CurveResult CurveThroughStart(const HybridModel& model, Propagator& propagator,
                              const TraceOptions& options, const SpecialPoint& start, int axis) {
  CurveOptions co = options.curve;
  const bool swapped = axis == 1;
  co.param1 = swapped ? options.param2 : options.param1;
  co.min1 = swapped ? options.min2 : options.min1;
  co.max1 = swapped ? options.max2 : options.max1;
  co.param2 = swapped ? options.param1 : options.param2;
  co.min2 = swapped ? options.min1 : options.min2;
  co.max2 = swapped ? options.max1 : options.max2;
  // The options' crossings1 / crossings2 are values of param1 / param2 of the trace.
  if (swapped) std::swap(co.crossings1, co.crossings2);
  return ContinueCurve(model, propagator, start, co);
}

CurveOptions SwitchCurveOptions(const TraceOptions& options) {
  CurveOptions co = options.curve;
  co.box() = options.box();
  return co;
}

}  // namespace internal

TraceTaskResult RunTraceTask(const HybridModel& model, Propagator& propagator,
                             const TraceOptions& options, const TraceTask& task) {
  if (const auto* curve = std::get_if<CurveTask>(&task)) {
    return internal::CurveThroughStart(model, propagator, options, curve->start, curve->axis);
  }
  if (const auto* at = std::get_if<CandidatesTask>(&task)) {
    return internal::CandidatesAt(model, propagator, at->from_kind, at->point);
  }
  const auto& run = std::get<CandidateTask>(task);
  return internal::RunCandidate(model, propagator, options, internal::SwitchCurveOptions(options),
                                model.ParamIndex(options.param1).value(),
                                model.ParamIndex(options.param2).value(), run.point, run.candidate,
                                run.last_resort);
}

}  // namespace drillbif
