// The sweep job: a brute-force bifurcation diagram, simulating at each value of a parameter grid
// and recording Poincare samples (proto/drillbif/v1/sweep.proto).
#ifndef DRILLBIF_JOBS_SWEEP_JOB_H_
#define DRILLBIF_JOBS_SWEEP_JOB_H_

#include <cstdint>

#include "drillbif/common/status.h"
#include "drillbif/model/hybrid_model.h"
#include "drillbif/simulate/sweep.h"
#include "drillbif/v1/sweep.pb.h"
#include "jobs/job_cost.h"
#include "jobs/run_context.h"

namespace drillbif::jobs {

// Largest request whatever the limits configured.
inline constexpr int64_t kMaxSweepSamples = 10'000'000;  // Poincare samples of one sweep
inline constexpr int kMaxSweepThreads = 512;

// A checked sweep request as the engine takes it.
struct SweepPlan {
  SweepOptions options;
  Params params;
  StateVector x0;
};

// Every check that needs no engine run: parameter name, range, steps, periods, threads, model
// parameters at both ends, initial state. INVALID_ARGUMENT naming the field otherwise.
StatusOr<SweepPlan> PlanSweep(const v1::SweepRequest& request);

// The cost of running `plan` (job_cost.h): forcing periods over the grid, samples recorded.
JobCost SweepCost(const SweepPlan& plan);

// Runs a parameter sweep. Errors: PlanSweep's. `context.progress` is called about every 10 ms
// with the fraction of grid values done.
StatusOr<v1::SweepResult> RunSweep(const v1::SweepRequest& request, const RunContext& context = {});

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_SWEEP_JOB_H_
