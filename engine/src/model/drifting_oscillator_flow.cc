// Closed-form flows of the drifting oscillator's three linear modes, with d x(t) / d x0, prepared
// segments for fast repeated evaluation, and the measures' increments.
// Notation: theta0 = s0 + phi0, x = omega t, theta = theta0 + x.
//
// Forcing integrals (all free of 1/omega, hence exact and robust as omega t -> 0):
//   I1 = int_0^t cos(theta0 + w tau) dtau       = t [cos th0 sinc(x) - sin th0 x C2(x)]
//   I2 = int_0^t I1                             = t^2 [cos th0 C2(x) - sin th0 x S3(x)]
//   J1 = int_0^t sin(theta0 + w tau) dtau       = t [sin th0 sinc(x) + cos th0 x C2(x)]
//   J2 = int_0^t J1                             = t^2 [sin th0 C2(x) + cos th0 x S3(x)]
// with C2 = (1 - cos x)/x^2, S3 = (x - sin x)/x^3; dI1/dtheta0 = -J1, dI2/dtheta0 = -J2.
// One sincos of x/2 gives sin x = 2 sin(x/2) cos(x/2), cos x = 1 - 2 sin^2(x/2), C2 without
// cancellation, and cos, sin of theta by rotating those of theta0.
//
// Contact (CwoP): u = (q, y) = u_p(theta) + expm(A t) (u0 - u_p(theta0)), u_p the harmonic steady
// state (drifting_oscillator_internal.h). expm(A t) = e^{-xi t}[C I + S (A + xi I)] with
// (A + xi I)^2 = (xi^2 - 1) I, C = cos(mu t), S = sin(mu t)/mu, mu^2 = 1 - xi^2; analytic in mu^2,
// so one series covers xi = 1 (repeated root) and its neighbourhood, cosh/sinh cover xi > 1.
#include <cmath>

#include "common/gauss_legendre.h"
#include "common/small_arg.h"
#include "drillbif/model/drifting_oscillator.h"
#include "model/drifting_oscillator_internal.h"

namespace drillbif {
namespace {

using internal::XMinusSinOverCube;

// expm(A t) for A = [[0, 1], [-1, -2 xi]] as e^{-xi t} C and e^{-xi t} S.
struct DampedExp {
  double ec, es;
};

DampedExp DampedOscillatorExp(double xi, double t) {
  const double d = 1.0 - xi * xi;  // mu^2
  const double z = d * t * t;
  if (std::abs(z) <= 1.0) {
    // C = sum (-z)^k / (2k)!, S = t sum (-z)^k / (2k+1)!; 13 terms reach 1/26! < 1e-26 at |z| = 1.
    double c = 0.0, s = 0.0, term_c = 1.0, term_s = 1.0;
    for (int k = 0; k < 13; ++k) {
      c += term_c;
      s += term_s;
      term_c *= -z / ((2.0 * k + 1.0) * (2.0 * k + 2.0));
      term_s *= -z / ((2.0 * k + 2.0) * (2.0 * k + 3.0));
    }
    const double e = std::exp(-xi * t);
    return {e * c, e * s * t};
  }
  if (d > 0.0) {
    const double mu = std::sqrt(d);
    const double e = std::exp(-xi * t);
    return {e * std::cos(mu * t), e * std::sin(mu * t) / mu};
  }
  // xi > 1: e^{-xi t} cosh(nu t) = (e^{(nu - xi) t} + e^{-(nu + xi) t}) / 2 with
  // nu - xi = -1/(nu + xi) (no cancellation, no overflow for large t).
  const double nu = std::sqrt(-d);
  const double slow = std::exp(-t / (nu + xi)), fast = std::exp(-(nu + xi) * t);
  return {0.5 * (slow + fast), 0.5 * (slow - fast) / nu};
}

// Layout of PreparedSegment::c.
enum : int {
  kCos0 = 0,  // cos theta0
  kSin0,      // sin theta0
  kDq0,       // contact: q0 - q_p(theta0)
  kDy0,       // contact: y0 - y_p(theta0)
  kGainKr,    // contact: ContactGain
  kGainKi,
  kGainSteady,
  kGainTransient,
};

internal::ContactGain GainOf(const PreparedSegment& seg) {
  return {seg.c[kGainKr], seg.c[kGainKi], seg.c[kGainSteady], seg.c[kGainTransient]};
}

// The state at time t of a prepared segment plus the intermediate quantities that the guards and
// the Jacobian reuse.
struct Core {
  StateVector x;
  double ct, st;              // cos, sin of theta(t)
  double sinc, c2, s3, xw;    // NC, CwP: functions of x = w t
  double decay;               // NC: e^{-t/(2 xi)}; CwP: expm1(-t/(2 xi))
  double e00, e01, e10, e11;  // CwoP: expm(A t)
  double dq, dy;              // CwoP: transient u - u_p at t
};

void EvaluateCore(const PreparedSegment& seg, double t, const Params& prm, Core* k) {
  using DO = DriftingOscillator;
  const double a = prm[DO::kA], b = prm[DO::kB], w = prm[DO::kOmega], xi = prm[DO::kXi];
  const StateVector& x0 = seg.x0;
  const double c0 = seg.c[kCos0], s0 = seg.c[kSin0];
  const double xw = w * t;
  k->xw = xw;
  k->x.resize(4);
  k->x[DO::kS] = x0[DO::kS] + xw;
  if (seg.mode == DO::kContact) {
    const double sx = std::sin(xw), cx = std::cos(xw);
    k->ct = c0 * cx - s0 * sx;
    k->st = s0 * cx + c0 * sx;
    const DampedExp ex = DampedOscillatorExp(xi, t);
    // expm(A t) = ec I + es (A + xi I), A + xi I = [[xi, 1], [-1, -xi]].
    k->e00 = ex.ec + ex.es * xi, k->e01 = ex.es, k->e10 = -ex.es, k->e11 = ex.ec - ex.es * xi;
    k->dq = k->e00 * seg.c[kDq0] + k->e01 * seg.c[kDy0];
    k->dy = k->e10 * seg.c[kDq0] + k->e11 * seg.c[kDy0];
    double qp, yp;
    internal::ContactSteadyState(GainOf(seg), k->ct, k->st, prm, &qp, &yp);
    k->x[DO::kQ] = qp + k->dq;
    k->x[DO::kY] = yp + k->dy;
    k->x[DO::kP] = k->x[DO::kQ] + (x0[DO::kP] - x0[DO::kQ]);  // p - q is constant in contact
    return;
  }
  const double sh = std::sin(0.5 * xw), ch = std::cos(0.5 * xw);
  const double sx = 2.0 * sh * ch, cx = 1.0 - 2.0 * sh * sh;
  k->ct = c0 * cx - s0 * sx;
  k->st = s0 * cx + c0 * sx;
  k->sinc = xw == 0.0 ? 1.0 : sx / xw;
  k->c2 = xw == 0.0 ? 0.5 : 2.0 * (sh / xw) * (sh / xw);
  k->s3 = XMinusSinOverCube(xw);
  const double i1 = t * (c0 * k->sinc - s0 * xw * k->c2);
  const double i2 = t * t * (c0 * k->c2 - s0 * xw * k->s3);
  if (seg.mode == DO::kNoContact) {
    k->decay = std::exp(-t / (2.0 * xi));
    k->x[DO::kP] = x0[DO::kP] + x0[DO::kY] * t + 0.5 * b * t * t + a * i2;
    k->x[DO::kY] = x0[DO::kY] + b * t + a * i1;
    k->x[DO::kQ] = x0[DO::kQ] * k->decay;
  } else {
    k->decay = std::expm1(-t / (2.0 * xi));
    k->x[DO::kQ] = x0[DO::kQ] + (x0[DO::kQ] - 1.0) * k->decay;
    k->x[DO::kP] = k->x[DO::kQ] + (x0[DO::kP] - x0[DO::kQ]);
    k->x[DO::kY] = x0[DO::kY] + (b - 1.0) * t + a * i1;
  }
}

// d x(t) / d omega at fixed x0 (theta0 fixed, theta = theta0 + omega t moves): s moves by t.
// NC and CwP through the forcing integrals (header comment), with x = omega t:
//   dI1/domega = -int_0^t tau sin(theta0 + w tau) = t^2 [-cos th0 x (C2 - S3) - sin th0 (sinc -
//   C2)] dI2/domega = int_0^t dI1/domega              = t^3 [-cos th0 Q(x) - sin th0 (C2 - 2 S3)]
// with Q = -C2' (common/small_arg.h); every bracket is free of cancellation as x -> 0.
// CwoP through the steady state: u = u_p(theta) + E (u0 - u_p(theta0)) with E independent of
// omega, so du/domega = u_p,w(theta) + t du_p/dtheta - E u_p,w(theta0), where u_p,w is the
// derivative at fixed theta: dK/domega = K^2 (2 w - 2 i xi) for K = 1/(1 - w^2 + 2 i xi w), and
// y_p = a w Re(i K e^{i theta}) also has the factor w.
void OmegaDerivative(const PreparedSegment& seg, const Core& core, double t, const Params& prm,
                     StateVector* dx) {
  using DO = DriftingOscillator;
  const double a = prm[DO::kA], b = prm[DO::kB], w = prm[DO::kOmega], xi = prm[DO::kXi];
  const double c0 = seg.c[kCos0], s0 = seg.c[kSin0];
  (*dx)[DO::kS] = t;
  if (seg.mode == DO::kContact) {
    const internal::ContactGain g = GainOf(seg);
    const double k2r = g.kr * g.kr - g.ki * g.ki, k2i = 2.0 * g.kr * g.ki;
    const double dkr = 2.0 * w * k2r + 2.0 * xi * k2i, dki = 2.0 * w * k2i - 2.0 * xi * k2r;
    // u_p,w at phase (ct, st).
    auto steady_w = [&](double ct, double st, double* dq, double* dy) {
      *dq = a * (dkr * ct - dki * st);
      *dy = a * (-g.kr * st - g.ki * ct) + a * w * (-dkr * st - dki * ct);
    };
    double dq0, dy0, dq1, dy1, qp1, yp1;
    steady_w(c0, s0, &dq0, &dy0);
    steady_w(core.ct, core.st, &dq1, &dy1);
    internal::ContactSteadyState(g, core.ct, core.st, prm, &qp1, &yp1);
    // d q_p / d theta = y_p / w, d y_p / d theta = -w (q_p - b).
    dq1 += t * yp1 / w;
    dy1 -= t * w * (qp1 - b);
    (*dx)[DO::kQ] = dq1 - (core.e00 * dq0 + core.e01 * dy0);
    (*dx)[DO::kY] = dy1 - (core.e10 * dq0 + core.e11 * dy0);
    (*dx)[DO::kP] = (*dx)[DO::kQ];
    return;
  }
  const double x = core.xw, s3 = core.s3, c2 = core.c2, sinc = core.sinc;
  const double di1 = t * t * (-c0 * x * (c2 - s3) - s0 * (sinc - c2));
  (*dx)[DO::kY] = a * di1;
  if (seg.mode == DO::kNoContact) {
    const double di2 = t * t * t * (-c0 * internal::MinusC2Derivative(x) - s0 * (c2 - 2.0 * s3));
    (*dx)[DO::kP] = a * di2;
  }
}

// d x(t) / d x0 of a prepared segment from its core at t (Flow's Jacobian).
void FlowJacobian(const PreparedSegment& seg, const Core& k, double t, const Params& params,
                  StateMatrix* jac) {
  using DO = DriftingOscillator;
  jac->setIdentity(4, 4);
  const double a = params[DO::kA];
  const double c0 = seg.c[kCos0], s0 = seg.c[kSin0];
  // J1 = -dI1/dtheta0 and J2 = -dI2/dtheta0 (see the header comment).
  const double j1 = t * (s0 * k.sinc + c0 * k.xw * k.c2);
  const double j2 = t * t * (s0 * k.c2 + c0 * k.xw * k.s3);
  switch (seg.mode) {
    case DO::kNoContact:
      (*jac)(DO::kP, DO::kY) = t;
      (*jac)(DO::kP, DO::kS) = -a * j2;
      (*jac)(DO::kY, DO::kS) = -a * j1;
      (*jac)(DO::kQ, DO::kQ) = k.decay;
      return;
    case DO::kContact: {
      // d u / d s0 = d u_p(theta)/d theta - expm(A t) d u_p(theta0)/d theta, where
      // d q_p / d theta = y_p / w and d y_p / d theta = -w (q_p - b).
      const internal::ContactGain g = GainOf(seg);
      const double w = params[DO::kOmega];
      double qp0, yp0, qp1, yp1;
      internal::ContactSteadyState(g, c0, s0, params, &qp0, &yp0);
      internal::ContactSteadyState(g, k.ct, k.st, params, &qp1, &yp1);
      const double dq0 = yp0 / w, dy0 = -w * (qp0 - params[DO::kB]);
      const double dq1 = yp1 / w, dy1 = -w * (qp1 - params[DO::kB]);
      const double dq_ds = dq1 - (k.e00 * dq0 + k.e01 * dy0);
      const double dy_ds = dy1 - (k.e10 * dq0 + k.e11 * dy0);
      (*jac)(DO::kQ, DO::kQ) = k.e00, (*jac)(DO::kQ, DO::kY) = k.e01,
                     (*jac)(DO::kQ, DO::kS) = dq_ds;
      (*jac)(DO::kY, DO::kQ) = k.e10, (*jac)(DO::kY, DO::kY) = k.e11,
                     (*jac)(DO::kY, DO::kS) = dy_ds;
      (*jac)(DO::kP, DO::kQ) = k.e00 - 1.0, (*jac)(DO::kP, DO::kY) = k.e01;
      (*jac)(DO::kP, DO::kS) = dq_ds;
      return;
    }
    default:
      (*jac)(DO::kQ, DO::kQ) = 1.0 + k.decay;
      (*jac)(DO::kP, DO::kQ) = k.decay;
      (*jac)(DO::kY, DO::kS) = -a * j1;
      return;
  }
}

// FlowParamDerivative's answer where it needs no flow: g never enters one (zero), xi in CwoP is
// left to the matrix exponential (false).
bool ParamDerivative(int k, int mode, StateVector* dx) {
  dx->setZero(4);
  return !(k == DriftingOscillator::kXi && mode == DriftingOscillator::kContact);
}

// Closed-form d x(t) / d params[k] of a prepared segment from its core at t (false: not in closed
// form). `jac`: the segment's flow Jacobian when already computed (phi0's column is its s
// column), else null. g never enters a flow; a and b enter linearly (NC, CwP: through the forcing
// integrals; CwoP: through the steady state, u_p = (b, 0) + a w(theta), so
// d u / d a = w(theta) - E w(theta0) and d u / d b = (1, 0) - E (1, 0)); phi0 shifts theta0 like
// s0 does, without moving s; xi in the decaying q of NC and CwP; omega by OmegaDerivative above.
// xi in CwoP is left to the matrix exponential.
bool ParamDerivative(const PreparedSegment& seg, const Core& core, double t, const Params& params,
                     int k, const StateMatrix* jac, StateVector* dx) {
  using DO = DriftingOscillator;
  const int mode = seg.mode;
  if (k == DO::kG || (k == DO::kXi && mode == DO::kContact)) return ParamDerivative(k, mode, dx);
  dx->setZero(4);
  if (k == DO::kPhi0) {
    StateMatrix own;
    if (jac == nullptr) {
      FlowJacobian(seg, core, t, params, &own);
      jac = &own;
    }
    *dx = jac->col(DO::kS);
    (*dx)[DO::kS] = 0.0;
    return true;
  }
  const StateVector& x0 = seg.x0;
  const double c0 = seg.c[kCos0], s0 = seg.c[kSin0];
  const double i1 = t * (c0 * core.sinc - s0 * core.xw * core.c2);
  const double i2 = t * t * (c0 * core.c2 - s0 * core.xw * core.s3);
  const double xi = params[DO::kXi];
  if (k == DO::kOmega) {
    OmegaDerivative(seg, core, t, params, dx);
    return true;
  }
  switch (mode) {
    case DO::kNoContact:
      if (k == DO::kA) (*dx)[DO::kP] = i2, (*dx)[DO::kY] = i1;
      if (k == DO::kB) (*dx)[DO::kP] = 0.5 * t * t, (*dx)[DO::kY] = t;
      // q = q0 e^{-t/(2 xi)}: d/dxi = q t / (2 xi^2).
      if (k == DO::kXi) (*dx)[DO::kQ] = core.x[DO::kQ] * t / (2.0 * xi * xi);
      return true;
    case DO::kProgression:
      if (k == DO::kA) (*dx)[DO::kY] = i1;
      if (k == DO::kB) (*dx)[DO::kY] = t;
      if (k == DO::kXi) {
        // q = 1 + (q0 - 1) e^{-t/(2 xi)}, p - q constant.
        const double dq = (x0[DO::kQ] - 1.0) * (1.0 + core.decay) * t / (2.0 * xi * xi);
        (*dx)[DO::kQ] = dq, (*dx)[DO::kP] = dq;
      }
      return true;
    default: {
      double wq0, wy0, wq1, wy1;
      if (k == DO::kA) {
        // w(theta) = d u_p / d a: the steady state of unit amplitude without the static force.
        Params unit = params;
        unit[DO::kA] = 1.0, unit[DO::kB] = 0.0;
        const internal::ContactGain g = GainOf(seg);
        internal::ContactSteadyState(g, c0, s0, unit, &wq0, &wy0);
        internal::ContactSteadyState(g, core.ct, core.st, unit, &wq1, &wy1);
      } else {
        wq0 = wq1 = 1.0, wy0 = wy1 = 0.0;
      }
      (*dx)[DO::kQ] = wq1 - (core.e00 * wq0 + core.e01 * wy0);
      (*dx)[DO::kY] = wy1 - (core.e10 * wq0 + core.e11 * wy0);
      (*dx)[DO::kP] = (*dx)[DO::kQ];
      return true;
    }
  }
}

}  // namespace

void DriftingOscillator::PrepareSegment(int mode, const StateVector& x0, const Params& params,
                                        PreparedSegment* seg) const {
  seg->mode = mode;
  seg->x0 = x0;
  const double theta0 = x0[kS] + params[kPhi0];
  seg->c[kCos0] = std::cos(theta0);
  seg->c[kSin0] = std::sin(theta0);
  if (mode == kContact) {
    const internal::ContactGain k = internal::MakeContactGain(params);
    double qp, yp;
    internal::ContactSteadyState(k, seg->c[kCos0], seg->c[kSin0], params, &qp, &yp);
    seg->c[kDq0] = x0[kQ] - qp;
    seg->c[kDy0] = x0[kY] - yp;
    seg->c[kGainKr] = k.kr, seg->c[kGainKi] = k.ki;
    seg->c[kGainSteady] = k.steady_bound, seg->c[kGainTransient] = k.transient_gain;
  }
}

void DriftingOscillator::EvaluateSegment(const PreparedSegment& seg, double t, const Params& params,
                                         bool with_guards, SegmentPoint* point) const {
  Core k;
  EvaluateCore(seg, t, params, &k);
  point->x = k.x;
  if (!with_guards) return;
  internal::OscillatorGuards(seg.mode, k.x, k.ct, k.st, params, point->guards);
  switch (seg.mode) {
    case kNoContact:
      point->bounds[0] = internal::NoContactBound(k.x[kQ], params);
      point->jerk_bounds[0] = internal::NoContactJerkBound(k.x[kQ], params);
      break;
    case kContact:
      point->bounds[0] = point->bounds[1] = internal::ContactBound(GainOf(seg), k.dq, k.dy);
      break;
    default:
      point->bounds[0] = internal::ProgressionBound(k.x[kQ], params);
      break;
  }
}

void DriftingOscillator::Flow(int mode, const StateVector& x0, double t, const Params& params,
                              StateVector* x, StateMatrix* jac) const {
  PreparedSegment seg;
  PrepareSegment(mode, x0, params, &seg);
  Core k;
  EvaluateCore(seg, t, params, &k);
  *x = k.x;
  if (jac) FlowJacobian(seg, k, t, params, jac);
}

bool DriftingOscillator::FlowParamDerivative(int mode, const StateVector& x0, double t,
                                             const Params& params, int k, StateVector* dx) const {
  if (k == kG || (k == kXi && mode == kContact)) return ParamDerivative(k, mode, dx);
  PreparedSegment seg;
  PrepareSegment(mode, x0, params, &seg);
  Core core;
  EvaluateCore(seg, t, params, &core);
  return ParamDerivative(seg, core, t, params, k, nullptr, dx);
}

void DriftingOscillator::FlowAndParamDerivatives(int mode, const StateVector& x0, double t,
                                                 const Params& params, StateVector* x,
                                                 StateMatrix* jac, std::span<const int> ks,
                                                 std::span<StateVector> dx,
                                                 std::span<bool> ok) const {
  PreparedSegment seg;
  PrepareSegment(mode, x0, params, &seg);
  Core core;
  EvaluateCore(seg, t, params, &core);
  *x = core.x;
  if (jac) FlowJacobian(seg, core, t, params, jac);
  for (size_t i = 0; i < ks.size(); ++i) {
    ok[i] = ParamDerivative(seg, core, t, params, ks[i], jac, &dx[i]);
  }
}

MeasureVector DriftingOscillator::MeasureIncrements(int mode, const StateVector& x0, double t,
                                                    const Params& params, unsigned which) const {
  const double xi = params[kXi];
  MeasureVector m = MeasureVector::Zero(2);
  const bool power = which & (1u << kPower), drift = which & (1u << kDrift);
  switch (mode) {
    case kNoContact:
      // w' = q^2/(2 xi) = -d/dt (q^2/2) since q' = -q/(2 xi): the spring's energy is released.
      if (power) m[kPower] = -0.5 * x0[kQ] * x0[kQ] * std::expm1(-t / xi);
      return m;
    case kContact: {
      if (!power) return m;  // no drift in contact without progression
      // w' = 2 xi y^2: no short closed form; Gauss-Legendre on panels of half the time scale.
      const double panel = 0.5 * std::min(TimeScale(kContact, params), 1.0 / params[kOmega]);
      PreparedSegment seg;
      PrepareSegment(kContact, x0, params, &seg);
      Core k;
      m[kPower] = internal::IntegrateGaussLegendre(
          [&](double tau) {
            EvaluateCore(seg, tau, params, &k);
            return 2.0 * xi * k.x[kY] * k.x[kY];
          },
          t, panel, 0.0);
      return m;
    }
    default: {
      // v' = y - p' (the bit moves at y, p is relative to the slider bottom), so
      // int v' = int y - (p(t) - p0) with int y = y0 t + (b - 1) t^2/2 + a I2.
      PreparedSegment seg;
      PrepareSegment(kProgression, x0, params, &seg);
      Core k;
      EvaluateCore(seg, t, params, &k);
      const double i2 = t * t * (seg.c[kCos0] * k.c2 - seg.c[kSin0] * k.xw * k.s3);
      const double int_y = x0[kY] * t + 0.5 * (params[kB] - 1.0) * t * t + params[kA] * i2;
      if (drift) m[kDrift] = int_y - (x0[kQ] - 1.0) * k.decay;
      // w' = (q-1)^2/(2 xi) = -d/dt ((q-1)^2/2).
      if (power) m[kPower] = -0.5 * (x0[kQ] - 1.0) * (x0[kQ] - 1.0) * std::expm1(-t / xi);
      return m;
    }
  }
}

}  // namespace drillbif
