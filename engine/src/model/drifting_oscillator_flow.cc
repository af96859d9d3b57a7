// Closed-form flows of the drifting oscillator's three linear modes, with d x(t) / d x0, and the
// measures' increments. Notation: theta0 = s0 + phi0, x = omega t.
//
// Forcing integrals (all free of 1/omega, hence exact and robust as omega t -> 0):
//   I1 = int_0^t cos(theta0 + w tau) dtau       = t [cos th0 sinc(x) - sin th0 x C2(x)]
//   I2 = int_0^t I1                             = t^2 [cos th0 C2(x) - sin th0 x S3(x)]
//   J1 = int_0^t sin(theta0 + w tau) dtau       = t [sin th0 sinc(x) + cos th0 x C2(x)]
//   J2 = int_0^t J1                             = t^2 [sin th0 C2(x) + cos th0 x S3(x)]
// with C2 = (1 - cos x)/x^2, S3 = (x - sin x)/x^3; dI1/dtheta0 = -J1, dI2/dtheta0 = -J2.
//
// Contact (CwoP) on u = (q, y): u' = A u + (0, a cos theta + b), A = [[0, 1], [-1, -2 xi]].
// Steady state u_p: q_p = b + a Re(K e^{i theta}), y_p = q_p', K = 1/(1 - w^2 + 2 i xi w)
// (never singular since xi > 0). Homogeneous part: expm(A t) = e^{-xi t}[C I + S (A + xi I)] with
// (A + xi I)^2 = (xi^2 - 1) I, C = cos(mu t), S = sin(mu t)/mu, mu^2 = 1 - xi^2; analytic in mu^2,
// so one series covers xi = 1 (repeated root) and its neighbourhood, cosh/sinh cover xi > 1.
#include <cmath>
#include <complex>

#include "common/gauss_legendre.h"
#include "common/small_arg.h"
#include "drillbif/model/drifting_oscillator.h"

namespace drillbif {
namespace {

using internal::OneMinusCosOverSq;
using internal::Sinc;
using internal::XMinusSinOverCube;

struct ForcingIntegrals {
  double i1, i2, j1, j2;
};

ForcingIntegrals Integrals(double theta0, double omega, double t) {
  const double x = omega * t;
  const double c = std::cos(theta0), s = std::sin(theta0);
  const double sc = Sinc(x), c2 = OneMinusCosOverSq(x), s3 = XMinusSinOverCube(x);
  return {t * (c * sc - s * x * c2), t * t * (c * c2 - s * x * s3), t * (s * sc + c * x * c2),
          t * t * (s * c2 + c * x * s3)};
}

// expm(A t) for A = [[0, 1], [-1, -2 xi]], returned as e^{-xi t} C and e^{-xi t} S.
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

struct SteadyState {
  double q, y, dq_dtheta, dy_dtheta;
};

// u_p at phase theta and its derivative with respect to theta.
SteadyState ContactSteadyState(const Params& prm, double theta) {
  using DO = DriftingOscillator;
  const double a = prm[DO::kA], w = prm[DO::kOmega], xi = prm[DO::kXi];
  const std::complex<double> k = 1.0 / std::complex<double>(1.0 - w * w, 2.0 * xi * w);
  const std::complex<double> e = std::polar(1.0, theta);
  const std::complex<double> ke = k * e, ike = std::complex<double>(0.0, 1.0) * ke;
  // q_p = b + a Re(K e), y_p = a w Re(i K e); d/dtheta multiplies K e by i.
  return {prm[DO::kB] + a * ke.real(), a * w * ike.real(), a * ike.real(), -a * w * ke.real()};
}

}  // namespace

void DriftingOscillator::Flow(int mode, const StateVector& x0, double t, const Params& params,
                              StateVector* x, StateMatrix* jac) const {
  const double a = params[kA], b = params[kB], w = params[kOmega], xi = params[kXi];
  const double theta0 = x0[kS] + params[kPhi0];
  x->resize(4);
  (*x)[kS] = x0[kS] + w * t;
  if (jac) {
    jac->setIdentity(4, 4);
  }
  switch (mode) {
    case kNoContact: {
      const ForcingIntegrals f = Integrals(theta0, w, t);
      const double e = std::exp(-t / (2.0 * xi));
      (*x)[kP] = x0[kP] + x0[kY] * t + 0.5 * b * t * t + a * f.i2;
      (*x)[kY] = x0[kY] + b * t + a * f.i1;
      (*x)[kQ] = x0[kQ] * e;
      if (jac) {
        (*jac)(kP, kY) = t;
        (*jac)(kP, kS) = -a * f.j2;
        (*jac)(kY, kS) = -a * f.j1;
        (*jac)(kQ, kQ) = e;
      }
      return;
    }
    case kContact: {
      const DampedExp ex = DampedOscillatorExp(xi, t);
      // expm(A t) = ec I + es (A + xi I), A + xi I = [[xi, 1], [-1, -xi]].
      const double e00 = ex.ec + ex.es * xi, e01 = ex.es, e10 = -ex.es, e11 = ex.ec - ex.es * xi;
      const SteadyState u0 = ContactSteadyState(params, theta0);
      const SteadyState u1 = ContactSteadyState(params, theta0 + w * t);
      const double dq0 = x0[kQ] - u0.q, dy0 = x0[kY] - u0.y;
      (*x)[kQ] = u1.q + e00 * dq0 + e01 * dy0;
      (*x)[kY] = u1.y + e10 * dq0 + e11 * dy0;
      (*x)[kP] = x0[kP] + ((*x)[kQ] - x0[kQ]);  // p - q is constant in contact
      if (jac) {
        const double dq_ds = u1.dq_dtheta - (e00 * u0.dq_dtheta + e01 * u0.dy_dtheta);
        const double dy_ds = u1.dy_dtheta - (e10 * u0.dq_dtheta + e11 * u0.dy_dtheta);
        (*jac)(kQ, kQ) = e00, (*jac)(kQ, kY) = e01, (*jac)(kQ, kS) = dq_ds;
        (*jac)(kY, kQ) = e10, (*jac)(kY, kY) = e11, (*jac)(kY, kS) = dy_ds;
        (*jac)(kP, kQ) = e00 - 1.0, (*jac)(kP, kY) = e01, (*jac)(kP, kS) = dq_ds;
      }
      return;
    }
    default: {
      const ForcingIntegrals f = Integrals(theta0, w, t);
      const double em1 = std::expm1(-t / (2.0 * xi));
      const double dq = (x0[kQ] - 1.0) * em1;  // q(t) - q0
      (*x)[kQ] = x0[kQ] + dq;
      (*x)[kP] = x0[kP] + dq;
      (*x)[kY] = x0[kY] + (b - 1.0) * t + a * f.i1;
      if (jac) {
        (*jac)(kQ, kQ) = 1.0 + em1;
        (*jac)(kP, kQ) = em1;
        (*jac)(kY, kS) = -a * f.j1;
      }
      return;
    }
  }
}

MeasureVector DriftingOscillator::MeasureIncrements(int mode, const StateVector& x0, double t,
                                                    const Params& params) const {
  const double xi = params[kXi];
  MeasureVector m = MeasureVector::Zero(2);
  switch (mode) {
    case kNoContact:
      // w' = q^2/(2 xi) = -d/dt (q^2/2) since q' = -q/(2 xi): the spring's energy is released.
      m[kPower] = -0.5 * x0[kQ] * x0[kQ] * std::expm1(-t / xi);
      return m;
    case kContact: {
      // w' = 2 xi y^2: no short closed form; Gauss-Legendre on panels of half the time scale.
      const double panel = 0.5 * std::min(TimeScale(kContact, params), 1.0 / params[kOmega]);
      StateVector x;
      m[kPower] = internal::IntegrateGaussLegendre(
          [&](double tau) {
            Flow(kContact, x0, tau, params, &x, nullptr);
            return 2.0 * xi * x[kY] * x[kY];
          },
          t, panel, 0.0);
      return m;
    }
    default: {
      // v' = y - p' (the bit moves at y, p is relative to the slider bottom), so
      // int v' = int y - (p(t) - p0) with int y = y0 t + (b - 1) t^2/2 + a I2.
      const ForcingIntegrals f = Integrals(x0[kS] + params[kPhi0], params[kOmega], t);
      const double em1 = std::expm1(-t / (2.0 * xi));
      const double int_y = x0[kY] * t + 0.5 * (params[kB] - 1.0) * t * t + params[kA] * f.i2;
      m[kDrift] = int_y - (x0[kQ] - 1.0) * em1;
      // w' = (q-1)^2/(2 xi) = -d/dt ((q-1)^2/2).
      m[kPower] = -0.5 * (x0[kQ] - 1.0) * (x0[kQ] - 1.0) * std::expm1(-t / xi);
      return m;
    }
  }
}

}  // namespace drillbif
