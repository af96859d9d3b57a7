// What every job runner needs, in one place: the shared model instance, the conversions between
// the API's model parameters and state and the engine's, the start orbit of a continuation, and
// small helpers for messages. Internal to the client library.
#ifndef DRILLBIF_JOBS_JOB_COMMON_H_
#define DRILLBIF_JOBS_JOB_COMMON_H_

#include <chrono>
#include <initializer_list>
#include <string>
#include <utility>

#include "drillbif/common/status.h"
#include "drillbif/common/termination.h"
#include "drillbif/model/drifting_oscillator.h"
#include "drillbif/orbit/periodic_orbit.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/v1/model.pb.h"
#include "drillbif/v1/simulate.pb.h"

namespace drillbif::jobs::internal {

using Osc = DriftingOscillator;

// The model is stateless once built; one shared instance serves every job and thread.
const Osc& Model();

// Shortest decimal form of a double, for messages.
std::string Num(double v);

// Seconds since `start`.
double Seconds(std::chrono::steady_clock::time_point start);

// Unset fields keep the reference values of DriftingOscillator::MakeParams().
Params ToEngineParams(const v1::ModelParams& m);
// The request's initial state, or the model's default when unset.
StateVector ToEngineState(bool has_state, const v1::State& s);
v1::ModelParams ToProtoParams(const Params& p);

// The start orbit: simulation from x0, a period read off the Poincare returns, then Newton.
// FAILED_PRECONDITION when there is none to be found from x0; CANCELLED when `progress` stopped
// the search.
StatusOr<PeriodicOrbit> StartOrbit(Propagator& propagator, const Params& params,
                                   const StateVector& x0, int transient_periods,
                                   const ProgressCallback& progress = {});

// `progress` for a stage that covers [lo, hi] of a run's progress: the stage's own fraction f
// is reported as lo + (hi - lo) f. Empty when `progress` is.
ProgressCallback StageProgress(const ProgressCallback& progress, double lo, double hi);

// Every value in `bounds` ({field, value}) is a valid value of parameter `index` with the other
// parameters as in `params`; else INVALID_ARGUMENT "field: why".
Status CheckParamValues(const Params& params, int index,
                        std::initializer_list<std::pair<const char*, double>> bounds);

// Where the start orbit of a request with `initial_state` and `transient_periods` (continue,
// trace) is looked for: the forcing periods (unset: GuessOptions' default) and the validated
// initial state. INVALID_ARGUMENT for transient_periods < 0 or an invalid state.
struct StartSearch {
  StateVector x0;
  int transient_periods = 0;
};
template <typename Request>
StatusOr<StartSearch> StartSearchOf(const Request& request, const Params& params) {
  StartSearch out;
  out.transient_periods = request.has_transient_periods() ? request.transient_periods()
                                                          : GuessOptions().transient_periods;
  if (out.transient_periods < 0) {
    return InvalidArgument("transient_periods must be >= 0, got " +
                           std::to_string(out.transient_periods));
  }
  out.x0 = ToEngineState(request.has_initial_state(), request.initial_state());
  if (Status s = Model().ValidateState(out.x0, params, SimulationOptions().state_tolerance);
      !s.ok()) {
    return s;
  }
  return out;
}

// How a run ended, as the results' `status` field (every result of the API has `status` and
// `message`): the termination's name, except "NOT_FOUND" for a search that failed finding
// nothing (status NOT_FOUND: the optimum) and "FAILED" for kNoConvergence, which no result lists
// (an orbit that does not converge fails the run that needs it).
const char* ResultStatus(const RunSummary& summary);
const char* ResultStatus(Termination termination);

// A result's `status` and `message` from how its run ended: every job maps the engine's
// summaries onto its protos here, so that the one vocabulary reads the same in every result.
template <typename Result>
void SetRunEnd(const RunSummary& summary, Result* out) {
  out->set_status(ResultStatus(summary));
  out->set_message(summary.message);
}
// The same for a run that ended outside the engine's summaries (e.g. cancelled while looking for
// the start orbit, or a job-level verdict over several of them).
template <typename Result>
void SetRunEnd(Termination termination, const std::string& message, Result* out) {
  out->set_status(ResultStatus(termination));
  out->set_message(message);
}

// The API's mode of an engine mode index.
v1::Mode ToProtoMode(int mode);
// A Poincare sample as the API's point.
void ToProto(const PoincareSample& in, v1::PoincarePoint* out);

}  // namespace drillbif::jobs::internal

#endif  // DRILLBIF_JOBS_JOB_COMMON_H_
