#include "continuation/bordered_sigma.h"

namespace drillbif::internal {

ShiftedMatrix BialternateSquare(const Eigen::Ref<const Eigen::MatrixXd>& m) {
  const int n = static_cast<int>(m.rows());
  const int size = n * (n - 1) / 2;
  ShiftedMatrix out(size, size);
  int row = 0;
  for (int p = 1; p < n; ++p) {
    for (int q = 0; q < p; ++q, ++row) {
      int col = 0;
      for (int r = 1; r < n; ++r) {
        for (int s = 0; s < r; ++s, ++col) {
          out(row, col) = m(p, r) * m(q, s) - m(p, s) * m(q, r);
        }
      }
    }
  }
  return out;
}

ShiftedMatrix ShiftedMonodromy(CurveKind kind, const Eigen::Ref<const Eigen::MatrixXd>& monodromy) {
  ShiftedMatrix a =
      kind == CurveKind::kNeimarkSacker ? BialternateSquare(monodromy) : ShiftedMatrix(monodromy);
  a.diagonal().array() += kind == CurveKind::kPeriodDoubling ? 1.0 : -1.0;
  return a;
}

BorderedSigma::BorderedSigma(const ShiftedMatrix& a) {
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(a, Eigen::ComputeFullU | Eigen::ComputeFullV);
  b_ = svd.matrixU().col(a.rows() - 1);
  c_ = svd.matrixV().col(a.cols() - 1);
}

double BorderedSigma::operator()(const ShiftedMatrix& a) const {
  using Bordered = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::ColMajor,
                                 kMaxShifted + 1, kMaxShifted + 1>;
  using Rhs = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxShifted + 1, 1>;
  const int d = static_cast<int>(a.rows());
  Bordered bordered = Bordered::Zero(d + 1, d + 1);
  bordered.topLeftCorner(d, d) = a;
  bordered.topRightCorner(d, 1) = b_;
  bordered.bottomLeftCorner(1, d) = c_.transpose();
  Rhs rhs = Rhs::Zero(d + 1);
  rhs[d] = 1.0;
  return Eigen::PartialPivLU<Bordered>(bordered).solve(rhs)[d];
}

}  // namespace drillbif::internal
