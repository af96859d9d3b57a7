#include "drillbif/flow/propagator.h"

#include <algorithm>
#include <cmath>

namespace drillbif {

Status EventOptions::Validate() const {
  if (!(tolerance > 0.0 && tolerance <= 1e-3)) {
    return InvalidArgument("event tolerance must be in (0, 1e-3], got " +
                           std::to_string(tolerance));
  }
  if (!(time_rtol >= 1e-16 && time_rtol <= 1e-3)) {
    return InvalidArgument("event time_rtol must be in [1e-16, 1e-3], got " +
                           std::to_string(time_rtol));
  }
  if (max_iterations <= 0) return InvalidArgument("event max_iterations must be > 0");
  return Status::Ok();
}

FlowResult Propagator::CancelledFlow(const HybridModel& model, const StateVector& x0,
                                     const FlowRequest& request) const {
  FlowResult r;
  r.status = Cancelled("flow cancelled");
  r.x = x0;
  const int n = static_cast<int>(x0.size());
  if (request.state_jacobian) r.state_jacobian = StateMatrix::Identity(n, n);
  if (request.param_jacobian) r.param_jacobian = ParamMatrix::Zero(n, model.num_params());
  return r;
}

AdvanceResult Propagator::CancelledAdvance(const HybridModel& model,
                                           const AdvanceRequest& request) const {
  AdvanceResult r;
  r.status = Cancelled("advance cancelled");
  r.end = AdvanceEnd::kFailed;
  r.x = request.x0;
  if (request.measures) {
    r.measures =
        MeasureVector::Zero(std::min(static_cast<int>(model.measure_names().size()), kMaxMeasures));
  }
  return r;
}

}  // namespace drillbif
