// Branch switching at period doubling (see continuation/continuation.h), and orbits traversed
// twice told from period-2n ones (continuation/period_doubling.h).
#include "continuation/period_doubling.h"

#include <Eigen/Eigenvalues>
#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

#include "common/phase_progress.h"
#include "continuation/tangent_grazing.h"
#include "drillbif/continuation/continuation.h"
#include "drillbif/simulate/simulator.h"
#include "orbit/orbit_bvp.h"

namespace drillbif {

namespace {

// The orbit traversed twice, as an orbit of twice the period: the last segment of the first pass
// and the first of the second are one segment (the section is not an event). Linear in the
// starts and durations.
StatusOr<PeriodicOrbit> Doubled(const PeriodicOrbit& o) {
  const std::vector<SegmentSpec>& seg = o.signature.segments;
  const int k = static_cast<int>(seg.size());
  if (k < 2 || seg.front().mode != seg.back().mode) {
    return Status(StatusCode::kFailedPrecondition,
                  "the orbit has no event, or starts at one (its first and last segments are of "
                  "different modes): no doubled signature");
  }
  PeriodicOrbit d;
  d.params = o.params;
  d.signature.periods = 2 * o.signature.periods;
  auto push = [&](const SegmentSpec& spec, const StateVector& start, double duration) {
    d.signature.segments.push_back(spec);
    d.starts.push_back(start);
    d.durations.push_back(duration);
  };
  for (int i = 0; i + 1 < k; ++i) push(seg[i], o.starts[i], o.durations[i]);
  push(seg.front(), o.starts[k - 1], o.durations[k - 1] + o.durations[0]);
  for (int i = 1; i < k; ++i) push(seg[i], o.starts[i], o.durations[i]);
  return d;
}

// The first pass of an orbit whose signature is Doubled's of one of half the periods: the inverse
// of Doubled where the two passes agree (the half-period orbit's last segment is the second
// pass's last, since the first pass's runs on into the next period).
StatusOr<PeriodicOrbit> FirstPass(const PeriodicOrbit& d) {
  const std::vector<SegmentSpec>& seg = d.signature.segments;
  const int total = static_cast<int>(seg.size()), k = (total + 1) / 2;
  bool doubled = d.signature.periods % 2 == 0 && total % 2 == 1 && k >= 2 && seg[k - 1] == seg[0] &&
                 seg[total - 1].mode == seg[0].mode;
  for (int i = 1; doubled && i + 1 < k; ++i) doubled = seg[k - 1 + i] == seg[i];
  if (!doubled) {
    return Status(StatusCode::kFailedPrecondition,
                  "the orbit's signature is no signature of half as many periods doubled");
  }
  PeriodicOrbit h;
  h.params = d.params;
  h.signature.periods = d.signature.periods / 2;
  for (int i = 0; i < k; ++i) {
    const int from = i + 1 < k ? i : total - 1;
    h.signature.segments.push_back(seg[from]);
    h.starts.push_back(d.starts[i]);
    h.durations.push_back(d.durations[from]);
  }
  return h;
}

// The unit null vector of the m x (m + 1) matrix [gx gp] (the branch's tangent), from the SVD.
Eigen::MatrixXd NullBasis(const Eigen::MatrixXd& gx, const Eigen::VectorXd& gp, int dim) {
  Eigen::MatrixXd j(gx.rows(), gx.cols() + 1);
  j << gx, gp;
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(j, Eigen::ComputeFullV);
  return svd.matrixV().rightCols(dim);
}

}  // namespace

StatusOr<PeriodicOrbit> SwitchAtPeriodDoubling(const HybridModel& model, Propagator& propagator,
                                               const SpecialPoint& period_doubling,
                                               const std::string& param,
                                               const PeriodDoublingSwitchOptions& options,
                                               const ProgressCallback& progress) {
  internal::PhaseProgress phase(propagator, progress);
  if (period_doubling.kind != SpecialPointKind::kPeriodDoubling) {
    return InvalidArgument("branch switching needs a PERIOD_DOUBLING point, got " +
                           std::string(SpecialPointKindName(period_doubling.kind)));
  }
  StatusOr<int> index = model.ParamIndex(param);
  if (!index.ok()) return Status(StatusCode::kInvalidArgument, index.status().message());
  const PeriodicOrbit& orbit = period_doubling.point.orbit;
  const int n = orbit.signature.periods;
  // The eigenvector of the multiplier closest to -1, on the state without its phase.
  Eigen::EigenSolver<Eigen::MatrixXd> eig(period_doubling.point.stability.monodromy);
  int best = 0;
  for (int i = 1; i < eig.eigenvalues().size(); ++i) {
    if (std::abs(eig.eigenvalues()[i] + 1.0) < std::abs(eig.eigenvalues()[best] + 1.0)) best = i;
  }
  const Eigen::VectorXd v = eig.eigenvectors().col(best).real().normalized();
  const int ps = model.phase_index();
  StateVector x0 = orbit.starts[0];
  const double scale = 1.0 + x0.lpNorm<Eigen::Infinity>();
  for (int i = 0, r = 0; i < x0.size(); ++i) {
    if (i != ps) x0[i] += options.perturbation * scale * v[r++];
  }
  // The kicked state may leave the invariant set (q < 0 at q = 0): pull it back inside.
  if (!model.ValidateState(x0, orbit.params, 0.0).ok()) {
    for (int i = 0, r = 0; i < x0.size(); ++i) {
      if (i != ps) x0[i] -= 2.0 * options.perturbation * scale * v[r++];
    }
  }
  std::string tried;
  for (double side : {-1.0, 1.0}) {
    Params p = orbit.params;
    p[*index] += side * options.offset;
    if (!model.ValidateParams(p).ok()) continue;
    // Each side's simulation is most of the work: half of the fraction each.
    const double from = side < 0.0 ? 0.0 : 0.5;
    GuessOptions guess;
    guess.transient_periods = options.transient_periods;
    guess.max_period = 2 * n;
    guess.return_tolerance = options.return_tolerance;
    StatusOr<PeriodicOrbit> found =
        OrbitFromSimulation(model, propagator, p, x0, guess, phase.Sub(from, from + 0.5));
    if (phase.stopped()) return Cancelled("period-doubling switch cancelled");
    if (!found.ok()) {
      tried += " " + param + " = " + std::to_string(p[*index]) + ": " + found.status().message();
      continue;
    }
    if (found->signature.periods != 2 * n) {
      tried += " " + param + " = " + std::to_string(p[*index]) + ": the simulation settled on " +
               "period " + std::to_string(found->signature.periods) + ";";
      continue;
    }
    PeriodicOrbit doubled = *found;
    const OrbitSolveSummary s = SolveOrbit(model, propagator, {}, &doubled);
    if (phase.stopped()) return Cancelled("period-doubling switch cancelled");
    if (!s.completed()) {
      tried += " " + param + " = " + std::to_string(p[*index]) + ": " + s.message + ";";
      continue;
    }
    // On the side where the period-n orbit attracts, its multiplier next to -1 makes the transient
    // decay slowly, and a simulation still alternating returns after 2n periods first: Newton then
    // lands on the period-n orbit traversed twice.
    if (internal::TraversedTwice(model, propagator, doubled)) {
      tried += " " + param + " = " + std::to_string(p[*index]) + ": the simulation settled on " +
               "the period-" + std::to_string(n) + " orbit traversed twice;";
      continue;
    }
    return doubled;
  }
  return Status(StatusCode::kFailedPrecondition,
                "no attracting period-" + std::to_string(2 * n) + " orbit next to the period " +
                    "doubling at " + param + " = " + std::to_string(period_doubling.point.value) +
                    " (a subcritical doubling?):" + tried);
}

StatusOr<PeriodicOrbit> SwitchAtPeriodDoublingAlgebraic(const HybridModel& model,
                                                        Propagator& propagator,
                                                        const PeriodicOrbit& orbit,
                                                        const std::string& param, double step,
                                                        const ProgressCallback& progress) {
  using Vec = Eigen::VectorXd;
  internal::PhaseProgress phase(propagator, progress);
  const Status cancelled = Cancelled("period-doubling switch cancelled");
  StatusOr<int> index = model.ParamIndex(param);
  if (!index.ok()) return Status(StatusCode::kInvalidArgument, index.status().message());
  if (!(step > 0.0 && std::isfinite(step))) {
    return InvalidArgument("step: need a finite value > 0");
  }
  StatusOr<PeriodicOrbit> doubled = Doubled(orbit);
  if (!doubled.ok()) return doubled.status();
  internal::OrbitBvp bvp1(model, propagator, orbit.signature, *index);
  internal::OrbitBvp bvp2(model, propagator, doubled->signature, *index);
  const int m1 = bvp1.size(), m = bvp2.size();
  Vec g, gp;
  Eigen::MatrixXd gx;
  // The period-n branch's tangent, mapped into the doubled unknowns (the doubling is linear).
  const Vec x1 = bvp1.Pack(orbit);
  if (Status s = bvp1.Evaluate(x1, orbit.params, &g, &gx, &gp); !s.ok()) {
    return phase.stopped() ? cancelled : s;
  }
  const Vec t1 = NullBasis(gx, gp, 1).col(0);
  PeriodicOrbit moved;
  bvp1.Unpack(x1 + t1.head(m1), orbit.params, &moved);
  StatusOr<PeriodicOrbit> moved2 = Doubled(moved);
  if (!moved2.ok()) return moved2.status();
  const Vec x2 = bvp2.Pack(*doubled);
  Vec t_sym(m + 1);
  t_sym << bvp2.Pack(*moved2) - x2, t1[m1];
  // The doubled system's two-dimensional null space; the new branch leaves orthogonally to the
  // doubled one within it.
  if (Status s = bvp2.Evaluate(x2, orbit.params, &g, &gx, &gp); !s.ok()) {
    return phase.stopped() ? cancelled : s;
  }
  const Eigen::MatrixXd basis = NullBasis(gx, gp, 2);
  const Eigen::Vector2d c = basis.transpose() * t_sym;
  const Vec t = basis * Eigen::Vector2d(-c[1], c[0]).normalized();

  Vec y0(m + 1);
  y0 << x2, orbit.params[*index];
  const double scale = 1.0 + y0.lpNorm<Eigen::Infinity>();
  const int k = static_cast<int>(orbit.signature.segments.size()), n = model.state_dim();
  std::string tried;
  for (double h = step * scale; h >= step * scale * 1e-4; h /= 4.0) {
    for (double side : {1.0, -1.0}) {
      if (!phase.Continue()) return cancelled;
      const Vec y_pred = y0 + side * h * t;
      Vec y = y_pred;
      Params p = orbit.params;
      bool converged = false;
      for (int it = 0; it < 20 && !converged; ++it) {
        p[*index] = y[m];
        if (!model.ValidateParams(p).ok()) break;
        if (!bvp2.Evaluate(y.head(m), p, &g, &gx, &gp).ok()) break;
        Eigen::MatrixXd jac(m + 1, m + 1);
        jac << gx, gp, t.transpose();
        Vec f(m + 1);
        f << g, t.dot(y - y_pred);
        const Vec dy = jac.partialPivLu().solve(-f);
        if (!dy.allFinite()) break;
        y += dy;
        converged = dy.lpNorm<Eigen::Infinity>() <= 1e-11 * scale;
      }
      if (!converged) {
        tried = "Newton did not converge";
        continue;
      }
      p[*index] = y[m];
      PeriodicOrbit result;
      bvp2.Unpack(y.head(m), p, &result);
      // A genuine period-2n orbit: its two passes differ at the matching segment starts
      // (segment i of the first pass is segment k - 1 + i of the second, i = 1 .. k - 1).
      double split = 0.0;
      for (int i = 1; i < k; ++i) {
        for (int j = 0; j < n; ++j) {
          if (j == model.phase_index()) continue;
          split = std::max(split, std::abs(result.starts[i][j] - result.starts[k - 1 + i][j]));
        }
      }
      if (split <= 1e-3 * h) {
        tried = "the corrector returned to the doubled orbit";
        continue;
      }
      const Admissibility adm = CheckAdmissible(model, propagator, result);
      if (phase.stopped()) return cancelled;
      if (!adm.admissible) {
        tried = "not admissible: " + adm.message;
        continue;
      }
      return result;
    }
  }
  return Status(StatusCode::kFailedPrecondition,
                "no period-" + std::to_string(2 * orbit.signature.periods) +
                    " orbit found next to the doubling at " + param + " = " +
                    std::to_string(orbit.params[*index]) + ": " + tried);
}

}  // namespace drillbif

namespace drillbif::internal {

double DistanceWithoutPhase(const HybridModel& model, const StateVector& x, const StateVector& y) {
  double sum = 0.0;
  for (int i = 0; i < model.state_dim(); ++i) {
    if (i != model.phase_index()) sum += (x[i] - y[i]) * (x[i] - y[i]);
  }
  return std::sqrt(sum);
}

bool TraversedTwice(const HybridModel& model, Propagator& propagator, const PeriodicOrbit& o) {
  if (o.signature.periods % 2 != 0) return false;
  SimulationOptions half;
  half.transient_periods = 0;
  half.sample_periods = o.signature.periods / 2;
  half.outputs = SimulationOutputs{false, true, false, false, 0.0};
  const SimulationResult s = Simulate(model, propagator, o.params, o.starts[0], half);
  if (!s.summary.completed() || s.poincare.size() != static_cast<size_t>(half.sample_periods)) {
    return false;
  }
  double size = 0.0;
  for (int i = 0; i < model.state_dim(); ++i) {
    if (i != model.phase_index()) size = std::max(size, std::abs(o.starts[0][i]));
  }
  return DistanceWithoutPhase(model, s.poincare.back().x, o.starts[0]) <= 1e-6 * (1.0 + size);
}

StatusOr<PeriodicOrbit> PitchforkTip(const HybridModel& model, Propagator& propagator,
                                     const PeriodicOrbit& near, int param) {
  StatusOr<PeriodicOrbit> half = FirstPass(near);
  if (!half.ok()) return half.status();
  const ExtraCondition doubling =
      ExtraCondition::Sigma(model, propagator, *half, CurveKind::kPeriodDoubling);
  StatusOr<PeriodicOrbit> at =
      SolveWithConditions(model, propagator, *half, {param}, {doubling}, 1e-12,
                          "the period doubling of the orbit of " +
                              std::to_string(half->signature.periods) + " periods");
  if (!at.ok()) return at.status();
  StatusOr<PeriodicOrbit> tip = Doubled(*at);
  if (tip.ok() && !(tip->signature == near.signature)) {
    return Status(StatusCode::kFailedPrecondition,
                  "the doubling's orbit traversed twice has another signature than the branch's");
  }
  return tip;
}

}  // namespace drillbif::internal
