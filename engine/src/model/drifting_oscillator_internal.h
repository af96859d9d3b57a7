// Formulas of the drifting oscillator shared by its vector-field, guard and closed-form-flow code:
// the guards with their time derivatives, their curvature bounds, and the contact mode's harmonic
// steady state. Each takes the trigonometry of the forcing phase precomputed, so that a caller
// evaluating flow and guards at one time computes it once.
#ifndef DRILLBIF_MODEL_DRIFTING_OSCILLATOR_INTERNAL_H_
#define DRILLBIF_MODEL_DRIFTING_OSCILLATOR_INTERNAL_H_

#include <cmath>

#include "drillbif/model/drifting_oscillator.h"

namespace drillbif::internal {

using DO = DriftingOscillator;

// Guards of `mode` at x, with ct = cos(s + phi0), st = sin(s + phi0).
inline void OscillatorGuards(int mode, const StateVector& x, double ct, double st,
                             const Params& prm, GuardValue* g) {
  const double xi = prm[DO::kXi], a = prm[DO::kA], b = prm[DO::kB], w = prm[DO::kOmega];
  switch (mode) {
    case DO::kNoContact:
      // h = q + g - p; h' = q' - y = -q/(2 xi) - y; h'' = q/(4 xi^2) - (a cos + b).
      g[0].h = x[DO::kQ] + prm[DO::kG] - x[DO::kP];
      g[0].dh = -x[DO::kQ] / (2.0 * xi) - x[DO::kY];
      g[0].ddh = x[DO::kQ] / (4.0 * xi * xi) - (a * ct + b);
      return;
    case DO::kContact: {
      // F = 2 xi y + q; F' = 2 xi (a cos + b - F) + y; F'' = 2 xi (-a w sin - F') + y'.
      const double f = 2.0 * xi * x[DO::kY] + x[DO::kQ];
      const double dy = a * ct + b - f;
      const double df = 2.0 * xi * dy + x[DO::kY];
      const double ddf = 2.0 * xi * (-a * w * st - df) + dy;
      g[DO::kProgressionStart] = {1.0 - f, -df, -ddf};
      g[DO::kSeparation] = {f, df, ddf};
      return;
    }
    default: {
      // h = F - 1; F' = 2 xi (a cos + b - 1) + q' with q' = (1 - q)/(2 xi);
      // F'' = -2 xi a w sin + q'' with q'' = -q'/(2 xi).
      const double dq = (1.0 - x[DO::kQ]) / (2.0 * xi);
      g[0].h = 2.0 * xi * x[DO::kY] + x[DO::kQ] - 1.0;
      g[0].dh = 2.0 * xi * (a * ct + b - 1.0) + dq;
      g[0].ddh = -2.0 * xi * a * w * st - dq / (2.0 * xi);
      return;
    }
  }
}

// Rounding in the bounds' terms is 1e-15 relative at most; a 1e-12 relative margin covers it,
// and the tiny floor keeps the bound positive.
inline double SafeBound(double bound) { return bound * (1.0 + 1e-12) + 1e-300; }

// NC: |h''| <= |q|/(4 xi^2) + a + b, and |q| decays monotonically in free flight.
inline double NoContactBound(double q, const Params& prm) {
  const double xi = prm[DO::kXi];
  return SafeBound(std::abs(q) / (4.0 * xi * xi) + prm[DO::kA] + prm[DO::kB]);
}

// NC: h''' = q'/(4 xi^2) + a w sin = -q/(8 xi^3) + a w sin, so |h'''| <= |q|/(8 xi^3) + a w while
// |q| decays.
inline double NoContactJerkBound(double q, const Params& prm) {
  const double xi = prm[DO::kXi];
  return SafeBound(std::abs(q) / (8.0 * xi * xi * xi) + std::abs(prm[DO::kA]) * prm[DO::kOmega]);
}

// CwP: |F''| <= 2 xi a w + |1 - q|/(4 xi^2), and |1 - q| decays monotonically in progression.
inline double ProgressionBound(double q, const Params& prm) {
  const double xi = prm[DO::kXi];
  return SafeBound(2.0 * xi * prm[DO::kA] * prm[DO::kOmega] + std::abs(1.0 - q) / (4.0 * xi * xi));
}

// Contact (CwoP) on u = (q, y): u' = A u + (0, a cos theta + b), A = [[0, 1], [-1, -2 xi]].
// Steady state q_p = b + a Re(K e^{i theta}), y_p = q_p', with K = kr + i ki =
// 1/(1 - w^2 + 2 i xi w), never singular since xi > 0.
struct ContactGain {
  double kr, ki;
  // |F_p''| <= w^2 a |1 + 2 i xi w| |K|: the steady state's share of the curvature bound.
  double steady_bound;
  // |(A^2)^T c| with c = (1, 2 xi): F_h'' = c . A^2 delta for the transient delta = u - u_p.
  double transient_gain;
};

inline ContactGain MakeContactGain(const Params& prm) {
  const double xi = prm[DO::kXi], w = prm[DO::kOmega];
  const double re = 1.0 - w * w, im = 2.0 * xi * w;
  const double k2 = 1.0 / (re * re + im * im);
  ContactGain g;
  g.kr = re * k2;
  g.ki = -im * k2;
  g.steady_bound = w * w * prm[DO::kA] * std::sqrt((1.0 + im * im) * k2);
  const double c0 = 4.0 * xi * xi - 1.0, c1 = 8.0 * xi * xi * xi - 4.0 * xi;
  g.transient_gain = std::sqrt(c0 * c0 + c1 * c1);
  return g;
}

// The steady state (q_p, y_p) at phase theta (ct, st its cosine and sine).
inline void ContactSteadyState(const ContactGain& k, double ct, double st, const Params& prm,
                               double* qp, double* yp) {
  const double a = prm[DO::kA];
  *qp = prm[DO::kB] + a * (k.kr * ct - k.ki * st);
  *yp = a * prm[DO::kOmega] * (-k.kr * st - k.ki * ct);
}

// CwoP: |F''| <= |F_p''| + |F_h''| <= steady_bound + transient_gain |delta(t)|, and |delta| is
// non-increasing because d/dt (q^2 + y^2) = -4 xi y^2 <= 0 for delta' = A delta.
inline double ContactBound(const ContactGain& k, double dq, double dy) {
  return SafeBound(k.steady_bound + k.transient_gain * std::sqrt(dq * dq + dy * dy));
}

}  // namespace drillbif::internal

#endif  // DRILLBIF_MODEL_DRIFTING_OSCILLATOR_INTERNAL_H_
