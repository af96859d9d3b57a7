// Event location by safe stepping on guard curvature bounds, for propagators that can evaluate the
// state at any time of a segment exactly (closed-form or matrix-exponential flows).
//
// For a guard with h > 0 at time t, |h''| <= M (HybridModel::GuardCurvatureBound) gives
//     h(t + tau) >= h + h' tau - M tau^2 / 2 =: L(tau),
// so no root lies in [t, t + tau_safe) where tau_safe is the positive root of L. Where h' < 0,
// h is strictly decreasing on [t, t + |h'|/M], so a sign change there brackets the unique root.
// Each step goes as far as every guard allows; a crossing is polished by safeguarded Newton on h
// (quadratic convergence, bisection fallback), an approach that turns back within the tolerance
// band is a tangential (grazing) event located at the extremum by Newton on h'. No crossing or
// touch deeper than EventOptions::tolerance can be stepped over.
//
// Start of a segment (the state may sit on a surface after a jump): a guard with h <= tolerance is
// "into" (fires at once, duration 0) when its local parabola h + h' tau + h'' tau^2/2 does not leave
// the band h <= tolerance, else "departing": ignored until h > tolerance.
#ifndef DRILLBIF_FLOW_SAFE_EVENT_LOCATOR_H_
#define DRILLBIF_FLOW_SAFE_EVENT_LOCATOR_H_

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include "drillbif/flow/propagator.h"
#include "drillbif/model/hybrid_model.h"

namespace drillbif::internal {

struct LocatedEvent {
  AdvanceEnd end = AdvanceEnd::kTimeLimit;
  int guard = -1;
  bool tangential = false;
  double t = 0.0;
  StateVector x;
  int evaluations = 0;
  Status status;
};

// Largest tau >= 0 with L(tau) = h + dh tau - m tau^2 / 2 >= 0 (h >= 0), in a form without
// cancellation for either sign of dh.
inline double SafeStep(double h, double dh, double m) {
  const double root = std::sqrt(dh * dh + 2.0 * m * h);
  if (dh >= 0.0) return (dh + root) / m;
  return root - dh > 0.0 ? 2.0 * h / (root - dh) : std::numeric_limits<double>::infinity();
}

// Whether a guard starting inside the band (h <= tol) moves into h < 0 at once.
inline bool MovesInto(const GuardValue& g, double tol) {
  if (g.ddh < 0.0) {
    const double peak = g.h + (g.dh > 0.0 ? g.dh * g.dh / (2.0 * -g.ddh) : 0.0);
    return peak <= tol;
  }
  if (g.ddh > 0.0) return g.dh < 0.0 && g.h - g.dh * g.dh / (2.0 * g.ddh) < -tol;
  return g.dh < 0.0;
}

// Finds the first event of `mode` in [0, t_max]. state_at(t, &x) gives the exact state at time t
// from the segment start x0 (state_at(0) == x0).
template <typename StateAt>
LocatedEvent LocateFirstEvent(const HybridModel& model, int mode, const Params& params,
                              const StateVector& x0, double t_max, const EventOptions& opt,
                              const StateAt& state_at) {
  const int n = static_cast<int>(model.guards(mode).size());
  const double tol = opt.tolerance;
  LocatedEvent out;
  GuardValue g[8];
  bool departing[8] = {};
  double t = 0.0;
  StateVector x = x0;
  for (int i = 0; i < n; ++i) {
    g[i] = model.Guard(mode, i, x, params);
    if (g[i].h <= tol) {
      if (MovesInto(g[i], tol)) {
        out.end = AdvanceEnd::kEvent, out.guard = i, out.t = 0.0, out.x = x0;
        out.tangential = g[i].h > 0.0 || std::abs(g[i].dh) * std::abs(g[i].dh) <= 2.0 * tol;
        return out;
      }
      departing[i] = true;
    }
  }
  if (n == 0) {
    state_at(t_max, &out.x);
    out.t = t_max, out.evaluations = 1;
    return out;
  }

  StateVector xn;
  GuardValue gn[8];
  for (int iter = 0; iter < opt.max_iterations; ++iter) {
    double step = t_max - t;
    for (int i = 0; i < n && step > 0.0; ++i) {
      const double m = model.GuardCurvatureBound(mode, i, x, params);
      double tau;
      if (departing[i]) {
        // Out of the band first; in sqrt(4 tol / m) the guard cannot fall more than 2 tol.
        tau = std::max(SafeStep(std::max(g[i].h, 0.0), g[i].dh, m), std::sqrt(4.0 * tol / m));
      } else {
        tau = SafeStep(g[i].h, g[i].dh, m);
        if (g[i].dh < 0.0) {
          // Monotone on [t, t + |h'|/m]: any point there brackets a crossing uniquely. Aim a little
          // past the Newton estimate so that a crossing is usually bracketed at the first try.
          tau = std::max(tau, std::min(-g[i].dh / m, 1.5 * g[i].h / -g[i].dh));
        }
      }
      step = std::min(step, tau);
    }
    const double tn = (t_max - t <= step) ? t_max : t + step;
    state_at(tn, &xn);
    ++out.evaluations;

    int best = -1;
    double best_t = std::numeric_limits<double>::infinity();
    bool best_tangential = false;
    for (int i = 0; i < n; ++i) {
      gn[i] = model.Guard(mode, i, xn, params);
      double ti = -1.0;
      bool tangential = false;
      const bool crossed = gn[i].h <= 0.0 && !(departing[i] && gn[i].h > -tol);
      if (crossed && g[i].h > 0.0) {
        // Safeguarded Newton on h over the bracket [t, tn].
        double lo = t, hi = tn, tk = tn;
        GuardValue gk = gn[i];
        StateVector xk;
        for (int k = 0; k < 200; ++k) {
          double next = tk - gk.h / gk.dh;
          if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
          const bool done = std::abs(next - tk) <= opt.time_rtol * std::max(1.0, tk);
          tk = next;
          state_at(tk, &xk);
          ++out.evaluations;
          gk = model.Guard(mode, i, xk, params);
          if (gk.h > 0.0) lo = tk; else hi = tk;
          if (gk.h == 0.0 || done || hi - lo <= opt.time_rtol * std::max(1.0, hi)) break;
        }
        ti = tk;
      } else if (crossed) {
        ti = t;  // a departing guard fell through the band within one step: fire at its start
      } else if (!departing[i] && gn[i].h <= tol && gn[i].dh >= 0.0) {
        // Turned back inside the band: a tangential contact at the minimum, where h' = 0.
        tangential = true;
        if (g[i].dh < 0.0) {
          double lo = t, hi = tn, tk = 0.5 * (t + tn);
          StateVector xk;
          for (int k = 0; k < 200; ++k) {
            state_at(tk, &xk);
            ++out.evaluations;
            const GuardValue gk = model.Guard(mode, i, xk, params);
            if (gk.dh < 0.0) lo = tk; else hi = tk;
            double next = gk.ddh > 0.0 ? tk - gk.dh / gk.ddh : 0.5 * (lo + hi);
            if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
            const bool done = std::abs(next - tk) <= opt.time_rtol * std::max(1.0, tk);
            tk = next;
            if (done || hi - lo <= opt.time_rtol * std::max(1.0, hi)) break;
          }
          ti = tk;
        } else {
          ti = tn;
        }
      }
      if (ti >= 0.0 && ti < best_t) best = i, best_t = ti, best_tangential = tangential;
      if (departing[i] && gn[i].h > tol) departing[i] = false;
    }
    if (best >= 0) {
      out.end = AdvanceEnd::kEvent, out.guard = best, out.tangential = best_tangential;
      out.t = best_t;
      state_at(best_t, &out.x);
      ++out.evaluations;
      return out;
    }
    t = tn;
    x = xn;
    std::copy(gn, gn + n, g);
    if (t >= t_max) {
      out.end = AdvanceEnd::kTimeLimit, out.t = t_max, out.x = x;
      return out;
    }
  }
  out.end = AdvanceEnd::kFailed;
  out.status = Internal("event location did not finish in " + std::to_string(opt.max_iterations) +
                        " steps in mode " + std::string(model.mode_name(mode)));
  return out;
}

}  // namespace drillbif::internal

#endif  // DRILLBIF_FLOW_SAFE_EVENT_LOCATOR_H_
