#include "continuation/corrector.h"

#include <cmath>

namespace drillbif::internal {

using Vec = Eigen::VectorXd;
using Mat = Eigen::MatrixXd;

PseudoArclengthCorrector::PseudoArclengthCorrector(const CorrectorSystem& system,
                                                   CondensedMode mode)
    : system_(system), lu_(0, 0, mode) {}

bool PseudoArclengthCorrector::Correct(const CorrectorOptions& options, const Vec& y_pred,
                                       const Vec& dir, Vec* y, int* iterations, Vec* tangent) {
  const Eigen::Index n = y_pred.size();
  *y = y_pred;
  steps_ = 0;
  Vec f;
  Mat a(n, n);
  // F's Jacobian straight into the bordered matrix's top rows (no copy per iteration).
  Eigen::Ref<Mat> jac(a.topRows(n - 1));
  Vec r(n);
  double last_norm = std::numeric_limits<double>::infinity();
  // The condition's residual must be small too, not only the step (condition_tolerance; why: the
  // curve tracer's Correct). Once the step has converged, the iterations go on while the residual
  // |condition| is above the tolerance and decreasing at least twofold; they end at the iterate
  // of smallest residual (at rounding's floor, or where an evaluation fails, the converged one).
  // *iterations is the iteration at which the step converged, which the step control sees.
  const bool settling = options.condition_tolerance < std::numeric_limits<double>::infinity();
  int converged_at = 0;
  double last_condition = std::numeric_limits<double>::infinity();
  Vec y_before;   // the iterate before the last step, of residual last_condition
  int after = 0;  // steps taken after the step converged
  auto settle = [&](bool keep_current) {
    if (!keep_current) *y = y_before;
    *iterations = converged_at;
    if (options.validate_result && !system_.Valid(*y)) return false;
    if (!tangent) return true;
    if (!Tangent(tangent)) return false;
    if (tangent->dot(dir) < 0.0) *tangent = -*tangent;
    return true;
  };
  for (int it = 1; it <= options.max_iterations; ++it) {
    if (system_.Stopped()) return false;
    // After convergence, chord steps: the residual alone (for a curve one monodromy, not one
    // per unknown) and the last factorization (the Jacobian moves by O(the step), ~1e-10).
    const bool chord = converged_at > 0;
    if (!system_.EvaluateInto(*y, &f, chord ? nullptr : &jac)) return chord && settle(after == 0);
    const double condition = std::abs(f[n - 2]);
    if (chord && (condition <= options.condition_tolerance || condition > 0.5 * last_condition)) {
      return settle(after == 0 || condition <= last_condition);
    }
    if (!chord) a.bottomRows(1) = dir.transpose();
    r.head(n - 1) = f;
    r[n - 1] = dir.dot(*y - y_pred);
    if (!chord) {
      // Right after a signature switch the system is ill-conditioned and the Newton steps can
      // stay at noise size without passing the step test: there a residual at rounding level
      // counts as converged. Not elsewhere: where the parameter is stationary (a located
      // grazing) a small residual does not pin it.
      if (options.accept_rounding_residual && it > 1 &&
          r.lpNorm<Eigen::Infinity>() <= 1e-13 * (1.0 + y->lpNorm<Eigen::Infinity>())) {
        converged_at = it;
        return settle(true);
      }
      lu_.Reshape(system_.Segments(), system_.Block());
      lu_.Compute(a);
      lu_rows_ = static_cast<int>(n);
    }
    const Vec step = lu_.Solve(-r);
    if (!step.allFinite()) return chord && settle(true);
    y_before = *y;
    *y += step;
    ++steps_;
    last_condition = condition;
    if (chord) {
      ++after;
      continue;
    }
    const double norm = step.lpNorm<Eigen::Infinity>();
    const double tol = options.tolerance * (1.0 + y->lpNorm<Eigen::Infinity>());
    // Converged: this step is below the tolerance, or (contraction_test) the contraction seen
    // (theta, the ratio of the last two steps; Newton's is quadratic, a differenced row makes it
    // at worst linear with a tiny rate) bounds what the steps still to come would add,
    // theta / (1 - theta) times this one, below it. The latter saves the confirming evaluation;
    // it is counted as taken, so that the step control sees the same iterations as without it.
    const double theta = norm / last_norm;
    if (norm <= tol || (options.contraction_test && it >= 2 && theta < 0.5 &&
                        theta / (1.0 - theta) * norm <= tol)) {
      converged_at = norm <= tol ? it : it + 1;
      // The residual before this step already below the tolerance: the one after it is too.
      if (!settling || condition <= options.condition_tolerance) return settle(true);
    }
    last_norm = norm;
  }
  return converged_at > 0 && settle(true);
}

bool PseudoArclengthCorrector::CorrectChord(const CorrectorOptions& options, const Vec& y_pred,
                                            const Vec& dir, Vec* y, int* iterations) {
  const Eigen::Index n = y_pred.size();
  if (lu_rows_ != n) return false;
  *y = y_pred;
  steps_ = 0;
  Vec f, r(n);
  double last_norm = std::numeric_limits<double>::infinity();
  for (int it = 1; it <= options.max_iterations; ++it) {
    if (system_.Stopped() || !system_.Evaluate(*y, &f, nullptr)) return false;
    r.head(n - 1) = f;
    r[n - 1] = dir.dot(*y - y_pred);
    const Vec step = lu_.Solve(-r);
    if (!step.allFinite()) return false;
    *y += step;
    ++steps_;
    const double norm = step.lpNorm<Eigen::Infinity>();
    const double theta = norm / last_norm;
    if (it >= 2 && !(theta < 0.5)) return false;
    const double tol = options.tolerance * (1.0 + y->lpNorm<Eigen::Infinity>());
    if (norm <= tol || (it >= 2 && theta / (1.0 - theta) * norm <= tol)) {
      *iterations = norm <= tol ? it : it + 1;
      return !options.validate_result || system_.Valid(*y);
    }
    last_norm = norm;
  }
  return false;
}

bool PseudoArclengthCorrector::Tangent(Vec* t) const {
  *t = lu_.Solve(Vec::Unit(lu_rows_, lu_rows_ - 1));
  if (!t->allFinite() || t->norm() == 0.0) return false;
  t->normalize();
  return true;
}

}  // namespace drillbif::internal
