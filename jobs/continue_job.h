// The continue job: a branch of periodic orbits followed in one parameter by pseudo-arclength
// continuation, with its special points (proto/drillbif/v1/continue.proto).
#ifndef DRILLBIF_JOBS_CONTINUE_JOB_H_
#define DRILLBIF_JOBS_CONTINUE_JOB_H_

#include "drillbif/common/status.h"
#include "drillbif/continuation/continuation.h"
#include "drillbif/v1/continue.pb.h"
#include "jobs/job_common.h"
#include "jobs/job_cost.h"
#include "jobs/run_context.h"

namespace drillbif::jobs {

// Largest ContinueRequest.max_steps, per direction, whatever the limits configured.
inline constexpr int kMaxContinuationSteps = 100'000;

// A checked continue request as the engine takes it.
struct ContinuePlan {
  ContinuationOptions options;
  Params params;
  int index = 0;  // of the continued parameter
  internal::StartSearch search;
  bool follow_period_doubling = false;
};

// Every check that needs no engine run: parameter name, range, start value inside it, step
// options, model parameters, initial state, transient. INVALID_ARGUMENT naming the field.
StatusOr<ContinuePlan> PlanContinue(const v1::ContinueRequest& request);

// The cost of running `plan` (job_cost.h): the start orbit's transient, the step budget, the
// branch points kept.
JobCost ContinueCost(const ContinuePlan& plan);

// Finds the start orbit by simulation from the initial state at the request's parameters, solves
// it by Newton, and follows its branch in `param` within [min, max]. Errors: PlanContinue's, and
// FAILED_PRECONDITION when the start state leads to no periodic orbit (chaos, or no return within
// the transient) or the orbit found is not admissible. `context.progress` is called at each
// accepted point with the fraction of the step budget (max_steps per direction) used.
StatusOr<v1::ContinueResult> RunContinue(const v1::ContinueRequest& request,
                                         const RunContext& context = {});

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_CONTINUE_JOB_H_
