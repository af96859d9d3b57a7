// The optimum job: the robust ROP optimum over the stability region of period-1 motion
// (proto/drillbif/v1/optimum.proto): the curves, the region on a grid, then the query.
#ifndef DRILLBIF_JOBS_OPTIMUM_RUNNER_H_
#define DRILLBIF_JOBS_OPTIMUM_RUNNER_H_

#include "drillbif/common/status.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/v1/optimum.pb.h"
#include "jobs/optimum_cache.h"

namespace drillbif::jobs {

// Errors: INVALID_ARGUMENT naming the field (margin, scaled, grid, trace.region, and every trace
// error of RunTrace under trace.); FAILED_PRECONDITION when the start orbit is not a stable
// period-1 orbit. A search that finds no node with the margin is a result (status NOT_FOUND).
// `progress` as in RunTrace. With a `cache`, curves and a region it holds for the request's trace
// (and grid) are used instead of computed (OptimumResult.curves_reused, region_reused), and those
// computed are put there.
StatusOr<v1::OptimumResult> RunOptimum(const v1::OptimumRequest& request,
                                       const ProgressCallback& progress = {},
                                       OptimumCache* cache = nullptr);

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_OPTIMUM_RUNNER_H_
