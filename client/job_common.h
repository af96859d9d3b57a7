// What every job runner needs, in one place: the shared model instance, the conversions between
// the API's model parameters and state and the engine's, the start orbit of a continuation, and
// small helpers for messages. Internal to the client library.
#ifndef DRILLBIF_CLIENT_JOB_COMMON_H_
#define DRILLBIF_CLIENT_JOB_COMMON_H_

#include <chrono>
#include <string>

#include "drillbif/common/status.h"
#include "drillbif/model/drifting_oscillator.h"
#include "drillbif/orbit/periodic_orbit.h"
#include "drillbif/v1/model.pb.h"

namespace drillbif::client::internal {

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

Status FailedPrecondition(std::string message);

// The start orbit: simulation from x0, a period read off the Poincare returns, then Newton.
// FAILED_PRECONDITION when there is none to be found from x0.
StatusOr<PeriodicOrbit> StartOrbit(Propagator& propagator, const Params& params,
                                   const StateVector& x0, int transient_periods);

}  // namespace drillbif::client::internal

#endif  // DRILLBIF_CLIENT_JOB_COMMON_H_
