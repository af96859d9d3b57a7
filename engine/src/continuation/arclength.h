// Pieces of pseudo-arclength continuation shared by the branch tracer (one parameter) and the
// curve tracer (two): the unit tangent of a solution curve and the step-length control.
#ifndef DRILLBIF_CONTINUATION_ARCLENGTH_H_
#define DRILLBIF_CONTINUATION_ARCLENGTH_H_

#include <Eigen/Dense>

namespace drillbif::internal {

// The unit tangent at a point of {F = 0}, F: R^n -> R^(n-1) with Jacobian `jac` there: the
// solution of [jac; prev^T] t = e_n, normalised and oriented along `prev`. False when that
// bordered matrix is singular (not a regular point, or prev orthogonal to the curve).
inline bool UnitTangent(const Eigen::MatrixXd& jac, const Eigen::VectorXd& prev,
                        Eigen::VectorXd* t) {
  const Eigen::Index n = prev.size();
  Eigen::MatrixXd a(n, n);
  a.topRows(n - 1) = jac;
  a.bottomRows(1) = prev.transpose();
  Eigen::VectorXd e = Eigen::VectorXd::Zero(n);
  e[n - 1] = 1.0;
  *t = a.partialPivLu().solve(e);
  if (!t->allFinite() || t->norm() == 0.0) return false;
  t->normalize();
  if (t->dot(prev) < 0.0) *t = -*t;
  return true;
}

// Factor for the next step length after a corrector that took `iterations` Newton iterations,
// aiming at `target`: longer when it took fewer, shorter when it took more than one extra.
inline double StepFactor(int iterations, int target) {
  return iterations <= target - 1 ? 1.6 : iterations > target + 1 ? 0.6 : 1.0;
}

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_ARCLENGTH_H_
