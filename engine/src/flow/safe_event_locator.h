// Event location by safe stepping on guard curvature bounds, for propagators that can evaluate the
// state at any time of a segment exactly (closed-form or matrix-exponential flows).
//
// For a guard with h > 0 at time t, |h''| <= M (HybridModel::GuardCurvatureBound) gives
//     h(t + tau) >= h + h' tau - M tau^2 / 2 =: L(tau),
// so no root lies in [t, t + tau_safe) where tau_safe is the positive root of L. Where h' < 0,
// h is strictly decreasing on [t, t + |h'|/M], so a sign change there brackets the unique root.
// Each step goes as far as every guard allows (with a bound on |h'''| where the flow gives one,
// the curvature bound of the step's own window: WindowStep); a crossing is polished by safeguarded
// Halley on h (cubic convergence, secant fallback). A minimum of h inside the tolerance band is a
// tangential (grazing) event, located by Newton on h': wherever h' turns from negative to positive
// within a step, unless a lower bound on h over the step (TurnLowerBound) keeps it above the band,
// so that where the steps end does not decide whether a touch is seen. No crossing, however
// shallow, can be stepped over (the parabola stays positive inside each step); a touch within
// (0, tolerance] goes unreported only where h' turns twice inside one step.
//
// Start of a segment (the state may sit on a surface after a jump): a guard with h <= tolerance is
// "into" (fires at once, duration 0) when its local parabola h + h' tau + h'' tau^2/2 does not
// leave the band h <= tolerance, else "departing": ignored until h > tolerance.
#ifndef DRILLBIF_FLOW_SAFE_EVENT_LOCATOR_H_
#define DRILLBIF_FLOW_SAFE_EVENT_LOCATOR_H_

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

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

// The step of a guard leaving the band (ignored until h > tol): out of the band first; in
// sqrt(4 tol / m) it cannot fall more than 2 tol.
inline double DepartingStep(const GuardValue& g, double m, double tol) {
  return std::max(SafeStep(std::max(g.h, 0.0), g.dh, m), std::sqrt(4.0 * tol / m));
}

// With |h'''| <= m3 from t on, h'' >= h''(t) - m3 s over a window [t, t + s]: a curvature bound for
// the parabola on that window, far below the mode's where a short window sees a guard's curvature
// nearly as it is (a free flight just after separation, h ~ 1e-13, h'' ~ 1e-4 against a bound of
// 0.5). The longest step within a window (the remaining time, then quarters of it) that its bound
// allows, if longer than `floor`; else floor. A departing guard takes DepartingStep.
inline double WindowStep(const GuardValue& g, double m3, bool departing, double tol,
                         double remaining, double floor) {
  double best = floor;
  double window = remaining;
  for (int k = 0; k < 8 && window > best; ++k, window *= 0.25) {
    const double m = std::max(m3 * window - g.ddh, std::numeric_limits<double>::min());
    const double safe = departing ? DepartingStep(g, m, tol) : SafeStep(g.h, g.dh, m);
    best = std::max(best, std::min(window, safe));
  }
  return best;
}

// A lower bound on h over a step of length tau where h' turns from negative (d0 at its start) to
// positive (d1 at its end), |h''| <= m: h stays above both ends' parabolas, h0 + d0 s - m s^2 / 2
// and h1 - d1 (tau - s) - m (tau - s)^2 / 2, whose difference is linear in s. The minimum of the
// larger of two concave functions lies at an end of the step or where they meet.
inline double TurnLowerBound(const GuardValue& g0, const GuardValue& g1, double tau, double m) {
  auto from_start = [&](double s) { return g0.h + g0.dh * s - 0.5 * m * s * s; };
  auto from_end = [&](double s) {
    const double r = tau - s;
    return g1.h - g1.dh * r - 0.5 * m * r * r;
  };
  double bound = std::min(std::max(g0.h, from_end(0.0)), std::max(from_start(tau), g1.h));
  const double slope = g0.dh - g1.dh - m * tau;  // d/ds of from_start - from_end
  if (slope != 0.0) {
    const double s = -(g0.h - g1.h + g1.dh * tau + 0.5 * m * tau * tau) / slope;
    if (s > 0.0 && s < tau) bound = std::min(bound, from_start(s));
  }
  return bound;
}

// Whether a guard starting at h <= tol fires at once: below the band the state is outside the
// mode's domain; inside it, when the guard moves into h < 0.
inline bool MovesInto(const GuardValue& g, double tol) {
  if (g.h < -tol) return true;
  if (g.ddh < 0.0) {
    const double peak = g.h + (g.dh > 0.0 ? g.dh * g.dh / (2.0 * -g.ddh) : 0.0);
    return peak <= tol;
  }
  if (g.ddh > 0.0) return g.dh < 0.0 && g.h - g.dh * g.dh / (2.0 * g.ddh) < -tol;
  return g.dh < 0.0;
}

// Polishes the root of a function v(t) (with v' and v'' known) in the bracket [lo, hi] where
// v(lo) > 0 >= v(hi): Halley steps from the regula-falsi point, kept inside the shrinking bracket
// (a step leaving it falls back to the bracket's secant point). Converges cubically near a simple
// root; stops when the step is below rtol * max(1, t). value(t, &v, &dv, &ddv) evaluates.
// Returns the last evaluated time (the best estimate) and counts evaluations.
template <typename Value>
double PolishRoot(double lo, double v_lo, double hi, double v_hi, double rtol, const Value& value,
                  int* evaluations) {
  auto secant = [&] {
    return v_lo - v_hi > 0.0 ? lo + (hi - lo) * (v_lo / (v_lo - v_hi)) : 0.5 * (lo + hi);
  };
  double t = secant();
  for (int k = 0; k < 100; ++k) {
    double v, dv, ddv;
    value(t, &v, &dv, &ddv);
    ++*evaluations;
    if (v == 0.0) return t;
    if (v > 0.0) {
      lo = t, v_lo = v;
    } else {
      hi = t, v_hi = v;
    }
    const double denom = 2.0 * dv * dv - v * ddv;
    double next = denom != 0.0 ? t - 2.0 * v * dv / denom : t - v / dv;
    if (!(next > lo && next < hi)) next = secant();
    const double step = std::abs(next - t);
    if (step <= rtol * std::max(1.0, std::abs(t)) || hi - lo <= rtol * std::max(1.0, hi)) break;
    t = next;
  }
  return t;
}

// Finds the first event of `mode` in [0, t_max]. eval(t, &point) gives the exact state at time t
// from the segment start (eval(0) is the start), with every guard and its curvature bound.
// keep_going() is asked before every safe step; false ends the search CANCELLED.
template <typename Eval, typename KeepGoing>
LocatedEvent LocateFirstEvent(const HybridModel& model, int mode, double t_max,
                              const EventOptions& opt, const Eval& eval,
                              const KeepGoing& keep_going) {
  const int n = static_cast<int>(model.guards(mode).size());
  const double tol = opt.tolerance;
  LocatedEvent out;
  // The step's two ends swap roles by pointer: a SegmentPoint is a few hundred bytes.
  SegmentPoint ends[2], probe;
  SegmentPoint* cur = &ends[0];
  SegmentPoint* next = &ends[1];
  GuardValue* g = cur->guards;
  bool departing[kMaxGuards] = {};
  double t = 0.0;
  eval(0.0, cur);
  out.evaluations = 1;
  for (int i = 0; i < n; ++i) {
    if (g[i].h <= tol) {
      if (MovesInto(g[i], tol)) {
        out.end = AdvanceEnd::kEvent, out.guard = i, out.t = 0.0, out.x = cur->x;
        out.tangential = g[i].h > 0.0 || std::abs(g[i].dh) * std::abs(g[i].dh) <= 2.0 * tol;
        return out;
      }
      departing[i] = true;
    }
  }
  GuardValue* gn = next->guards;
  for (int iter = 0; iter < opt.max_iterations; ++iter) {
    if (!keep_going()) {
      out.end = AdvanceEnd::kFailed;
      out.status = Cancelled("event location cancelled");
      return out;
    }
    double step = t_max - t;
    for (int i = 0; i < n && step > 0.0; ++i) {
      const double m = cur->bounds[i];
      double tau;
      if (departing[i]) {
        tau = DepartingStep(g[i], m, tol);
      } else {
        tau = SafeStep(g[i].h, g[i].dh, m);
        if (g[i].dh < 0.0) {
          // Monotone on [t, t + |h'|/m]: any point there brackets a crossing uniquely. Aim a little
          // past the Newton estimate so that a crossing is usually bracketed at the first try.
          tau = std::max(tau, std::min(-g[i].dh / m, 1.5 * g[i].h / -g[i].dh));
        }
      }
      if (cur->jerk_bounds[i] > 0.0) {
        tau = WindowStep(g[i], cur->jerk_bounds[i], departing[i], tol, t_max - t, tau);
      }
      step = std::min(step, tau);
    }
    const double tn = (t_max - t <= step) ? t_max : t + step;
    eval(tn, next);
    ++out.evaluations;

    int best = -1;
    double best_t = std::numeric_limits<double>::infinity();
    bool best_tangential = false;
    for (int i = 0; i < n; ++i) {
      double ti = -1.0;
      bool tangential = false;
      const bool crossed = gn[i].h <= 0.0 && !(departing[i] && gn[i].h > -tol);
      if (crossed && g[i].h > 0.0) {
        // The unique root of h in [t, tn] (monotone there, or tn at the safe step's end).
        ti = PolishRoot(
            t, g[i].h, tn, gn[i].h, opt.time_rtol,
            [&](double tk, double* v, double* dv, double* ddv) {
              eval(tk, &probe);
              *v = probe.guards[i].h, *dv = probe.guards[i].dh, *ddv = probe.guards[i].ddh;
            },
            &out.evaluations);
      } else if (crossed) {
        ti = t;  // a departing guard fell through the band within one step: fire at its start
      } else if (!departing[i] && gn[i].dh >= 0.0 &&
                 (gn[i].h <= tol ||
                  (g[i].dh < 0.0 && TurnLowerBound(g[i], gn[i], tn - t, cur->bounds[i]) <= tol))) {
        // Turned back: a tangential contact at the minimum, where h' = 0 (the root of -h', falling
        // through zero in [t, tn]; without a sign change, tn itself), if the minimum lies in the
        // band. Wherever the step ends, the minimum is found: the step's end does not decide.
        if (g[i].dh < 0.0) {
          const double t_min = PolishRoot(
              t, -g[i].dh, tn, -gn[i].dh, opt.time_rtol,
              [&](double tk, double* v, double* dv, double* ddv) {
                eval(tk, &probe);
                *v = -probe.guards[i].dh, *dv = -probe.guards[i].ddh;
                *ddv = 0.0;  // h''' is not known: Newton steps
              },
              &out.evaluations);
          if (probe.guards[i].h <= tol) ti = t_min, tangential = true;
        } else {
          ti = tn, tangential = true;
        }
      }
      if (ti >= 0.0 && ti < best_t) best = i, best_t = ti, best_tangential = tangential;
      if (departing[i] && gn[i].h > tol) departing[i] = false;
    }
    if (best >= 0) {
      out.end = AdvanceEnd::kEvent, out.guard = best, out.tangential = best_tangential;
      out.t = best_t;
      eval(best_t, &probe);
      out.x = probe.x;
      ++out.evaluations;
      return out;
    }
    t = tn;
    std::swap(cur, next);
    g = cur->guards;
    gn = next->guards;
    if (t >= t_max) {
      out.end = AdvanceEnd::kTimeLimit, out.t = t_max, out.x = cur->x;
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
