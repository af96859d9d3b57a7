// The simulate job: an event-driven simulation of the drifting oscillator from an initial state,
// with the outputs the request names (proto/drillbif/v1/simulate.proto).
#ifndef DRILLBIF_JOBS_SIMULATE_JOB_H_
#define DRILLBIF_JOBS_SIMULATE_JOB_H_

#include <memory>

#include "drillbif/common/status.h"
#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/propagator.h"
#include "drillbif/model/hybrid_model.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/v1/simulate.pb.h"
#include "jobs/job_cost.h"
#include "jobs/run_context.h"

namespace drillbif::jobs {

// Largest sampling window and trajectory, whatever the limits configured: the engine's counters
// and the result's sizes stay far from overflow below them.
inline constexpr int64_t kMaxSamplePeriods = 10'000'000;     // SimulateRequest.sample_periods
inline constexpr int64_t kMaxTrajectoryPoints = 10'000'000;  // per simulation

// The outputs a simulate request asks for: its `outputs`, or measures and Poincare samples when
// unset.
v1::SimulateRequest::Outputs EffectiveOutputs(const v1::SimulateRequest& request);

// A checked simulate request as the engine takes it.
struct SimulatePlan {
  SimulationOptions options;
  Params params;
  StateVector x0;
  bool cvode = false;  // the CVODE propagator (else the exact one)
  CvodeOptions cvode_options;

  // The propagator the request asks for.
  std::unique_ptr<Propagator> MakePropagator() const;
};

// Every check that needs no engine run: outputs, periods, trajectory size, model parameters,
// initial state, propagator and its tolerance. INVALID_ARGUMENT naming the field otherwise.
StatusOr<SimulatePlan> PlanSimulate(const v1::SimulateRequest& request);

// The cost of running `plan` (job_cost.h): forcing periods simulated, result size by output.
JobCost SimulateCost(const SimulatePlan& plan);

// Runs a simulation. Errors: PlanSimulate's. A run that is stopped by the progress callback is a
// result with status CANCELLED and the outputs recorded until then.
StatusOr<v1::SimulateResult> RunSimulate(const v1::SimulateRequest& request,
                                         const RunContext& context = {});

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_SIMULATE_JOB_H_
