// CvodePropagator: see the header for the design. Here: the options' and inputs' checks, FlowMap
// and the public wrappers. The SUNDIALS objects and their callbacks are in flow/cvode_integrator.h;
// Advance, with its event semantics, is in flow/cvode_advance.cc.
#include "drillbif/flow/cvode_propagator.h"

#include <cvodes/cvodes.h>

#include <cmath>
#include <exception>
#include <string>
#include <utility>

#include "flow/cvode_propagator_impl.h"
#include "flow/cvode_util.h"

namespace drillbif {

using internal::FormatDouble;

Status CvodeOptions::Validate() const {
  if (!(rtol > 0.0 && rtol <= 1e-2)) {
    return InvalidArgument("CvodeOptions.rtol must be in (0, 1e-2] (got " + FormatDouble(rtol) +
                           ")");
  }
  if (!(atol > 0.0) || !std::isfinite(atol)) {
    return InvalidArgument("CvodeOptions.atol must be finite and > 0 (got " + FormatDouble(atol) +
                           ")");
  }
  if (max_steps <= 0) {
    return InvalidArgument("CvodeOptions.max_steps must be > 0 (got " + std::to_string(max_steps) +
                           ")");
  }
  if (!std::isfinite(max_step_fraction)) {
    return InvalidArgument("CvodeOptions.max_step_fraction must be finite (got " +
                           FormatDouble(max_step_fraction) + ")");
  }
  return events.Validate();
}

Status CvodePropagator::Impl::CheckCommon(int mode, const StateVector& x0,
                                          const Params& params) const {
  Status st = options.Validate();
  if (!st.ok()) return st;
  if (mode < 0 || mode >= model.num_modes()) {
    return InvalidArgument("mode " + std::to_string(mode) + " is out of range [0, " +
                           std::to_string(model.num_modes()) + ")");
  }
  const int n = model.state_dim();
  if (n <= 0 || n > kMaxStateDim) {
    return InvalidArgument("model state dimension " + std::to_string(n) + " is outside [1, " +
                           std::to_string(kMaxStateDim) + "]");
  }
  if (x0.size() != n) {
    return InvalidArgument("x0 has " + std::to_string(x0.size()) + " components, the model " +
                           std::to_string(n));
  }
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(x0[i])) {
      return InvalidArgument("x0[" + std::to_string(i) + "] (" + model.state_names()[i] +
                             ") is not finite");
    }
  }
  if (params.size() != model.num_params()) {
    return InvalidArgument("params has " + std::to_string(params.size()) +
                           " components, the model " + std::to_string(model.num_params()));
  }
  return model.ValidateParams(params);
}

CvodePropagator::CvodePropagator(const HybridModel& model, CvodeOptions options)
    : model_(model),
      options_(std::move(options)),
      impl_(std::make_unique<Impl>(model_, options_)) {}

CvodePropagator::~CvodePropagator() = default;

std::unique_ptr<Propagator> CvodePropagator::Clone() const {
  return std::make_unique<CvodePropagator>(model_, options_);
}

FlowResult CvodePropagator::Impl::RunFlowMap(int mode, const StateVector& x0, double t,
                                             const Params& params, const FlowRequest& request) {
  FlowResult r;
  r.x = x0;
  r.status = CheckCommon(mode, x0, params);
  if (r.status.ok() && !(t >= 0.0 && std::isfinite(t))) {
    r.status =
        InvalidArgument("FlowMap time must be finite and >= 0 (got " + FormatDouble(t) + ")");
  }
  if (!r.status.ok()) return r;
  const int n = model.state_dim();
  const int np = model.num_params();
  if (request.state_jacobian) r.state_jacobian = StateMatrix::Identity(n, n);
  if (request.param_jacobian) r.param_jacobian = ParamMatrix::Zero(n, np);
  if (t == 0.0) return r;

  internal::CvodeIntegrator::Setup s;
  s.mode = mode;
  s.x0 = &x0;
  s.t_stop = t;
  s.state_sens = request.state_jacobian ? n : 0;
  s.param_sens = request.param_jacobian ? np : 0;
  Status st = integrator.Prepare(s, params);
  if (!st.ok()) {
    r.status = st;
    return r;
  }
  double tret = 0.0;
  const int flag = integrator.Integrate(t, CV_NORMAL, &tret);
  if (flag < 0) {
    r.status = integrator.Fail(flag, "CVode");
    return r;
  }
  r.x = integrator.State();
  if (s.state_sens + s.param_sens > 0) {
    st = integrator.FetchSensitivities();
    if (!st.ok()) {
      r.status = st;
      return r;
    }
    for (int c = 0; c < s.state_sens; ++c) r.state_jacobian.col(c) = integrator.Sensitivity(c);
    for (int k = 0; k < s.param_sens; ++k) {
      r.param_jacobian.col(k) = integrator.Sensitivity(s.state_sens + k);
    }
  }
  if (!r.x.allFinite() || (request.state_jacobian && !r.state_jacobian.allFinite()) ||
      (request.param_jacobian && !r.param_jacobian.allFinite())) {
    r.status = Internal("CVODES FlowMap produced a non-finite result in mode " +
                        std::string(model.mode_name(mode)) + " at t = " + FormatDouble(t));
  }
  return r;
}

FlowResult CvodePropagator::FlowMap(int mode, const StateVector& x0, double t, const Params& params,
                                    const FlowRequest& request) {
  if (!KeepGoing()) return CancelledFlow(model_, x0, request);
  try {
    impl_->integrator.set_progress(progress());
    FlowResult r = impl_->RunFlowMap(mode, x0, t, params, request);
    if (impl_->integrator.cancelled()) return CancelledFlow(model_, x0, request);
    return r;
  } catch (const std::exception& e) {
    FlowResult r;
    r.x = x0;
    r.status = Internal(std::string("CvodePropagator::FlowMap: ") + e.what());
    return r;
  } catch (...) {
    FlowResult r;
    r.x = x0;
    r.status = Internal("CvodePropagator::FlowMap: unknown exception");
    return r;
  }
}

AdvanceResult CvodePropagator::Advance(const AdvanceRequest& request, const Params& params) {
  if (!KeepGoing()) return CancelledAdvance(model_, request);
  try {
    impl_->integrator.set_progress(progress());
    AdvanceResult r = impl_->RunAdvance(request, params);
    if (impl_->integrator.cancelled()) return CancelledAdvance(model_, request);
    return r;
  } catch (const std::exception& e) {
    AdvanceResult r;
    r.x = request.x0;
    r.status = Internal(std::string("CvodePropagator::Advance: ") + e.what());
    return r;
  } catch (...) {
    AdvanceResult r;
    r.x = request.x0;
    r.status = Internal("CvodePropagator::Advance: unknown exception");
    return r;
  }
}

}  // namespace drillbif
