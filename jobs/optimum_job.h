// The optimum job: the robust ROP optimum over the stability region of period-1 motion
// (proto/drillbif/v1/optimum.proto): the curves, the region on a grid, then the query.
#ifndef DRILLBIF_JOBS_OPTIMUM_JOB_H_
#define DRILLBIF_JOBS_OPTIMUM_JOB_H_

#include <optional>
#include <utility>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/region/robust_optimum.h"
#include "drillbif/v1/optimum.pb.h"
#include "jobs/job_cost.h"
#include "jobs/optimum_cache.h"
#include "jobs/run_context.h"
#include "jobs/trace_job.h"

namespace drillbif::jobs {

// A checked optimum request as the engine takes it.
struct OptimumPlan {
  OptimumOptions options;
  TracePlan trace;
  std::pair<int, int> grid;  // the region's grid: the request's, or one following the margin
};

// Every check that needs no engine run: margin, scaled, grid, and every check of PlanTrace on
// `trace` (INVALID_ARGUMENT naming the field, "trace." before the trace's fields).
StatusOr<OptimumPlan> PlanOptimum(const v1::OptimumRequest& request);

// The cost of running `plan` from scratch (job_cost.h): the trace, the region, the query and the
// coexistence check. (A run that reuses cached curves costs far less.)
JobCost OptimumCost(const OptimumPlan& plan);

// What an optimum run knows beyond its result, for an optimum map's cell (optimum_map_job.h): set
// when the run completed its query.
struct OptimumDetail {
  std::optional<PeriodicOrbit> orbit;      // the optimum's orbit, when a start settled on it
  std::vector<BoundarySegment> obstacles;  // the region's boundary off the box
  std::vector<CurveKind> kinds;            // the kind of each traced curve (obstacles' `curve`)
  std::shared_ptr<const StabilityRegion> region;  // the region searched
  std::shared_ptr<const OptimumCurves> curves;    // the curves it was bounded by
  OptimumOptions options;                         // the margin
  double width1 = 0.0, width2 = 0.0;              // the box
};

// Errors: INVALID_ARGUMENT naming the field (margin, scaled, grid, trace.region, and every trace
// error of RunTrace under trace.); FAILED_PRECONDITION when the start orbit is not a stable
// period-1 orbit. A search that finds no node with the margin is a result (status NOT_FOUND).
// `context.progress` as in RunTrace. With `context.optimum_cache`, curves and a region it holds
// for the request's trace (and grid) are used instead of computed (OptimumResult.curves_reused,
// region_reused), and those computed are put there.
StatusOr<v1::OptimumResult> RunOptimum(const v1::OptimumRequest& request,
                                       const RunContext& context = {});
// The same, and `detail` gets the above.
StatusOr<v1::OptimumResult> RunOptimumWithDetail(const v1::OptimumRequest& request,
                                                 const RunContext& context, OptimumDetail* detail);

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_OPTIMUM_JOB_H_
