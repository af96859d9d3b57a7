#include "problems/forced_linear_oscillator.h"

#include <algorithm>
#include <cmath>
#include <string>

namespace drillbif::testing {
namespace {

// Bisection of a function with a sign change on [a, b] down to adjacent doubles.
template <typename F>
double Bisect(F f, double a, double b) {
  double fa = f(a);
  for (int i = 0; i < 200; ++i) {
    const double m = 0.5 * (a + b);
    if (m <= a || m >= b) break;
    const double fm = f(m);
    if ((fm > 0) == (fa > 0)) {
      a = m;
      fa = fm;
    } else {
      b = m;
    }
  }
  return 0.5 * (a + b);
}

// Homogeneous fundamental matrix of (x, v)' = [[0, 1], [-1, -2 zeta]] (x, v), 0 <= zeta < 1.
Eigen::Matrix2d Fundamental(double zeta, double t) {
  const double wd = std::sqrt(1.0 - zeta * zeta);
  const double e = std::exp(-zeta * t);
  const double c = std::cos(wd * t);
  const double s = std::sin(wd * t);
  Eigen::Matrix2d phi;
  phi << c + zeta / wd * s, s / wd, -s / wd, c - zeta / wd * s;
  return e * phi;
}

// Steady state (x_p, v_p) at phase s and its derivative with respect to s.
Eigen::Vector2d Steady(const Params& p, double s) {
  const double r = ForcedLinearOscillator::SteadyAmplitude(p);
  const double d = ForcedLinearOscillator::PhaseLag(p);
  const double w = p[ForcedLinearOscillator::kOmega];
  return Eigen::Vector2d(r * std::cos(s - d), -r * w * std::sin(s - d));
}
Eigen::Vector2d SteadyPrime(const Params& p, double s) {
  const double r = ForcedLinearOscillator::SteadyAmplitude(p);
  const double d = ForcedLinearOscillator::PhaseLag(p);
  const double w = p[ForcedLinearOscillator::kOmega];
  return Eigen::Vector2d(-r * std::sin(s - d), -r * w * std::cos(s - d));
}

}  // namespace

ForcedLinearOscillator::ForcedLinearOscillator()
    : state_names_{"x", "v", "s"},
      param_names_{"zeta", "amplitude", "omega", "wall", "restitution"},
      measure_names_{"displacement", "position_integral"},
      guards_{GuardSpec{"wall", "x=w"}} {}

Params ForcedLinearOscillator::MakeParams(double zeta, double amplitude, double omega, double wall,
                                          double restitution) {
  Params p(5);
  p << zeta, amplitude, omega, wall, restitution;
  return p;
}

StateVector ForcedLinearOscillator::MakeState(double x, double v, double s) {
  StateVector st(3);
  st << x, v, s;
  return st;
}

double ForcedLinearOscillator::SteadyAmplitude(const Params& p) {
  const double w = p[kOmega];
  const double a = 1.0 - w * w;
  const double b = 2.0 * p[kZeta] * w;
  return p[kAmplitude] / std::sqrt(a * a + b * b);
}

double ForcedLinearOscillator::PhaseLag(const Params& p) {
  const double w = p[kOmega];
  return std::atan2(2.0 * p[kZeta] * w, 1.0 - w * w);
}

StateVector ForcedLinearOscillator::ExactState(const StateVector& x0, double t, const Params& p) {
  const double s0 = x0[kS];
  const double s = s0 + p[kOmega] * t;
  // x(t) = P(s(t)) + Phi(t) (X0 - P(s0)).
  const Eigen::Vector2d xv =
      Steady(p, s) + Fundamental(p[kZeta], t) * (x0.head<2>() - Steady(p, s0));
  return MakeState(xv[0], xv[1], s);
}

double ForcedLinearOscillator::FirstUpCrossing(const StateVector& x0, double level, double t_end,
                                               const Params& params, double dt_grid) {
  auto g = [&](double t) { return ExactState(x0, t, params)[kX] - level; };
  auto v = [&](double t) { return ExactState(x0, t, params)[kV]; };
  double t0 = 0.0;
  double g0 = g(t0);
  while (t0 < t_end && g0 < 0.0) {
    const double t1 = std::min(t_end, t0 + dt_grid);
    const double g1 = g(t1);
    if (g1 >= 0.0) return Bisect(g, t0, t1);
    // A dip narrower than the grid: look at the maximum inside the cell.
    if (v(t0) > 0.0 && v(t1) <= 0.0) {
      const double tm = Bisect(v, t0, t1);
      if (g(tm) >= 0.0) return Bisect(g, t0, tm);
    }
    t0 = t1;
    g0 = g1;
  }
  return g0 >= 0.0 ? 0.0 : -1.0;
}

bool ForcedLinearOscillator::FirstMaximum(const StateVector& x0, double t_end, const Params& params,
                                          double* t_max, double* x_max, double dt_grid) {
  auto v = [&](double t) { return ExactState(x0, t, params)[kV]; };
  double t0 = 0.0;
  double v0 = v(t0);
  while (t0 < t_end) {
    const double t1 = std::min(t_end, t0 + dt_grid);
    const double v1 = v(t1);
    if (v0 > 0.0 && v1 <= 0.0) {
      *t_max = Bisect(v, t0, t1);
      *x_max = ExactState(x0, *t_max, params)[kX];
      return true;
    }
    t0 = t1;
    v0 = v1;
  }
  return false;
}

std::string_view ForcedLinearOscillator::mode_name(int mode) const {
  return mode == kFree ? "free" : "invalid";
}

Status ForcedLinearOscillator::ValidateParams(const Params& p) const {
  if (p.size() != 5) {
    return InvalidArgument("forced_linear_oscillator expects 5 parameters (got " +
                           std::to_string(p.size()) + ")");
  }
  for (int k = 0; k < 5; ++k) {
    if (!std::isfinite(p[k])) return InvalidArgument(param_names_[k] + " must be finite");
  }
  if (p[kZeta] < 0.0 || p[kZeta] >= 1.0) {
    return InvalidArgument("zeta must be in [0, 1) (got " + std::to_string(p[kZeta]) + ")");
  }
  if (p[kOmega] <= 0.0) {
    return InvalidArgument("omega must be > 0 (got " + std::to_string(p[kOmega]) + ")");
  }
  if (p[kRestitution] < 0.0 || p[kRestitution] > 1.0) {
    return InvalidArgument("restitution must be in [0, 1] (got " + std::to_string(p[kRestitution]) +
                           ")");
  }
  const double a = 1.0 - p[kOmega] * p[kOmega];
  const double b = 2.0 * p[kZeta] * p[kOmega];
  if (a * a + b * b < 1e-12) {
    return InvalidArgument("omega = 1 with zeta = 0 is the undamped resonance (no steady state)");
  }
  return Status::Ok();
}

Status ForcedLinearOscillator::ValidateState(const StateVector& x, const Params& p,
                                             double tol) const {
  if (x.size() != 3) {
    return InvalidArgument("forced_linear_oscillator state has 3 components (got " +
                           std::to_string(x.size()) + ")");
  }
  for (int i = 0; i < 3; ++i) {
    if (!std::isfinite(x[i])) return InvalidArgument(state_names_[i] + " must be finite");
  }
  if (x[kX] > p[kWall] + tol) {
    return InvalidArgument("x must be <= wall (x = " + std::to_string(x[kX]) +
                           ", wall = " + std::to_string(p[kWall]) + ")");
  }
  return Status::Ok();
}

void ForcedLinearOscillator::VectorField(int /*mode*/, const StateVector& x, const Params& p,
                                         StateVector* dx) const {
  dx->resize(3);
  (*dx)[kX] = x[kV];
  (*dx)[kV] = p[kAmplitude] * std::cos(x[kS]) - 2.0 * p[kZeta] * x[kV] - x[kX];
  (*dx)[kS] = p[kOmega];
}

void ForcedLinearOscillator::StateJacobian(int /*mode*/, const StateVector& x, const Params& p,
                                           StateMatrix* jac) const {
  jac->setZero(3, 3);
  (*jac)(kX, kV) = 1.0;
  (*jac)(kV, kX) = -1.0;
  (*jac)(kV, kV) = -2.0 * p[kZeta];
  (*jac)(kV, kS) = -p[kAmplitude] * std::sin(x[kS]);
}

void ForcedLinearOscillator::ParamJacobian(int /*mode*/, const StateVector& x, const Params& /*p*/,
                                           ParamMatrix* jac) const {
  jac->setZero(3, 5);
  (*jac)(kV, kZeta) = -2.0 * x[kV];
  (*jac)(kV, kAmplitude) = std::cos(x[kS]);
  (*jac)(kS, kOmega) = 1.0;
}

GuardValue ForcedLinearOscillator::Guard(int /*mode*/, int /*guard*/, const StateVector& x,
                                         const Params& p) const {
  // h = w - x, h' = -v, h'' = -v' = x + 2 zeta v - A cos s.
  GuardValue g;
  g.h = p[kWall] - x[kX];
  g.dh = -x[kV];
  g.ddh = x[kX] + 2.0 * p[kZeta] * x[kV] - p[kAmplitude] * std::cos(x[kS]);
  return g;
}

StateRow ForcedLinearOscillator::GuardGradient(int /*mode*/, int /*guard*/,
                                               const StateVector& /*x*/,
                                               const Params& /*p*/) const {
  StateRow r = StateRow::Zero(3);
  r[kX] = -1.0;
  return r;
}

ParamVector ForcedLinearOscillator::GuardParamGradient(int /*mode*/, int /*guard*/,
                                                       const StateVector& /*x*/,
                                                       const Params& /*p*/) const {
  ParamVector g = ParamVector::Zero(5);
  g[kWall] = 1.0;
  return g;
}

double ForcedLinearOscillator::GuardCurvatureBound(int /*mode*/, int /*guard*/,
                                                   const StateVector& x, const Params& p) const {
  // |h''| = |x + 2 zeta v - A cos s| <= |x| + 2 zeta |v| + |A|. The transient (x_h, v_h) has
  // non-increasing energy x_h^2 + v_h^2 (its derivative is -4 zeta v_h^2), so with
  // e = |(x_h, v_h)(0)|: |x| <= R + e and |v| <= omega R + e for all t >= 0.
  const double r = SteadyAmplitude(p);
  const double e = (x.head<2>() - Steady(p, x[kS])).norm();
  return (r + e) + 2.0 * p[kZeta] * (p[kOmega] * r + e) + std::abs(p[kAmplitude]) + 1e-300;
}

Transition ForcedLinearOscillator::Jump(int /*mode*/, int /*guard*/, const StateVector& x,
                                        const Params& p) const {
  Transition tr;
  tr.next_mode = kFree;
  tr.x = x;
  tr.x[kV] = -p[kRestitution] * x[kV];
  tr.jacobian = StateMatrix::Identity(3, 3);
  tr.jacobian(kV, kV) = -p[kRestitution];
  tr.param_jacobian = ParamMatrix::Zero(3, p.size());
  tr.param_jacobian(kV, kRestitution) = -x[kV];
  return tr;
}

MeasureVector ForcedLinearOscillator::MeasureRates(int /*mode*/, const StateVector& x,
                                                   const Params& /*p*/) const {
  MeasureVector m(2);
  m[kDisplacement] = x[kV];
  m[kPositionIntegral] = x[kX];
  return m;
}

double ForcedLinearOscillator::TimeScale(int /*mode*/, const Params& p) const {
  // Natural frequency 1, forcing frequency omega.
  return 1.0 / std::max(1.0, p[kOmega]);
}

void ForcedLinearOscillator::ToAugmented(const StateVector& x, const Params& /*p*/,
                                         Eigen::VectorXd* z) const {
  z->resize(5);
  *z << x[kX], x[kV], std::cos(x[kS]), std::sin(x[kS]), 1.0;
}

void ForcedLinearOscillator::AugmentedMatrix(int /*mode*/, const Params& p,
                                             Eigen::MatrixXd* a) const {
  // x' = v, v' = -x - 2 zeta v + A c, c' = -omega sn, sn' = omega c, 1' = 0.
  a->setZero(5, 5);
  (*a)(0, 1) = 1.0;
  (*a)(1, 0) = -1.0;
  (*a)(1, 1) = -2.0 * p[kZeta];
  (*a)(1, 2) = p[kAmplitude];
  (*a)(2, 3) = -p[kOmega];
  (*a)(3, 2) = p[kOmega];
}

void ForcedLinearOscillator::AugmentedMatrixDerivative(int /*mode*/, const Params& /*p*/, int k,
                                                       Eigen::MatrixXd* da) const {
  da->setZero(5, 5);
  switch (k) {
    case kZeta:
      (*da)(1, 1) = -2.0;
      break;
    case kAmplitude:
      (*da)(1, 2) = 1.0;
      break;
    case kOmega:
      (*da)(2, 3) = -1.0;
      (*da)(3, 2) = 1.0;
      break;
    default:
      break;
  }
}

void ForcedLinearOscillator::AugmentedInitialDerivative(const StateVector& /*x*/,
                                                        const Params& /*p*/, int /*k*/,
                                                        Eigen::VectorXd* dz) const {
  dz->setZero(5);  // no phase-offset parameter
}

void ForcedLinearOscillator::Flow(int /*mode*/, const StateVector& x0, double t, const Params& p,
                                  StateVector* x, StateMatrix* jac) const {
  *x = ExactState(x0, t, p);
  if (jac == nullptr) return;
  // x(t) = P(s0 + omega t) + Phi(t) (X0 - P(s0)): d/dX0 = Phi, d/ds0 = P'(s(t)) - Phi P'(s0).
  const Eigen::Matrix2d phi = Fundamental(p[kZeta], t);
  jac->setZero(3, 3);
  jac->topLeftCorner<2, 2>() = phi;
  jac->block<2, 1>(0, kS) = SteadyPrime(p, x0[kS] + p[kOmega] * t) - phi * SteadyPrime(p, x0[kS]);
  (*jac)(kS, kS) = 1.0;
}

void ForcedLinearOscillator::PrepareSegment(int mode, const StateVector& x0,
                                            const Params& /*params*/,
                                            PreparedSegment* segment) const {
  segment->mode = mode;
  segment->x0 = x0;
}

void ForcedLinearOscillator::EvaluateSegment(const PreparedSegment& segment, double t,
                                             const Params& params, bool with_guards,
                                             SegmentPoint* point) const {
  point->x = ExactState(segment.x0, t, params);
  if (!with_guards) return;
  point->guards[kWallGuard] = Guard(segment.mode, kWallGuard, point->x, params);
  point->bounds[kWallGuard] = GuardCurvatureBound(segment.mode, kWallGuard, point->x, params);
}

MeasureVector ForcedLinearOscillator::MeasureIncrements(int /*mode*/, const StateVector& x0,
                                                        double t, const Params& p,
                                                        unsigned /*which*/) const {
  const StateVector x = ExactState(x0, t, p);
  MeasureVector m(2);
  m[kDisplacement] = x[kX] - x0[kX];
  m[kPositionIntegral] = p[kAmplitude] / p[kOmega] * (std::sin(x[kS]) - std::sin(x0[kS])) -
                         2.0 * p[kZeta] * (x[kX] - x0[kX]) - (x[kV] - x0[kV]);
  return m;
}

}  // namespace drillbif::testing
