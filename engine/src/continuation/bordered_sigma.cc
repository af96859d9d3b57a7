#include "continuation/bordered_sigma.h"

namespace drillbif::internal {

Eigen::MatrixXd BialternateSquare(const Eigen::MatrixXd& m) {
  const int n = static_cast<int>(m.rows());
  const int size = n * (n - 1) / 2;
  Eigen::MatrixXd out(size, size);
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

Eigen::MatrixXd ShiftedMonodromy(CurveKind kind, const Eigen::MatrixXd& monodromy) {
  if (kind == CurveKind::kNeimarkSacker) {
    const Eigen::MatrixXd b = BialternateSquare(monodromy);
    return b - Eigen::MatrixXd::Identity(b.rows(), b.cols());
  }
  const double shift = kind == CurveKind::kFold ? -1.0 : 1.0;
  return monodromy + shift * Eigen::MatrixXd::Identity(monodromy.rows(), monodromy.cols());
}

BorderedSigma::BorderedSigma(const Eigen::MatrixXd& a) {
  Eigen::JacobiSVD<Eigen::MatrixXd> svd(a, Eigen::ComputeFullU | Eigen::ComputeFullV);
  b_ = svd.matrixU().col(a.rows() - 1);
  c_ = svd.matrixV().col(a.cols() - 1);
}

double BorderedSigma::operator()(const Eigen::MatrixXd& a) const {
  const int d = static_cast<int>(a.rows());
  Eigen::MatrixXd bordered = Eigen::MatrixXd::Zero(d + 1, d + 1);
  bordered.topLeftCorner(d, d) = a;
  bordered.topRightCorner(d, 1) = b_;
  bordered.bottomLeftCorner(1, d) = c_.transpose();
  Eigen::VectorXd rhs = Eigen::VectorXd::Zero(d + 1);
  rhs[d] = 1.0;
  return bordered.partialPivLu().solve(rhs)[d];
}

}  // namespace drillbif::internal
