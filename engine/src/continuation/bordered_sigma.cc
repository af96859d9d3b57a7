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

BorderedSigma::Bordered BorderedSigma::BorderedMatrix(const ShiftedMatrix& a) const {
  const int d = static_cast<int>(a.rows());
  Bordered bordered = Bordered::Zero(d + 1, d + 1);
  bordered.topLeftCorner(d, d) = a;
  bordered.topRightCorner(d, 1) = b_;
  bordered.bottomLeftCorner(1, d) = c_.transpose();
  return bordered;
}

namespace {

using Rhs = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxShifted + 1, 1>;

// (0, ..., 0, 1), of size d + 1.
Rhs LastUnit(int d) {
  Rhs rhs = Rhs::Zero(d + 1);
  rhs[d] = 1.0;
  return rhs;
}

}  // namespace

double BorderedSigma::operator()(const ShiftedMatrix& a) const {
  const int d = static_cast<int>(a.rows());
  return Eigen::PartialPivLU<Bordered>(BorderedMatrix(a)).solve(LastUnit(d))[d];
}

double BorderedSigma::WithGradient(const ShiftedMatrix& a, ShiftedMatrix* gradient) const {
  const int d = static_cast<int>(a.rows());
  const Eigen::PartialPivLU<Bordered> lu(BorderedMatrix(a));
  const Rhs rhs = LastUnit(d);
  const Rhs v = lu.solve(rhs);              // (v, sigma)
  const Rhs w = lu.transpose().solve(rhs);  // (w, sigma)
  *gradient = -w.head(d) * v.head(d).transpose();
  return v[d];
}

double SigmaWithGradient(CurveKind kind, const BorderedSigma& sigma,
                         const Eigen::Ref<const Eigen::MatrixXd>& monodromy,
                         Eigen::MatrixXd* gradient) {
  ShiftedMatrix of_a;
  const double value = sigma.WithGradient(ShiftedMonodromy(kind, monodromy), &of_a);
  if (kind != CurveKind::kNeimarkSacker) {
    *gradient = of_a;
    return value;
  }
  // Entry (pq, rs) of M (.) M is m_pr m_qs - m_ps m_qr (BialternateSquare's order of the pairs):
  // its change is dm_pr m_qs + m_pr dm_qs - dm_ps m_qr - m_ps dm_qr, so d sigma / d a_(pq, rs)
  // goes to those four entries of M with those weights.
  const int n = static_cast<int>(monodromy.rows());
  const auto& m = monodromy;
  gradient->setZero(n, n);
  int row = 0;
  for (int p = 1; p < n; ++p) {
    for (int q = 0; q < p; ++q, ++row) {
      int col = 0;
      for (int r = 1; r < n; ++r) {
        for (int s = 0; s < r; ++s, ++col) {
          const double g = of_a(row, col);
          (*gradient)(p, r) += g * m(q, s);
          (*gradient)(q, s) += g * m(p, r);
          (*gradient)(p, s) -= g * m(q, r);
          (*gradient)(q, r) -= g * m(p, s);
        }
      }
    }
  }
  return value;
}

}  // namespace drillbif::internal
