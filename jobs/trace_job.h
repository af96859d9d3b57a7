// The trace job: every fold, period-doubling and grazing curve through a start orbit's branches in
// a box of two parameters, with their codimension-2 points (proto/drillbif/v1/trace.proto).
#ifndef DRILLBIF_JOBS_TRACE_JOB_H_
#define DRILLBIF_JOBS_TRACE_JOB_H_

#include <chrono>
#include <optional>
#include <utility>

#include "drillbif/common/status.h"
#include "drillbif/continuation/trace.h"
#include "drillbif/region/stability_region.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/v1/trace.pb.h"
#include "jobs/job_common.h"
#include "jobs/job_cost.h"
#include "jobs/run_context.h"

namespace drillbif::jobs {

// Largest region grid per parameter, whatever the limits configured.
inline constexpr int kMaxRegionNodes = 10001;
// Most TraceRequest.seeds: each seed is a 500-period simulation, an orbit solve and two branches
// over the box, none of which the cost estimate counts, so their number is bounded instead (one
// or a few seeds are the use; without a bound a 4 MB request held ~500000 of them).
inline constexpr int kMaxTraceSeeds = 100;

// A checked trace request as the engine takes it.
struct TracePlan {
  Params params;
  TraceOptions options;  // seed_state is the start search's initial state
  internal::StartSearch search;
  // The region's grid when the request asks for a region.
  std::optional<std::pair<int, int>> region_grid;
};

// Every check that needs no engine run: the two parameters, the box (finite, min < max, valid
// values, the start inside it), period options, seeds, curve steps, the region's grid, model
// parameters, initial state, transient. INVALID_ARGUMENT naming the field.
StatusOr<TracePlan> PlanTrace(const v1::TraceRequest& request);

// The cost of running `plan` (job_cost.h), from the box's size relative to the parameters'
// reference spans and the orbits' largest period; a rough upper estimate (docs/performance.md).
JobCost TraceCost(const TracePlan& plan);

// The cost of filling an n1 x n2 region grid.
JobCost RegionCost(int n1, int n2);

// Finds the start orbit as RunContinue does and traces; with `region` set, also computes the
// stability region around the start (which must then be a stable period-1 orbit). Errors:
// INVALID_ARGUMENT naming the field (trace_params not two different known names, min/max not one
// finite pair per parameter with min < max, a bound that is not a valid value of its parameter, the
// start outside the box, invalid params, initial_state or transient_periods); FAILED_PRECONDITION
// when the start state leads to no periodic orbit. `context.progress` is called from the calling
// thread with the fraction done and returns false to cancel (the result is then CANCELLED, with the
// curves traced so far). With `context.optimum_cache`, the curves of a trace of period-1 curves
// (and its region) are put there for later optimum jobs (jobs/optimum_cache.h) unless cancelled.
StatusOr<v1::TraceResult> RunTrace(const v1::TraceRequest& request, const RunContext& context = {});

namespace internal {

// The engine side of a trace request, shared with the optimum job.
struct EngineTrace {
  PeriodicOrbit start;
  TraceOptions options;
  TraceResult result;
  std::chrono::steady_clock::time_point started;
};

// Finds the start orbit of a checked request and traces; `progress` as in RunTrace, `on_curve`
// as TraceCurves'. CANCELLED when `progress` stopped the search for the start orbit. Exceptions
// are the caller's to catch.
StatusOr<EngineTrace> TraceCurvesOf(const TracePlan& plan, const ProgressCallback& progress,
                                    const TracedCurveCallback& on_curve = {});

// Whether a curve or a branch of the trace failed (a curve's termination, or a note of a branch
// or a start that failed): its curves may then miss some.
bool TraceFailed(const TraceResult& trace);

// The region options for the trace's box with an n1 x n2 grid.
RegionOptions RegionOptionsFor(const TraceOptions& trace, int n1, int n2);

}  // namespace internal

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_TRACE_JOB_H_
