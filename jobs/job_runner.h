// The job runner: the one boundary between the API (drillbif.v1 request and result protos) and the
// engine. A request is validated and converted into engine options, the engine runs, and its result
// is converted back into a result proto. No command line and no I/O here, so that the service can
// reuse it as is.
//
// Errors: an invalid request (a parameter outside its domain, an unknown swept parameter, a bad
// option, an inadmissible initial state) is an INVALID_ARGUMENT status whose message names the
// offending field; a continuation whose start state leads to no periodic orbit is a
// FAILED_PRECONDITION status (there is nothing to continue). A run that starts and then fails or is
// cancelled is not an error: it is a result with status "FAILED" or "CANCELLED", a message and
// whatever was computed before it stopped.
#ifndef DRILLBIF_JOBS_JOB_RUNNER_H_
#define DRILLBIF_JOBS_JOB_RUNNER_H_

#include <functional>

#include "drillbif/common/status.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/v1/continue.pb.h"
#include "drillbif/v1/simulate.pb.h"
#include "drillbif/v1/sweep.pb.h"

namespace drillbif::jobs {

// Limits on what one request may make the engine hold in memory (see the proto comments).
inline constexpr long long kMaxSamplePeriods = 10'000'000;     // SimulateRequest.sample_periods
inline constexpr long long kMaxTrajectoryPoints = 10'000'000;  // per simulation
inline constexpr long long kMaxSweepSamples = 10'000'000;      // Poincare samples of one sweep
inline constexpr int kMaxSweepThreads = 512;
inline constexpr int kMaxContinuationSteps = 100'000;  // ContinueRequest.max_steps, per direction

// The outputs a simulate request asks for: its `outputs`, or measures and Poincare samples when
// unset.
v1::SimulateRequest::Outputs EffectiveOutputs(const v1::SimulateRequest& request);

// Runs a simulation. `progress` (optional) receives the fraction done in [0, 1] from the calling
// thread and returns false to cancel (the result is then CANCELLED, with partial outputs).
StatusOr<v1::SimulateResult> RunSimulate(const v1::SimulateRequest& request,
                                         const ProgressCallback& progress = {});

// Receives the current value of the swept or continued parameter (a sweep: the grid point finished
// last, about every 10 ms; a continuation: each accepted point), for progress displays: the
// service records it as the job's current value.
using ValueCallback = std::function<void(double value)>;

// Runs a parameter sweep. `progress` (optional) is called from the calling thread about every
// 10 ms with the fraction of grid values done, and returns false to cancel.
StatusOr<v1::SweepResult> RunSweep(const v1::SweepRequest& request,
                                   const ProgressCallback& progress = {},
                                   const ValueCallback& on_value = {});

// Runs a one-parameter continuation: finds the start orbit by simulation from the initial state at
// the request's parameters, solves it by Newton, and follows its branch in `param` within
// [min, max]. Errors: INVALID_ARGUMENT naming the field for an invalid request (unknown param,
// empty or invalid range, start value of param outside [min, max], invalid model parameters,
// initial state or step options); FAILED_PRECONDITION when the start state leads to no periodic
// orbit (chaos, or no return within the transient) or the orbit found is not admissible.
// `progress` (optional) is called from the calling thread at each accepted point with the fraction
// of the step budget (max_steps per direction) used, and returns false to cancel (the result is
// then CANCELLED, with the points found so far).
StatusOr<v1::ContinueResult> RunContinue(const v1::ContinueRequest& request,
                                         const ProgressCallback& progress = {},
                                         const ValueCallback& on_value = {});

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_JOB_RUNNER_H_
