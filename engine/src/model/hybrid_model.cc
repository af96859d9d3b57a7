#include "drillbif/model/hybrid_model.h"

namespace drillbif {

StatusOr<int> HybridModel::ParamIndex(std::string_view name) const {
  const auto& names = param_names();
  std::string valid;
  for (int i = 0; i < static_cast<int>(names.size()); ++i) {
    if (names[i] == name) return i;
    valid += (i ? ", " : "") + names[i];
  }
  return Status(StatusCode::kNotFound, "unknown parameter '" + std::string(name) + "' of model " +
                                           std::string(this->name()) + " (valid: " + valid + ")");
}

StateMatrix HybridModel::Saltation(int mode, int guard, int next_mode, const StateVector& x,
                                   const Params& params) const {
  StateVector f_minus, f_plus;
  VectorField(mode, x, params, &f_minus);
  const Transition tr = Jump(mode, guard, x, params);
  VectorField(next_mode, tr.x, params, &f_plus);
  const StateRow grad = GuardGradient(mode, guard, x, params);
  const StateVector jump_f = tr.jacobian * f_minus;
  StateMatrix salt = tr.jacobian;
  salt.noalias() += ((f_plus - jump_f) / grad.dot(f_minus)) * grad;
  return salt;
}

void ClosedFormFlow::FlowAndParamDerivatives(int mode, const StateVector& x0, double t,
                                             const Params& params, StateVector* x, StateMatrix* jac,
                                             std::span<const int> ks, std::span<StateVector> dx,
                                             std::span<bool> ok) const {
  Flow(mode, x0, t, params, x, jac);
  for (size_t i = 0; i < ks.size(); ++i) {
    ok[i] = FlowParamDerivative(mode, x0, t, params, ks[i], &dx[i]);
  }
}

}  // namespace drillbif
