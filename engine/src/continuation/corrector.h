// The pseudo-arclength corrector of one- and two-parameter continuation: Newton on
//   [F(y) = 0; dir . (y - y_pred) = 0],   F: R^n -> R^(n-1),
// from a prediction y_pred, the bordered matrix [F'(y); dir^T] factorized by internal::CondensedLu
// (condensed or dense). The branch tracer (F = the shooting system G(X, lambda)) and the curve
// tracer (F = G(X, lambda1, lambda2) and the curve's defining condition) both correct with it;
// their differences are options (CorrectorOptions).
//
// The orbit solver (SolveOrbit, orbit/periodic_orbit.cc) runs its own Newton loop: its system is
// square (G(X) = 0 at fixed parameters, no arclength row, so there is no `dir` to border with), it
// falls back to a rank-revealing QR of the whole system where the condensed solve is refused or
// not finite (not to the dense LU), it reports progress every iteration, and running out of
// iterations is a result (NO_CONVERGENCE, with the residual of the last iterate) rather than a
// failure. Folding those into this class would make each of them an option used by one caller.
#ifndef DRILLBIF_CONTINUATION_CORRECTOR_H_
#define DRILLBIF_CONTINUATION_CORRECTOR_H_

#include <Eigen/Dense>
#include <limits>

#include "orbit/condensed.h"

namespace drillbif::internal {

// What the corrector solves: F and its Jacobian, and the shape of the shooting system inside it
// (for CondensedLu).
class CorrectorSystem {
 public:
  virtual ~CorrectorSystem() = default;

  // F(y) (n - 1 values) into *f and, when `jac` is given, its Jacobian (n - 1 rows, n columns).
  // False where F cannot be evaluated at y (parameters out of the model's range, a flow that
  // fails, a value that is not finite where the system checks it).
  bool Evaluate(const Eigen::VectorXd& y, Eigen::VectorXd* f, Eigen::MatrixXd* jac) const {
    if (jac == nullptr) return EvaluateInto(y, f, nullptr);
    jac->resize(y.size() - 1, y.size());
    Eigen::Ref<Eigen::MatrixXd> block(*jac);
    return EvaluateInto(y, f, &block);
  }
  // As Evaluate, with the Jacobian written into *jac, n - 1 rows and n columns (the corrector's
  // bordered matrix but its last row), every entry.
  virtual bool EvaluateInto(const Eigen::VectorXd& y, Eigen::VectorXd* f,
                            Eigen::Ref<Eigen::MatrixXd>* jac) const = 0;
  // Whether a stop was requested: the corrector gives up at its next iteration.
  virtual bool Stopped() const = 0;
  // Whether a converged point is one the caller keeps (CorrectorOptions::validate_result).
  virtual bool Valid(const Eigen::VectorXd& /*y*/) const { return true; }
  // The shooting system's segments and rows per segment (CondensedLu::Reshape).
  virtual int Segments() const = 0;
  virtual int Block() const = 0;
};

// How a correction runs.
struct CorrectorOptions {
  int max_iterations = 8;    // Newton iterations before the correction fails
  double tolerance = 1e-11;  // converged when the step is below tolerance (1 + |y|_inf)
  // Also converged when the steps' contraction (the ratio theta of the last two) bounds what the
  // steps still to come would add, theta / (1 - theta) times this one, below the tolerance; the
  // iteration count then includes the confirming iteration so saved.
  bool contraction_test = false;
  // A residual [F; dir . (y - y_pred)] at rounding level (1e-13 (1 + |y|_inf)), from the second
  // iteration on, also counts as converged.
  bool accept_rounding_residual = false;
  // Once the step has converged: chord iterations (the residual alone, the last factorization)
  // while |F's last component| (a curve's condition) is above this and at least halving; the
  // result is the iterate of smallest such residual. Infinity: none.
  double condition_tolerance = std::numeric_limits<double>::infinity();
  bool validate_result = false;  // the result must pass CorrectorSystem::Valid
};

class PseudoArclengthCorrector {
 public:
  // `system` must outlive the corrector; `mode`: how CondensedLu factorizes.
  PseudoArclengthCorrector(const CorrectorSystem& system, CondensedMode mode);

  // Newton on (F = 0, dir . (y - y_pred) = 0) from y_pred into *y; *iterations: the iteration at
  // which it converged. `tangent`, when given, receives the unit tangent at the result oriented
  // along dir, from the last factorization (Tangent()). False when it does not converge within
  // options.max_iterations, an evaluation or a step fails, or a stop is seen.
  bool Correct(const CorrectorOptions& options, const Eigen::VectorXd& y_pred,
               const Eigen::VectorXd& dir, Eigen::VectorXd* y, int* iterations,
               Eigen::VectorXd* tangent = nullptr);

  // Chord Newton on (F = 0, dir . (y - y_pred) = 0) from y_pred into *y: the residual alone at
  // each iterate, solved with the last factorization, whose border row must be `dir` (an earlier
  // Correct's with that dir, at a point near y_pred). Its contraction is linear, at a rate of
  // about |y - y0| |F''| / |F'| from the factorization's point y0; converged by Correct's
  // contraction test. False (*y then unspecified) where there is no factorization of y_pred's
  // size, an evaluation or a step fails, a step does not contract at least twofold, the steps do
  // not converge within options.max_iterations, or a stop is seen. *iterations: as Correct's.
  bool CorrectChord(const CorrectorOptions& options, const Eigen::VectorXd& y_pred,
                    const Eigen::VectorXd& dir, Eigen::VectorXd* y, int* iterations);

  // The unit vector along the solution of the last factorization's system for e_n: [F'; dir^T]
  // at the iterate before the converged step, within the tolerance of the result, so the tangent
  // of internal::UnitTangent's system at no further evaluation, on dir's side. False where that
  // solution is not finite or zero.
  bool Tangent(Eigen::VectorXd* t) const;

  // The last factorization ([F'; dir^T] at the last full Newton iteration).
  const CondensedLu& lu() const { return lu_; }
  // Newton steps added to the iterate by the last Correct (chord steps included).
  int steps() const { return steps_; }

 private:
  const CorrectorSystem& system_;
  CondensedLu lu_;
  int lu_rows_ = 0;  // the size of the last factorized system
  int steps_ = 0;
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_CORRECTOR_H_
