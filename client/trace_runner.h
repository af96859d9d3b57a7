// The trace job: every fold, period-doubling and grazing curve through a start orbit's branches in
// a box of two parameters, with their codimension-2 points (proto/drillbif/v1/trace.proto).
#ifndef DRILLBIF_CLIENT_TRACE_RUNNER_H_
#define DRILLBIF_CLIENT_TRACE_RUNNER_H_

#include "drillbif/common/status.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/v1/trace.pb.h"

namespace drillbif::client {

// Finds the start orbit as RunContinue does and traces. Errors: INVALID_ARGUMENT naming the field
// (trace_params not two different known names, min/max not one finite pair per parameter with
// min < max, a bound that is not a valid value of its parameter, the start outside the box,
// invalid params, initial_state or transient_periods); FAILED_PRECONDITION when the start state
// leads to no periodic orbit. `progress` (optional) is called from the calling thread with the
// fraction done and returns false to cancel (the result is then CANCELLED, with the curves traced
// so far).
StatusOr<v1::TraceResult> RunTrace(const v1::TraceRequest& request,
                                   const ProgressCallback& progress = {});

}  // namespace drillbif::client

#endif  // DRILLBIF_CLIENT_TRACE_RUNNER_H_
