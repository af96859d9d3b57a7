// The defining condition of fold, period-doubling and Neimark-Sacker curves: sigma(A), the last
// component of the solution of the bordered system [[A, b], [c^T, 0]] (v, sigma) = (0, 1), with A
// the shifted monodromy (M - I, M + I, or M (.) M - I with the bialternate square) and b, c the
// singular vectors of A's smallest singular value at a reference point (Govaerts, "Numerical
// Methods for Bifurcations of Dynamical Equilibria", SIAM 2000). sigma is smooth near the
// reference point and vanishes exactly where A is singular; its zero set does not depend on the
// borders, which only have to keep the bordered matrix regular.
#ifndef DRILLBIF_CONTINUATION_BORDERED_SIGMA_H_
#define DRILLBIF_CONTINUATION_BORDERED_SIGMA_H_

#include <Eigen/Dense>

#include "drillbif/common/types.h"
#include "drillbif/continuation/curve.h"

namespace drillbif::internal {

// The shifted monodromy's largest size: the bialternate square of the reduced state's
// (kMaxStateDim - 1)-square monodromy. Fixed-capacity matrices keep sigma, evaluated once per
// unknown in every Jacobian of a curve's extended system, off the heap.
inline constexpr int kMaxShifted = (kMaxStateDim - 1) * (kMaxStateDim - 2) / 2;
using ShiftedMatrix = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor,
                                    kMaxShifted, kMaxShifted>;

// The bialternate square M (.) M: rows and columns indexed by pairs (p, q), p > q, entry
// det [[m_pr, m_ps], [m_qr, m_qs]] for column (r, s); its eigenvalues are mu_i mu_j, i < j
// (Govaerts 2000, sec. 4.4.4).
ShiftedMatrix BialternateSquare(const Eigen::Ref<const Eigen::MatrixXd>& m);

// M - I (fold), M + I (period doubling) or M (.) M - I (Neimark-Sacker); `kind` not kGrazing.
ShiftedMatrix ShiftedMonodromy(CurveKind kind, const Eigen::Ref<const Eigen::MatrixXd>& monodromy);

class BorderedSigma {
 public:
  BorderedSigma() = default;
  // Borders from the shifted monodromy `a` at the reference point.
  explicit BorderedSigma(const ShiftedMatrix& a);
  // sigma at `a`.
  double operator()(const ShiftedMatrix& a) const;
  // sigma at `a` (the same bits as operator()) and its gradient in a's entries,
  // *gradient(p, q) = d sigma / d a_pq = -w_p v_q: differentiating [[A, b], [c^T, 0]] (v, sigma) =
  // (0, 1) gives d sigma = -w^T (dA) v, with w from the transposed system
  // [[A^T, c], [b^T, 0]] (w, sigma) = (0, 1) (Govaerts 2000); one factorization serves
  // both solves.
  double WithGradient(const ShiftedMatrix& a, ShiftedMatrix* gradient) const;

 private:
  using Border = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxShifted, 1>;
  using Bordered = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor,
                                 kMaxShifted + 1, kMaxShifted + 1>;
  // [[a, b], [c^T, 0]].
  Bordered BorderedMatrix(const ShiftedMatrix& a) const;

  Border b_, c_;
};

// sigma of the shifted monodromy of `kind` (ShiftedMonodromy; not kGrazing) at `monodromy`, and
// into *gradient its derivative in the monodromy's entries, d sigma / d m_pq: for fold and period
// doubling BorderedSigma::WithGradient's (A = M -+ I), for Neimark-Sacker that one carried back
// through the bialternate square's entries, each bilinear in M.
double SigmaWithGradient(CurveKind kind, const BorderedSigma& sigma,
                         const Eigen::Ref<const Eigen::MatrixXd>& monodromy,
                         Eigen::MatrixXd* gradient);

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_BORDERED_SIGMA_H_
