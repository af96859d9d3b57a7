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

bool KeptWhole(int max_period, const CurveResult& c) {
  return c.kind == CurveKind::kPeriodDoubling && !c.points.empty() &&
         2 * c.points.front().orbit.signature.periods <= max_period;
}

void DropVertexStates(int max_period, CurveResult* c) {
  std::vector<CurvePoint>& points = c->points;
  if (points.size() < 3 || KeptWhole(max_period, *c)) return;
  for (size_t k = 1; k + 1 < points.size(); ++k) {
    std::vector<StateVector>().swap(points[k].orbit.starts);
    points[k].stability.monodromy.resize(0, 0);
  }
}

CurveOptions SwitchCurveOptions(const TraceOptions& options) {
  CurveOptions co = options.curve;
  co.box() = options.box();
  return co;
}

}  // namespace internal

namespace {

TraceTaskResult Compute(const HybridModel& model, Propagator& propagator,
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

}  // namespace

TraceTaskResult RunTraceTask(const HybridModel& model, Propagator& propagator,
                             const TraceOptions& options, const TraceTask& task) {
  TraceTaskResult result = Compute(model, propagator, options, task);
  // Without vertex_states the trace drops these at its next report anyway, before it reads them
  // (internal::DropVertexStates): not carried, they do not cost the runner their bytes.
  if (!options.vertex_states) {
    if (auto* curve = std::get_if<CurveResult>(&result)) {
      internal::DropVertexStates(options.max_period, curve);
    } else if (auto* run = std::get_if<CandidateRun>(&result)) {
      for (auto& [seed, tried] : run->tries) internal::DropVertexStates(options.max_period, &tried);
    }
  }
  return result;
}

}  // namespace drillbif
