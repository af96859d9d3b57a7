#include "drillbif/orbit/periodic_orbit.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>

#include "common/format.h"
#include "common/phase_progress.h"
#include "orbit/condensed.h"
#include "orbit/monodromy.h"
#include "orbit/orbit_bvp.h"

namespace drillbif {

Status OrbitSolverOptions::Validate() const {
  if (!(tolerance > 0.0 && tolerance < 1e-2)) {
    return InvalidArgument("orbit solver tolerance must be in (0, 1e-2)");
  }
  if (max_iterations < 1) return InvalidArgument("orbit solver max_iterations must be >= 1");
  return Status::Ok();
}

std::string OrbitSolveSummary::BriefReport() const {
  return RunSummary::BriefReport(CountOf(iterations, "Newton iteration") + ", residual " +
                                 internal::FormatNumber(residual, 2));
}

OrbitSolveSummary SolveOrbit(const HybridModel& model, Propagator& propagator,
                             const OrbitSolverOptions& options, PeriodicOrbit* orbit,
                             const ProgressCallback& progress) {
  OrbitSolveSummary summary;
  internal::PhaseProgress phase(propagator, progress);
  auto cancelled = [&] {
    summary.Cancel("cancelled");
    return summary;
  };
  auto fail = [&](Status s) {
    summary.Fail(std::move(s));
    return summary;
  };
  for (const Status& s : {options.Validate(), ValidateSignature(model, orbit->signature),
                          model.ValidateParams(orbit->params)}) {
    if (!s.ok()) return fail(s);
  }
  internal::OrbitBvp bvp(model, propagator, orbit->signature, -1);
  Eigen::VectorXd x = bvp.Pack(*orbit), g;
  Eigen::MatrixXd gx;
  internal::CondensedLu lu(bvp.segments(), bvp.size() / bvp.segments());
  for (summary.iterations = 1; summary.iterations <= options.max_iterations; ++summary.iterations) {
    if (!phase.Continue(static_cast<double>(summary.iterations - 1) / options.max_iterations)) {
      return cancelled();
    }
    if (Status s = bvp.Evaluate(x, orbit->params, &g, &gx, nullptr); !s.ok()) {
      if (phase.stopped()) return cancelled();
      return fail(s);
    }
    // A residual at rounding level (1e-13 of the unknowns' size) is converged even when an
    // ill-conditioned system keeps the steps at noise size.
    if (summary.iterations > 1 &&
        g.lpNorm<Eigen::Infinity>() <= 1e-13 * (1.0 + x.lpNorm<Eigen::Infinity>())) {
      break;
    }
    // Condensed (orbit/condensed.h) when asked for and its growth allows, else (and where that
    // step is not finite: a singular reduced system) a rank-revealing QR of the whole system.
    Eigen::VectorXd step;
    if (options.condensed_solve && lu.Compute(gx)) step = lu.Solve(-g);
    if (!lu.condensed() || !step.allFinite()) step = gx.colPivHouseholderQr().solve(-g);
    if (!step.allFinite()) return fail(FailedPrecondition("singular Newton system"));
    x += step;
    if (step.lpNorm<Eigen::Infinity>() <= options.tolerance * (1.0 + x.lpNorm<Eigen::Infinity>())) {
      break;
    }
  }
  if (Status s = bvp.Evaluate(x, orbit->params, &g, nullptr, nullptr); !s.ok()) {
    if (phase.stopped()) return cancelled();
    return fail(s);
  }
  if (phase.stopped()) return cancelled();
  bvp.Unpack(x, orbit->params, orbit);
  summary.residual = g.lpNorm<Eigen::Infinity>();
  if (summary.iterations > options.max_iterations) {
    summary.iterations = options.max_iterations;
    summary.NoConvergence("Newton did not converge in " + std::to_string(options.max_iterations) +
                          " iterations (residual " + std::to_string(summary.residual) + ")");
    return summary;
  }
  summary.Complete();
  return summary;
}

Stability OrbitStability(const HybridModel& model, Propagator& propagator,
                         const PeriodicOrbit& orbit) {
  Stability st;
  st.monodromy =
      internal::ReducedMonodromy(model, internal::MonodromyFactors(model, propagator, orbit));
  const Eigen::VectorXcd mu = st.monodromy.eigenvalues();
  // On a constraint surface throughout: the multiplier nearest 1 is the constraint's (within
  // 1e-9 of 1: the flows keep the constraint's value to rounding, ~1e-15 measured).
  bool confined = true;
  for (size_t i = 0; i < orbit.durations.size() && confined; ++i) {
    double c = 0.0;
    StateRow grad;
    ParamVector param_grad;
    confined = model.ModeConstraint(orbit.signature.segments[i].mode, orbit.starts[i], orbit.params,
                                    &c, &grad, &param_grad);
  }
  int unit = -1;
  if (confined) {
    for (int i = 0; i < mu.size(); ++i) {
      if (std::abs(mu[i] - 1.0) <= 1e-9 &&
          (unit < 0 || std::abs(mu[i] - 1.0) < std::abs(mu[unit] - 1.0))) {
        unit = i;
      }
    }
  }
  st.structural_ones = unit >= 0 ? 1 : 0;
  st.stable = true;
  for (int i = 0; i < mu.size(); ++i) {
    if (i == unit) continue;
    // Structural zeros: the contact manifold's normal direction and fully decayed components;
    // rounding leaves them at ~1e-16 times the monodromy's norm.
    if (std::abs(mu[i]) <= 1e-12 * std::max(1.0, st.monodromy.norm())) {
      ++st.structural_zeros;
      continue;
    }
    st.multipliers.push_back(mu[i]);
    st.stable = st.stable && std::abs(mu[i]) < 1.0;
  }
  std::sort(st.multipliers.begin(), st.multipliers.end(),
            [](auto a, auto b) { return std::abs(a) > std::abs(b); });
  return st;
}

std::vector<double> OrbitMeasures(const HybridModel& model, Propagator& propagator,
                                  const PeriodicOrbit& orbit, unsigned which) {
  const auto* closed = dynamic_cast<const ClosedFormFlow*>(&model);
  MeasureVector sum = MeasureVector::Zero(model.measure_names().size());
  double period = 0.0;
  for (size_t i = 0; i < orbit.durations.size(); ++i) {
    const int mode = orbit.signature.segments[i].mode;
    if (closed) {
      sum +=
          closed->MeasureIncrements(mode, orbit.starts[i], orbit.durations[i], orbit.params, which);
    } else {
      AdvanceRequest req;
      req.mode = mode, req.x0 = orbit.starts[i], req.t_max = orbit.durations[i];
      req.measures = true;
      sum += propagator.Advance(req, orbit.params).measures;
    }
    period += orbit.durations[i];
  }
  std::vector<double> means;
  for (int j = 0; j < sum.size(); ++j) means.push_back(sum[j] / period);
  return means;
}

namespace {

// Whether an event of segment i's own guard at time t is the segment's end at tau: within
// 1e-6 tau (a crossing cannot fall back through the surface in so short a time without touching it
// tangentially there), or within what the end's error in h makes of the event time there. That
// error, e, is rounding (1e-13 (1 + |x|)) plus the residual h(tau) the orbit was solved to (a
// corrector stopping at a scaled step of 1e-10 leaves |h(tau)| up to a few 1e-12). Where the
// guard crosses, the time is uncertain by e / |h'|, at most sqrt(2 e / |h''|) (a short segment
// ending at a shallow crossing: 1e-6 tau can be below it). At a tangent end's touch (h = h' = 0,
// h'' > 0) the quadratic h + h' s + h'' s^2 / 2 has its other root at most
// sqrt(2 e / h'') + 2 |h'| / h'' before the end: h stays within that error of zero for so long
// around it, and the locator can see a crossing anywhere there (with h'' = 2e-4, 1e-6 before
// tau, grazing curves ended at spurious double grazings at random places along them; with
// h'' = 0.065 and h(tau) = -4e-12 left by the corrector, 1.1e-5 before it, a grazing curve of
// the reference box ended at one). A real crossing that close to the end is itself a degenerate
// (cubic) tangency.
bool IsOwnEnd(const HybridModel& model, Propagator& propagator, const PeriodicOrbit& orbit,
              size_t i, double t) {
  const SegmentSpec& seg = orbit.signature.segments[i];
  const double tau = orbit.durations[i];
  if (tau - t <= 1e-6 * tau) return true;
  const StateVector end = propagator.FlowMap(seg.mode, orbit.starts[i], tau, orbit.params, {}).x;
  const GuardValue g = model.Guard(seg.mode, seg.guard, end, orbit.params);
  // The residual is taken up to the corrector's tolerance, 1e-10 (1 + |x|): an end further off
  // the surface is not a solved orbit's and its crossing is a crossing.
  const double scale = 1.0 + end.lpNorm<Eigen::Infinity>();
  const double e = 1e-13 * scale + std::min(std::abs(g.h), 1e-10 * scale);
  if (seg.tangent) {
    const double rate = std::min(std::abs(g.dh), 1e-10 * scale);
    return g.ddh > 0.0 && tau - t <= std::sqrt(2.0 * e / g.ddh) + 2.0 * rate / g.ddh;
  }
  const double window = std::min(e / std::abs(g.dh), std::sqrt(2.0 * e / std::abs(g.ddh)));
  return std::isfinite(window) && tau - t <= window;
}

// AdmissibilityViolations; with first_only, stops at the first violation (the segments are
// checked in order, so it is the first of the full list): CheckAdmissible needs no more, and the
// orbits it is asked about are often inadmissible (bisection midpoints past a grazing).
std::vector<Admissibility> Violations(const HybridModel& model, Propagator& propagator,
                                      const PeriodicOrbit& orbit, bool first_only) {
  std::vector<Admissibility> found;
  // Vanished segments first: they explain the guard crossings of their neighbours (past a
  // grazing point the fixed-signature branch re-crosses the surface inside the adjacent segments).
  for (size_t i = 0; i < orbit.durations.size(); ++i) {
    const double tau = orbit.durations[i];
    if (!(tau > 0.0)) {
      const int mode = orbit.signature.segments[i].mode;
      found.push_back({false, static_cast<int>(i), -1, false, 0.0,
                       "segment " + std::to_string(i) + " (" + std::string(model.mode_name(mode)) +
                           ") has duration " + std::to_string(tau) + " <= 0"});
    }
  }
  if (!found.empty()) return found;
  for (size_t i = 0; i < orbit.durations.size() && !(first_only && !found.empty()); ++i) {
    const SegmentSpec& seg = orbit.signature.segments[i];
    const double tau = orbit.durations[i];
    // No guard may fire before the segment's end. The terminating one fires at tau itself: an
    // event of it next to tau is the segment's own end (IsOwnEnd).
    AdvanceRequest req;
    req.mode = seg.mode, req.x0 = orbit.starts[i], req.t_max = tau;
    const AdvanceResult r = propagator.Advance(req, orbit.params);
    // (Only an event has a guard: a failed or cancelled advance ends with guard -1, as does the
    // segment ending at the section.)
    const bool own_end = r.end == AdvanceEnd::kEvent && r.guard == seg.guard &&
                         IsOwnEnd(model, propagator, orbit, i, r.duration);
    if (r.end == AdvanceEnd::kEvent && !own_end) {
      found.push_back({false, static_cast<int>(i), r.guard, r.duration == 0.0, r.duration,
                       "segment " + std::to_string(i) + " (" +
                           std::string(model.mode_name(seg.mode)) + ") crosses " +
                           model.guards(seg.mode)[r.guard].surface +
                           " at t = " + std::to_string(r.duration) + " of " + std::to_string(tau)});
    }
  }
  return found;
}

}  // namespace

std::vector<Admissibility> AdmissibilityViolations(const HybridModel& model, Propagator& propagator,
                                                   const PeriodicOrbit& orbit) {
  return Violations(model, propagator, orbit, false);
}

Admissibility CheckAdmissible(const HybridModel& model, Propagator& propagator,
                              const PeriodicOrbit& orbit) {
  const std::vector<Admissibility> v = Violations(model, propagator, orbit, true);
  return v.empty() ? Admissibility{} : v.front();
}

StatusOr<PeriodicOrbit> OrbitFromSimulation(const HybridModel& model, Propagator& propagator,
                                            const Params& params, const StateVector& x0,
                                            const GuessOptions& options,
                                            const ProgressCallback& progress) {
  internal::PhaseProgress phase(propagator, progress);
  SimulationOptions settle;
  settle.transient_periods = std::max(0, options.transient_periods - 1);
  settle.sample_periods = 1;
  settle.outputs = SimulationOutputs{false, false, false, false, 0.0};
  SimulationOptions look;
  look.transient_periods = 0;
  look.sample_periods = options.max_period;
  look.outputs = SimulationOutputs{false, true, true, false, 0.0};
  // Progress in proportion to the periods of the two runs.
  const double split =
      static_cast<double>(settle.transient_periods + 1) /
      static_cast<double>(settle.transient_periods + 1 + std::max<int64_t>(look.sample_periods, 0));
  const SimulationResult first =
      Simulate(model, propagator, params, x0, settle, phase.Sub(0.0, split));
  if (!first.summary.completed()) return first.summary.status;
  const SimulationResult r =
      Simulate(model, propagator, params, first.final_state, look, phase.Sub(split, 1.0));
  if (!r.summary.completed()) return r.summary.status;

  const StateVector& start = first.final_state;
  int n = 0;
  double closest = std::numeric_limits<double>::infinity();
  for (int k = 0; k < static_cast<int>(r.poincare.size()) && n == 0; ++k) {
    const double dist = (r.poincare[k].x - start).lpNorm<Eigen::Infinity>() /
                        (1.0 + start.lpNorm<Eigen::Infinity>());
    closest = std::min(closest, dist);
    if (dist <= options.return_tolerance) n = k + 1;
  }
  if (n == 0) {
    return Status(StatusCode::kFailedPrecondition,
                  "no periodic orbit of period <= " + std::to_string(options.max_period) +
                      " found after " + std::to_string(options.transient_periods) +
                      " transient periods (closest return: " + std::to_string(closest) +
                      " relative); the start is not near a periodic orbit, or the motion is "
                      "chaotic");
  }
  const int ps = model.phase_index();
  const double omega = model.ForcingFrequency(params);
  PeriodicOrbit orbit;
  orbit.params = params;
  orbit.signature.periods = n;
  int mode = first.final_mode;
  StateVector seg_start = start;
  double t0 = 0.0;
  for (const EventRecord& e : r.events) {
    if (e.period >= n) break;
    if (e.from_mode == e.to_mode) continue;  // a touch that changes nothing is no segment end
    orbit.signature.segments.push_back({mode, e.guard});
    orbit.starts.push_back(seg_start);
    orbit.durations.push_back(e.t - t0);
    seg_start = model.Jump(e.from_mode, e.guard, e.x, params).x;
    seg_start[ps] = omega * e.t;
    t0 = e.t;
    mode = e.to_mode;
  }
  orbit.signature.segments.push_back({mode, -1});
  orbit.starts.push_back(seg_start);
  orbit.durations.push_back(kTwoPi * n / omega - t0);
  return orbit;
}

}  // namespace drillbif
