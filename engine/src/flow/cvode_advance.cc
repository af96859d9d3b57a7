// CvodePropagator::Advance: one segment of flow in a mode up to the first event or t_max, on the
// CVODES integrator of flow/cvode_integrator.h.
//
// Event semantics of Advance, the same as the exact propagator's (flow/safe_event_locator.h) up to
// integration accuracy, so that the two can be compared event by event:
//  - Root functions: for guard i, g_2i = h (direction decreasing: crossings into h < 0) and
//    g_2i+1 = h' (direction increasing: the minima of h, where a graze turns back). CVode runs in
//    CV_ONE_STEP mode with the stop time t_max, so that every internal step end is seen: the start
//    logic below needs it, samples and crossings inside a step come from its dense output.
//  - A crossing (h root) is an event at the crossing.
//  - A minimum (h' root) with 0 < h <= tolerance is a tangential event at the minimum (the flow
//    turns back inside the band). A minimum with h <= 0 means that both crossings of a shallow dip
//    fell inside one internal step, so that no sign change of h was seen at the step ends: the
//    first crossing is located on the dense output of the step (grid, then bisection) and reported.
//    Minima with h > tolerance (near misses) are ignored.
//  - The tangential flag of a crossing: set when the crossing cannot be told from a graze at the
//    integrator's accuracy, i.e. when its local parabola h' tau + h'' tau^2 / 2 dips at most
//        d_graze = max(tolerance, kGrazeResolution * sum_j |dh/dx_j| (rtol |x_j| + atol))
//    below the surface (h'^2 <= 2 |h''| d_graze); the sum is the tolerance CVODE keeps on h per
//    step (global errors are larger). The exact propagator is accurate to rounding and flags only
//    the minima inside the band.
//  - Start: a guard with h(x0) <= tolerance fires at once (duration 0) when its local parabola
//    moves into h < 0 (internal::MovesInto, shared with the exact propagator); otherwise it is
//    leaving the surface (the usual situation right after the simulator applied its jump): it is
//    disarmed until h > tolerance at a step end. If it falls below -tolerance instead, it fires at
//    the start of that step.
//  - A disarmed guard's root functions are masked while it is inside the band: g_2i = max(h, tol)
//    and g_2i+1 = (h > tol ? h' : 1), which have no roots there and equal h and h' where it leaves,
//    so that CVODE's values at the step end where it is armed are the true ones. Handing CVODE the
//    raw functions instead fails: right after a separation (F = 0) the drifting oscillator's
//    impact guard starts with h and h' = -F / (2 xi) both at rounding level, so that h' (or h)
//    has a "root" within ~1e-17 of the start; CVODE returns it, and on the next call finds the
//    function exactly zero at that root and again ttol = 100 u (|t| + |step|) ~ 1e-20 later, and
//    stops with CV_ILL_INPUT (cvRcheck2, "Root found at and very near t"). A root reported for a
//    masked function (h came back down through tol inside the step) arms the guard but is not an
//    event. Root values are never exactly zero either (NonZero,
//    flow/cvode_integrator_callbacks.cc), which rules that failure out for armed guards too, e.g. a
//    rounding-level minimum of h just above the band, a near miss that CVode must step past.
#include <cvodes/cvodes.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "drillbif/flow/cvode_propagator.h"
#include "flow/cvode_propagator_impl.h"
#include "flow/cvode_util.h"
#include "flow/safe_event_locator.h"

namespace drillbif {
namespace {

using internal::FormatDouble;

// Crossings whose dip below the surface is within this many local tolerances of h are flagged
// tangential (see d_graze above). Adams' global error on the test oscillator is 5-15 local
// tolerances over the first periods, BDF's up to 50 times more.
constexpr double kGrazeResolution = 100.0;
// Safety cap on trajectory samples of one Advance call.
constexpr size_t kMaxSamples = 10000000;

bool Finite(const GuardValue& g) {
  return std::isfinite(g.h) && std::isfinite(g.dh) && std::isfinite(g.ddh);
}

}  // namespace

bool CvodePropagator::Impl::Shallow(int i, const StateVector& x, const GuardValue& g) const {
  return g.dh >= 0.0 || g.dh * g.dh <= 2.0 * std::abs(g.ddh) * GrazeDepth(i, x);
}

double CvodePropagator::Impl::GrazeDepth(int i, const StateVector& x) const {
  const StateRow grad = model.GuardGradient(integrator.mode(), i, x, integrator.params());
  double acc = 0.0;
  const int n = std::min<int>(static_cast<int>(grad.size()), static_cast<int>(x.size()));
  for (int j = 0; j < n; ++j) {
    acc += std::abs(grad[j]) * (options.rtol * std::abs(x[j]) + options.atol);
  }
  if (!std::isfinite(acc)) acc = 0.0;
  return std::max(options.events.tolerance, kGrazeResolution * acc);
}

AdvanceResult CvodePropagator::Impl::RunAdvance(const AdvanceRequest& request,
                                                const Params& params) {
  AdvanceResult res;
  res.x = request.x0;
  res.status = CheckCommon(request.mode, request.x0, params);
  if (res.status.ok() && !(request.t_max >= 0.0 && std::isfinite(request.t_max))) {
    res.status = InvalidArgument("AdvanceRequest.t_max must be finite and >= 0 (got " +
                                 FormatDouble(request.t_max) + ")");
  }
  if (res.status.ok() && !(request.sample_dt >= 0.0 && std::isfinite(request.sample_dt))) {
    res.status = InvalidArgument("AdvanceRequest.sample_dt must be finite and >= 0 (got " +
                                 FormatDouble(request.sample_dt) + ")");
  }
  if (res.status.ok() && request.measures &&
      static_cast<int>(model.measure_names().size()) > kMaxMeasures) {
    res.status = InvalidArgument("the model has more than kMaxMeasures measures");
  }
  if (!res.status.ok()) return res;

  const int mode = request.mode;
  const int ng = static_cast<int>(model.guards(mode).size());
  const int nq = static_cast<int>(model.measure_names().size());
  const double tol = options.events.tolerance;
  const double sample_dt = request.sample_dt;
  if (request.measures) res.measures = MeasureVector::Zero(nq);

  auto fail = [&res](Status st) {
    res.status = std::move(st);
    res.end = AdvanceEnd::kFailed;
  };
  // Ends the segment at (t, x) with measures m: drops samples at or after t, adds the end point.
  auto finish = [&](AdvanceEnd end, int guard, bool tangential, double t, const StateVector& x,
                    const MeasureVector& m) {
    res.end = end;
    res.guard = guard;
    res.tangential = tangential;
    res.duration = t;
    res.x = x;
    if (request.measures) res.measures = m;
    if (sample_dt > 0.0) {
      while (!res.samples.empty() && res.samples.back().t >= t) res.samples.pop_back();
      res.samples.push_back(TrajectorySample{t, x});
    }
    if (!res.x.allFinite() || (request.measures && !res.measures.allFinite())) {
      fail(Internal("CVODES Advance produced a non-finite state or measure in mode " +
                    std::string(model.mode_name(mode))));
    }
  };

  // ---- start: guards already on their surface (see the file comment) ----
  std::vector<char>& armed = integrator.armed();
  armed.assign(ng, 1);
  for (int i = 0; i < ng; ++i) {
    const GuardValue g = model.Guard(mode, i, request.x0, params);
    if (!Finite(g)) {
      fail(Internal("guard " + model.guards(mode)[i].name + " is not finite at x0"));
      return res;
    }
    if (g.h > tol) continue;
    if (internal::MovesInto(g, tol)) {
      // Tangential as in the exact propagator: a touch from inside the band, or a slow approach.
      finish(AdvanceEnd::kEvent, i, g.h > 0.0 || g.dh * g.dh <= 2.0 * tol, 0.0, request.x0,
             res.measures);
      return res;
    }
    armed[i] = 0;  // leaving the surface
  }
  if (request.t_max == 0.0) {
    finish(AdvanceEnd::kTimeLimit, -1, false, 0.0, request.x0, res.measures);
    return res;
  }

  internal::CvodeIntegrator::Setup setup;
  setup.mode = mode;
  setup.x0 = &request.x0;
  setup.t_stop = request.t_max;
  setup.active_guards = ng;
  setup.quadrature = request.measures && nq > 0;
  Status st = integrator.Prepare(setup, params);
  if (!st.ok()) {
    fail(st);
    return res;
  }

  long next_sample = 0;
  if (sample_dt > 0.0) {
    res.samples.push_back(TrajectorySample{0.0, request.x0});
    next_sample = 1;
  }

  // The earliest event found at one return (ties: lowest guard index).
  struct Candidate {
    int guard = -1;
    double t = 0.0;
    bool tangential = false;
    StateVector x;
    MeasureVector m;
  } ev;
  auto consider = [&ev](int i, double t, bool tangential, const StateVector& x,
                        const MeasureVector& m) {
    if (ev.guard >= 0 && (ev.t < t || (ev.t == t && ev.guard <= i))) return;
    ev.guard = i;
    ev.t = t;
    ev.tangential = tangential;
    ev.x = x;
    ev.m = m;
  };

  const std::vector<int>& roots_found = integrator.roots_found();
  double t_prev = 0.0;
  int root_returns = 0;
  MeasureVector m_now = res.measures;
  while (true) {
    double tret = 0.0;
    const int flag = integrator.Integrate(request.t_max, CV_ONE_STEP, &tret);
    const long nfe = integrator.NumRhsEvals();
    res.evaluations = static_cast<int>(std::min<long>(nfe, std::numeric_limits<int>::max()));
    if (flag < 0) {
      res.duration = t_prev;
      fail(integrator.Fail(flag, "CVode"));
      return res;
    }
    const StateVector x = integrator.State();
    const long nst = integrator.NumSteps();
    if (nst > options.max_steps) {
      res.duration = tret;
      res.x = x;
      fail(Internal("CVODES Advance: more than max_steps = " + std::to_string(options.max_steps) +
                    " internal steps before t_max or an event (CV_TOO_MUCH_WORK)"));
      return res;
    }

    // Samples in (t_prev, tret], from the dense output of the current step.
    if (sample_dt > 0.0) {
      while (static_cast<double>(next_sample) * sample_dt <= tret) {
        if (!integrator.KeepGoing()) {
          fail(Cancelled("advance cancelled"));
          return res;
        }
        const double ts = static_cast<double>(next_sample) * sample_dt;
        StateVector xs = x;
        if (ts != tret) {
          st = integrator.DenseOutput(ts, &xs, nullptr);
          if (!st.ok()) {
            fail(st);
            return res;
          }
        }
        res.samples.push_back(TrajectorySample{ts, xs});
        ++next_sample;
        if (res.samples.size() > kMaxSamples) {
          fail(OutOfRange("Advance: more than " + std::to_string(kMaxSamples) +
                          " trajectory samples (sample_dt too small for t_max)"));
          return res;
        }
      }
    }

    ev.guard = -1;
    if (flag == CV_ROOT_RETURN) {
      st = integrator.CurrentMeasures(&m_now);
      if (!st.ok()) {
        fail(st);
        return res;
      }
    }

    // Guards that started on their surface take part once they have left the band; one that
    // falls through it instead fires at the start of the step (as in the exact propagator).
    // A root of a masked function means that the guard left the band inside the step (h' then
    // had a root with h > tol, or h came back down through tol): it is armed here too. Roots
    // reported at this return for a guard armed only now came from its masked functions and
    // are not events (skipped below).
    if (flag == CV_ROOT_RETURN) {
      st = integrator.FetchRootInfo();
      if (!st.ok()) {
        fail(st);
        return res;
      }
    }
    armed_before.assign(armed.begin(), armed.end());
    for (int i = 0; i < ng; ++i) {
      if (armed[i]) continue;
      const double h = model.Guard(mode, i, x, params).h;
      const bool masked_root =
          flag == CV_ROOT_RETURN && (roots_found[2 * i] != 0 || roots_found[2 * i + 1] != 0);
      if (h > tol || (masked_root && h >= -tol)) {
        armed[i] = 1;
      } else if (h < -tol) {
        StateVector xp;
        MeasureVector mp = m_now;
        st = integrator.DenseOutput(t_prev, &xp, &mp);
        if (!st.ok()) {
          fail(st);
          return res;
        }
        consider(i, t_prev, false, xp, mp);
      }
    }

    if (flag == CV_ROOT_RETURN) {
      if (++root_returns > options.events.max_iterations) {
        fail(Internal("CVODES Advance: more than events.max_iterations = " +
                      std::to_string(options.events.max_iterations) + " root returns"));
        return res;
      }
      for (int i = 0; i < ng; ++i) {
        if (!armed_before[i]) continue;
        const bool crossing = roots_found[2 * i] < 0;     // h decreasing through 0
        const bool minimum = roots_found[2 * i + 1] > 0;  // h' increasing through 0
        if (!crossing && !minimum) continue;
        const GuardValue g = model.Guard(mode, i, x, params);
        if (!Finite(g)) {
          fail(Internal("guard " + model.guards(mode)[i].name + " is not finite"));
          return res;
        }
        if (crossing) {
          consider(i, tret, Shallow(i, x, g), x, m_now);
        } else if (g.h > 0.0 && g.h <= tol) {
          consider(i, tret, true, x, m_now);  // turned back inside the band: a graze
        } else if (g.h <= 0.0) {
          // Both crossings of a dip fell inside the last step: report the first one.
          double tc = 0.0;
          StateVector xc;
          MeasureVector mc = m_now;
          st = integrator.LocateCrossing(i, t_prev, tret, &tc, &xc, &mc);
          if (!st.ok()) {
            fail(st);
            return res;
          }
          consider(i, tc, Shallow(i, xc, model.Guard(mode, i, xc, params)), xc, mc);
        }
      }
    }

    if (ev.guard >= 0) {
      finish(AdvanceEnd::kEvent, ev.guard, ev.tangential, ev.t, ev.x, ev.m);
      return res;
    }
    if (flag == CV_TSTOP_RETURN || tret >= request.t_max) {
      st = integrator.CurrentMeasures(&m_now);
      if (!st.ok()) {
        fail(st);
        return res;
      }
      finish(AdvanceEnd::kTimeLimit, -1, false, tret, x, m_now);
      return res;
    }
    t_prev = tret;
  }
}

}  // namespace drillbif
