// Branch switching at period doubling (see continuation/continuation.h).
#include <Eigen/Eigenvalues>
#include <cmath>

#include "drillbif/continuation/continuation.h"

namespace drillbif {

StatusOr<PeriodicOrbit> SwitchAtPeriodDoubling(const HybridModel& model, Propagator& propagator,
                                               const SpecialPoint& period_doubling,
                                               const std::string& param,
                                               const PeriodDoublingSwitchOptions& options) {
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
    GuessOptions guess;
    guess.transient_periods = options.transient_periods;
    guess.max_period = 2 * n;
    guess.return_tolerance = options.return_tolerance;
    StatusOr<PeriodicOrbit> found = OrbitFromSimulation(model, propagator, p, x0, guess);
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
    if (s.status == SolveStatus::kConverged) return doubled;
    tried += " " + param + " = " + std::to_string(p[*index]) + ": " + s.message + ";";
  }
  return Status(StatusCode::kFailedPrecondition,
                "no attracting period-" + std::to_string(2 * n) + " orbit next to the period " +
                    "doubling at " + param + " = " + std::to_string(period_doubling.point.value) +
                    " (a subcritical doubling?):" + tried);
}

}  // namespace drillbif
