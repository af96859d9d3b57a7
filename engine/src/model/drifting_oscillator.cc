// DriftingOscillator: description, validation, vector fields, Jacobians, guards, jumps, measures
// and the augmented linear form. The closed-form flows are in drifting_oscillator_flow.cc.
#include "drillbif/model/drifting_oscillator.h"

#include <algorithm>
#include <cmath>

#include "common/format.h"
#include "model/drifting_oscillator_internal.h"

namespace drillbif {
namespace {

std::string Num(double v) { return internal::FormatNumber(v); }

// The vector field of `mode` at x into dx[0..3], with force = a cos(s + phi0) + b given (the
// saltation evaluates two modes' fields at one phase).
void Field(int mode, const StateVector& x, double force, const Params& params, double* dx) {
  using DO = DriftingOscillator;
  const double xi = params[DO::kXi];
  switch (mode) {
    case DO::kNoContact:
      dx[DO::kP] = x[DO::kY];
      dx[DO::kY] = force;
      dx[DO::kQ] = -x[DO::kQ] / (2.0 * xi);
      break;
    case DO::kContact:
      dx[DO::kP] = x[DO::kY];
      dx[DO::kY] = force - (2.0 * xi * x[DO::kY] + x[DO::kQ]);
      dx[DO::kQ] = x[DO::kY];
      break;
    default:  // kProgression
      dx[DO::kP] = (1.0 - x[DO::kQ]) / (2.0 * xi);
      dx[DO::kY] = force - 1.0;
      dx[DO::kQ] = (1.0 - x[DO::kQ]) / (2.0 * xi);
      break;
  }
  dx[DO::kS] = params[DO::kOmega];
}

}  // namespace

DriftingOscillator::DriftingOscillator()
    : state_names_{"p", "y", "q", "s"},
      param_names_{"a", "b", "omega", "xi", "g", "phi0"},
      measure_names_{"drift", "power"},
      guards_{
          {{"impact", "Pi"}}, {{"progression", "l1"}, {"separation", "l2"}}, {{"stick", "l1"}}} {}

std::vector<StateVector> DriftingOscillator::SpreadStates(const Params& params) {
  const double g = params[kG], pi = std::acos(-1.0);
  const double states[8][4] = {{0, 0, 0, 0},       {-50, 5, 0.5, 0},  {g, 0, 0, 0},
                               {-200, -10, 1, 0},  {0.5, 0, 0.5, pi}, {-5, 0, 0, pi},
                               {-20, 20, 0.2, pi}, {0.2, -5, 0.9, pi}};
  std::vector<StateVector> out;
  for (const auto& x : states) {
    StateVector v(4);
    v << x[kP], x[kY], x[kQ], x[kS];
    out.push_back(v);
  }
  return out;
}

Params DriftingOscillator::MakeParams(double a, double b, double omega, double xi, double g,
                                      double phi0) {
  Params p(6);
  p << a, b, omega, xi, g, phi0;
  return p;
}

double DriftingOscillator::ContactForce(const StateVector& x, const Params& params) {
  return 2.0 * params[kXi] * x[kY] + x[kQ];
}

const std::vector<std::string>& DriftingOscillator::state_names() const { return state_names_; }
const std::vector<std::string>& DriftingOscillator::param_names() const { return param_names_; }
const std::vector<std::string>& DriftingOscillator::measure_names() const { return measure_names_; }
const std::vector<GuardSpec>& DriftingOscillator::guards(int mode) const { return guards_[mode]; }

std::string_view DriftingOscillator::mode_name(int mode) const {
  switch (mode) {
    case kNoContact:
      return "NC";
    case kContact:
      return "CwoP";
    case kProgression:
      return "CwP";
  }
  return "?";
}

Status DriftingOscillator::ValidateParams(const Params& params) const {
  if (params.size() != 6) {
    return InvalidArgument(
        "drifting_oscillator takes 6 parameters (a, b, omega, xi, g, phi0), got " +
        std::to_string(params.size()));
  }
  for (int i = 0; i < 6; ++i) {
    if (!std::isfinite(params[i])) {
      return InvalidArgument("parameter " + param_names_[i] + " must be finite (got " +
                             Num(params[i]) + ")");
    }
  }
  auto need = [&](int i, bool ok, const char* rule) -> Status {
    if (ok) return Status::Ok();
    return InvalidArgument("parameter " + param_names_[i] + " must be " + rule + " (got " +
                           Num(params[i]) + ")");
  };
  for (const Status& s : {need(kA, params[kA] >= 0.0, ">= 0 (forcing amplitude)"),
                          need(kB, params[kB] >= 0.0, ">= 0 (static force)"),
                          need(kOmega, params[kOmega] > 0.0, "> 0 (forcing frequency)"),
                          need(kXi, params[kXi] > 0.0, "> 0 (damping ratio of the slider)"),
                          need(kG, params[kG] > 0.0, "> 0 (gap)")}) {
    if (!s.ok()) return s;
  }
  return Status::Ok();
}

Status DriftingOscillator::ValidateState(const StateVector& x, const Params& params,
                                         double tol) const {
  if (x.size() != 4) {
    return InvalidArgument("state must have 4 components (p, y, q, s), got " +
                           std::to_string(x.size()));
  }
  for (int i = 0; i < 4; ++i) {
    if (!std::isfinite(x[i])) {
      return InvalidArgument("state component " + state_names_[i] + " must be finite (got " +
                             Num(x[i]) + ")");
    }
  }
  if (x[kQ] < -tol || x[kQ] > 1.0 + tol) {
    return InvalidArgument("state component q = " + Num(x[kQ]) +
                           " is outside the invariant set 0 <= q <= 1");
  }
  if (x[kP] > x[kQ] + params[kG] + tol) {
    return InvalidArgument("state component p = " + Num(x[kP]) +
                           " is outside the invariant set p <= q + g = " + Num(x[kQ] + params[kG]));
  }
  return Status::Ok();
}

int DriftingOscillator::ModeAt(const StateVector& x, const Params& params) const {
  // Contact within rounding of the gap: closer than 1e-14 relative to the positions involved.
  const double h = x[kQ] + params[kG] - x[kP];
  const double scale = 1.0 + std::abs(x[kP]);
  if (h > 1e-14 * scale) return kNoContact;
  const double f = ContactForce(x, params);
  if (f > 1.0) return kProgression;
  if (f == 1.0) {
    // On l1 the force's rate is the same in both contact modes; progression continues if rising.
    const double df =
        2.0 * params[kXi] * (params[kA] * std::cos(x[kS] + params[kPhi0]) + params[kB] - 1.0) +
        (1.0 - x[kQ]) / (2.0 * params[kXi]);
    return df >= 0.0 ? kProgression : kContact;
  }
  if (f > 0.0) return kContact;
  return kNoContact;
}

void DriftingOscillator::VectorField(int mode, const StateVector& x, const Params& params,
                                     StateVector* dx) const {
  dx->resize(4);
  Field(mode, x, params[kA] * std::cos(x[kS] + params[kPhi0]) + params[kB], params, dx->data());
}

void DriftingOscillator::StateJacobian(int mode, const StateVector& x, const Params& params,
                                       StateMatrix* jac) const {
  const double xi = params[kXi];
  jac->setZero(4, 4);
  (*jac)(kY, kS) = -params[kA] * std::sin(x[kS] + params[kPhi0]);
  switch (mode) {
    case kNoContact:
      (*jac)(kP, kY) = 1.0;
      (*jac)(kQ, kQ) = -1.0 / (2.0 * xi);
      break;
    case kContact:
      (*jac)(kP, kY) = 1.0;
      (*jac)(kY, kY) = -2.0 * xi;
      (*jac)(kY, kQ) = -1.0;
      (*jac)(kQ, kY) = 1.0;
      break;
    default:
      (*jac)(kP, kQ) = -1.0 / (2.0 * xi);
      (*jac)(kQ, kQ) = -1.0 / (2.0 * xi);
      break;
  }
}

void DriftingOscillator::ParamJacobian(int mode, const StateVector& x, const Params& params,
                                       ParamMatrix* jac) const {
  const double xi = params[kXi];
  const double theta = x[kS] + params[kPhi0];
  jac->setZero(4, 6);
  (*jac)(kY, kA) = std::cos(theta);
  (*jac)(kY, kB) = 1.0;
  (*jac)(kY, kPhi0) = -params[kA] * std::sin(theta);
  (*jac)(kS, kOmega) = 1.0;
  switch (mode) {
    case kNoContact:
      (*jac)(kQ, kXi) = x[kQ] / (2.0 * xi * xi);
      break;
    case kContact:
      (*jac)(kY, kXi) = -2.0 * x[kY];
      break;
    default:
      (*jac)(kP, kXi) = (x[kQ] - 1.0) / (2.0 * xi * xi);
      (*jac)(kQ, kXi) = (x[kQ] - 1.0) / (2.0 * xi * xi);
      break;
  }
}

GuardValue DriftingOscillator::Guard(int mode, int guard, const StateVector& x,
                                     const Params& params) const {
  const double theta = x[kS] + params[kPhi0];
  GuardValue g[2];
  internal::OscillatorGuards(mode, x, std::cos(theta), std::sin(theta), params, g);
  return g[guard];
}

StateRow DriftingOscillator::GuardGradient(int mode, int guard, const StateVector& /*x*/,
                                           const Params& params) const {
  StateRow g = StateRow::Zero(4);
  const double xi = params[kXi];
  if (mode == kNoContact) {
    g[kP] = -1.0, g[kQ] = 1.0;
  } else {
    const double sign = (mode == kContact && guard == kProgressionStart) ? -1.0 : 1.0;
    g[kY] = sign * 2.0 * xi, g[kQ] = sign;
  }
  return g;
}

ParamVector DriftingOscillator::GuardParamGradient(int mode, int guard, const StateVector& x,
                                                   const Params& /*params*/) const {
  ParamVector g = ParamVector::Zero(6);
  if (mode == kNoContact) {
    g[kG] = 1.0;
  } else {
    const double sign = (mode == kContact && guard == kProgressionStart) ? -1.0 : 1.0;
    g[kXi] = sign * 2.0 * x[kY];
  }
  return g;
}

double DriftingOscillator::GuardCurvatureBound(int mode, int /*guard*/, const StateVector& x,
                                               const Params& params) const {
  switch (mode) {
    case kNoContact:
      return internal::NoContactBound(x[kQ], params);
    case kContact: {
      const internal::ContactGain k = internal::MakeContactGain(params);
      const double theta = x[kS] + params[kPhi0];
      double qp, yp;
      internal::ContactSteadyState(k, std::cos(theta), std::sin(theta), params, &qp, &yp);
      return internal::ContactBound(k, x[kQ] - qp, x[kY] - yp);
    }
    default:
      return internal::ProgressionBound(x[kQ], params);
  }
}

Transition DriftingOscillator::Jump(int mode, int guard, const StateVector& x,
                                    const Params& params) const {
  Transition t;
  t.x = x;
  t.jacobian = StateMatrix::Identity(4, 4);
  t.param_jacobian = ParamMatrix::Zero(4, 6);
  switch (mode) {
    case kNoContact: {
      // The event fires on Pi: place the state on it exactly (p = q + g), so that the rounding of a
      // long free flight (|p| up to 1e3 or more) does not leave the contact phase off its manifold;
      // d p_after / d q = 1 replaces d p_after / d p = 1 there.
      t.x[kP] = x[kQ] + params[kG];
      t.jacobian(kP, kP) = 0.0;
      t.jacobian(kP, kQ) = 1.0;
      t.param_jacobian(kP, kG) = 1.0;
      const double f = ContactForce(t.x, params);
      if (f >= 1.0) {
        t.next_mode = kProgression;
      } else if (f > kForceTolerance) {
        t.next_mode = kContact;
      } else {
        // A grazing impact (F ~ 0): contact only if the force is about to rise.
        const double df =
            2.0 * params[kXi] * (params[kA] * std::cos(x[kS] + params[kPhi0]) + params[kB] - f) +
            x[kY];
        t.next_mode = df > 0.0 ? kContact : kNoContact;
      }
      break;
    }
    case kContact:
      t.next_mode = guard == kProgressionStart ? kProgression : kNoContact;
      break;
    default:
      t.next_mode = kContact;
      break;
  }
  return t;
}

StateMatrix DriftingOscillator::Saltation(int mode, int guard, int next_mode, const StateVector& x,
                                          const Params& params) const {
  // HybridModel::Saltation's arithmetic on the same values, with one cosine for both fields and
  // without the jump's parameter Jacobian. The jump is the identity except at an impact, which
  // sets p = q + g: DR's p row is e_q there, so DR f- is f- with its p entry replaced by f-_q
  // (products of DR's 0 and 1 entries are exact, so is their sum). Every entry of S is formed as
  // the default forms it, DR_ij + grad_j v_i, zero gradient entries included, so that S matches
  // bit for bit even where grad h . f- vanishes.
  const double force = params[kA] * std::cos(x[kS] + params[kPhi0]) + params[kB];
  double f_minus[4], f_plus[4], jump_f[4], grad[4] = {0.0, 0.0, 0.0, 0.0};
  Field(mode, x, force, params, f_minus);
  std::copy(f_minus, f_minus + 4, jump_f);
  double dr[4][4] = {{1, 0, 0, 0}, {0, 1, 0, 0}, {0, 0, 1, 0}, {0, 0, 0, 1}};  // DR(i, j)
  if (mode == kNoContact) {
    StateVector after = x;
    after[kP] = x[kQ] + params[kG];
    Field(next_mode, after, force, params, f_plus);
    jump_f[kP] = f_minus[kQ];
    dr[kP][kP] = 0.0, dr[kP][kQ] = 1.0;
    grad[kP] = -1.0, grad[kQ] = 1.0;
  } else {
    Field(next_mode, x, force, params, f_plus);
    const double sign = (mode == kContact && guard == kProgressionStart) ? -1.0 : 1.0;
    grad[kY] = sign * 2.0 * params[kXi], grad[kQ] = sign;
  }
  // grad . f- with the zero entries' products dropped (exact: they add +-0 to a finite sum).
  const double denom = mode == kNoContact ? grad[kP] * f_minus[kP] + grad[kQ] * f_minus[kQ]
                                          : grad[kY] * f_minus[kY] + grad[kQ] * f_minus[kQ];
  StateMatrix salt(4, 4);
  for (int i = 0; i < 4; ++i) {
    const double v = (f_plus[i] - jump_f[i]) / denom;
    for (int j = 0; j < 4; ++j) salt(i, j) = dr[i][j] + grad[j] * v;
  }
  return salt;
}

bool DriftingOscillator::ModeConstraint(int mode, const StateVector& x, const Params& params,
                                        double* c, StateRow* grad, ParamVector* param_grad) const {
  if (mode == kNoContact) return false;
  *c = x[kP] - x[kQ] - params[kG];
  *grad = StateRow::Zero(4);
  (*grad)[kP] = 1.0, (*grad)[kQ] = -1.0;
  *param_grad = ParamVector::Zero(6);
  (*param_grad)[kG] = -1.0;
  return true;
}

int DriftingOscillator::ModeAcross(int mode, int guard) const {
  switch (mode) {
    case kNoContact:
      return kContact;  // an impact that is not tangential starts contact
    case kContact:
      return guard == kProgressionStart ? kProgression : kNoContact;
    default:
      return kContact;
  }
}

MeasureVector DriftingOscillator::MeasureRates(int mode, const StateVector& x,
                                               const Params& params) const {
  const double xi = params[kXi];
  MeasureVector r = MeasureVector::Zero(2);
  switch (mode) {
    case kNoContact:
      r[kPower] = x[kQ] * x[kQ] / (2.0 * xi);
      break;
    case kContact:
      r[kPower] = 2.0 * xi * x[kY] * x[kY];
      break;
    default:
      r[kDrift] = (ContactForce(x, params) - 1.0) / (2.0 * xi);
      r[kPower] = (x[kQ] - 1.0) * (x[kQ] - 1.0) / (2.0 * xi);
      break;
  }
  return r;
}

double DriftingOscillator::TimeScale(int mode, const Params& params) const {
  const double xi = params[kXi], w = params[kOmega];
  switch (mode) {
    case kNoContact:
      return 1.0 / std::max(w, 1.0);
    case kContact: {
      // Largest |eigenvalue| of [[0, 1], [-1, -2 xi]]: 1 if xi <= 1, xi + sqrt(xi^2 - 1) otherwise.
      const double lam = xi <= 1.0 ? 1.0 : xi + std::sqrt(xi * xi - 1.0);
      return 1.0 / std::max(w, lam);
    }
    default:
      return 1.0 / std::max({w, 1.0, 1.0 / (2.0 * xi)});
  }
}

// ---- LinearForm: z = (p, y, q, cos(s + phi0), sin(s + phi0), 1) ----

void DriftingOscillator::ToAugmented(const StateVector& x, const Params& params,
                                     Eigen::VectorXd* z) const {
  const double theta = x[kS] + params[kPhi0];
  z->resize(6);
  *z << x[kP], x[kY], x[kQ], std::cos(theta), std::sin(theta), 1.0;
}

void DriftingOscillator::AugmentedMatrix(int mode, const Params& params, Eigen::MatrixXd* a) const {
  const double xi = params[kXi];
  a->setZero(6, 6);
  (*a)(1, 3) = params[kA];
  (*a)(1, 5) = params[kB];
  (*a)(3, 4) = -params[kOmega];
  (*a)(4, 3) = params[kOmega];
  switch (mode) {
    case kNoContact:
      (*a)(0, 1) = 1.0;
      (*a)(2, 2) = -1.0 / (2.0 * xi);
      break;
    case kContact:
      (*a)(0, 1) = 1.0;
      (*a)(1, 1) = -2.0 * xi;
      (*a)(1, 2) = -1.0;
      (*a)(2, 1) = 1.0;
      break;
    default:
      (*a)(0, 2) = (*a)(2, 2) = -1.0 / (2.0 * xi);
      (*a)(0, 5) = (*a)(2, 5) = 1.0 / (2.0 * xi);
      (*a)(1, 5) = params[kB] - 1.0;
      break;
  }
}

void DriftingOscillator::AugmentedMatrixDerivative(int mode, const Params& params, int k,
                                                   Eigen::MatrixXd* da) const {
  const double xi = params[kXi];
  da->setZero(6, 6);
  switch (k) {
    case kA:
      (*da)(1, 3) = 1.0;
      break;
    case kB:
      (*da)(1, 5) = 1.0;
      break;
    case kOmega:
      (*da)(3, 4) = -1.0, (*da)(4, 3) = 1.0;
      break;
    case kXi:
      if (mode == kNoContact) {
        (*da)(2, 2) = 1.0 / (2.0 * xi * xi);
      } else if (mode == kContact) {
        (*da)(1, 1) = -2.0;
      } else {
        (*da)(0, 2) = (*da)(2, 2) = 1.0 / (2.0 * xi * xi);
        (*da)(0, 5) = (*da)(2, 5) = -1.0 / (2.0 * xi * xi);
      }
      break;
    default:
      break;  // g and phi0 do not enter A
  }
}

void DriftingOscillator::AugmentedInitialDerivative(const StateVector& x, const Params& params,
                                                    int k, Eigen::VectorXd* dz) const {
  dz->setZero(6);
  if (k == kPhi0) {
    const double theta = x[kS] + params[kPhi0];
    (*dz)[3] = -std::sin(theta);
    (*dz)[4] = std::cos(theta);
  }
}

}  // namespace drillbif
