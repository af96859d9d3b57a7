#include "orbit/condensed.h"

#include <cmath>
#include <vector>

#include "orbit/column_sum.h"

namespace drillbif::internal {
namespace {

// An event row's own-duration entry below this fraction of the largest entry in its segment's
// columns is not divided by: the duration stays a reduced unknown. A tangent end's entry is zero
// to rounding (grad h . f = 0 there); a near-grazing one would make the saltation, and so the
// growth, large.
constexpr double kKeepDuration = 1e-2;

// Sign of the permutation taking position i to perm[i]: (-1)^(size - number of cycles).
double PermutationSign(const std::vector<int>& perm) {
  std::vector<bool> seen(perm.size(), false);
  int cycles = 0;
  for (size_t i = 0; i < perm.size(); ++i) {
    if (seen[i]) continue;
    ++cycles;
    for (size_t j = i; !seen[j]; j = static_cast<size_t>(perm[j])) seen[j] = true;
  }
  return (static_cast<int>(perm.size()) - cycles) % 2 == 0 ? 1.0 : -1.0;
}

double Sign(double v) { return v > 0.0 ? 1.0 : (v < 0.0 ? -1.0 : 0.0); }

// known's first r columns = inner block i's rows of `a` (n of them, rows of n unknowns per segment)
// times the unknowns' expressions e over the columns before the block's duration, where those
// rows are zero in the earlier starts' columns (a shooting system's: a segment's end moves with
// its own start and, through its phase, the earlier durations). Summed over the nonzero columns
// only, the earlier durations' then the own start's, each entry from +0 in the columns' order, as
// Eigen's product of the whole rows sums (ColumnSum): the zeros left out change no bit but a
// zero's sign.
// False (nothing written) where the rows are not zero there. N: n known at compile time (0: not,
// n <= kMaxBlock), so that the rows, innermost, are unrolled.
constexpr int kMaxBlock = 64;
template <int N>
bool ShootingBlockProduct(const Eigen::MatrixXd& a, const Eigen::MatrixXd& e, int n, int i, int r,
                          Eigen::MatrixXd* known) {
  if constexpr (N > 0) n = N;
  const int row = i * n, d = n - 1;
  for (int s = 0; s < i; ++s) {
    for (int p = s * n; p < s * n + d; ++p) {
      const double* q = &a(row, p);
      for (int j = 0; j < n; ++j) {
        if (q[j] != 0.0) return false;
      }
    }
  }
  for (int col = 0; col < r; ++col) {
    ColumnSum<N, (N > 0 ? N : kMaxBlock)> sum(n);
    for (int s = 0; s < i; ++s) sum.Add(&a(row, s * n + d), e(s * n + d, col));
    for (int p = i * n; p < i * n + d; ++p) sum.Add(&a(row, p), e(p, col));
    sum.StoreTo(&(*known)(0, col));
  }
  return true;
}

}  // namespace

CondensedLu::CondensedLu(int segments, int block, CondensedMode mode, double max_growth)
    : k_(segments), n_(block), mode_(mode), max_growth_(max_growth) {}

bool CondensedLu::Compute(const Eigen::MatrixXd& a) {
  condensed_ = false;
  growth_ = 0.0;
  if (mode_ != CondensedMode::kDense && Condense(a) &&
      (mode_ == CondensedMode::kCondensed || growth_ <= max_growth_)) {
    condensed_ = true;
    return true;
  }
  dense_lu_.compute(a);
  return false;
}

bool CondensedLu::Condense(const Eigen::MatrixXd& a) {
  const int size = static_cast<int>(a.rows()), m = k_ * n_, d = n_ - 1, q = size - m;
  if (k_ < 1 || n_ < 1 || q < 0 || a.cols() != size) return false;
  // Each inner block's rows in the next start's columns: zero in the event row, the identity in
  // the continuity rows (anything else is not a shooting system this elimination knows).
  for (int i = 0; i + 1 < k_; ++i) {
    const int row = i * n_, next = (i + 1) * n_;
    for (int j = 0; j < d; ++j) {
      if (a(row, next + j) != 0.0) return false;
      for (int r = 0; r < d; ++r) {
        if (a(row + 1 + r, next + j) != (r == j ? 1.0 : 0.0)) return false;
      }
    }
  }
  a_ = a;
  const int most = q + d + k_;  // reduced unknowns when every duration is kept
  // xi = (parameters, first start, kept durations in segment order, the last one last); e_'s
  // columns from xi's size on stay zero.
  e_.setZero(size, most);
  for (int j = 0; j < q; ++j) e_(m + j, j) = 1.0;
  for (int j = 0; j < d; ++j) e_(j, q + j) = 1.0;
  int r = q + d;
  pivot_.setZero(k_);
  Eigen::MatrixXd& reduced = reduced_;
  reduced.setZero(most, most);
  int rows = 0;
  // The permutations [eliminated rows / unknowns in elimination order, then the reduced ones in
  // xi's order] for det(a)'s sign: there a is [[M_w, M_xi], [N_w, N_xi]] with M_w block lower
  // triangular (diagonal blocks [[pivot, 0], [*, I]], or I where the duration is kept), and the
  // reduced matrix is the Schur complement N_xi - N_w M_w^-1 M_xi.
  std::vector<int>& row_order = row_order_;
  std::vector<int>& col_order = col_order_;
  std::vector<int>& kept_rows = kept_rows_;
  std::vector<int>& kept_cols = kept_cols_;
  row_order.clear();
  col_order.clear();
  kept_rows.clear();
  kept_cols.clear();
  double sign = 1.0;
  Eigen::MatrixXd& known = known_;
  known.resize(n_, most);
  for (int i = 0; i + 1 < k_; ++i) {
    const int row = i * n_, c = i * n_ + d;  // c: this segment's duration column
    // The block's rows applied to the unknowns already expressed in xi (columns before c, the
    // parameters).
    const bool sparse = n_ == 4
                            ? ShootingBlockProduct<4>(a, e_, n_, i, r, &known)
                            : n_ <= kMaxBlock && ShootingBlockProduct<0>(a, e_, n_, i, r, &known);
    if (!sparse) {
      known.leftCols(r).noalias() = a.block(row, 0, n_, c) * e_.topLeftCorner(c, r);
    }
    known.leftCols(q) += a.block(row, m, n_, q);
    const double pivot = a(row, c);
    const double scale = a.block(row, i * n_, 1, n_).cwiseAbs().maxCoeff();
    if (pivot != 0.0 && std::abs(pivot) > kKeepDuration * scale) {
      pivot_[i] = pivot;
      sign *= Sign(pivot);
      e_.row(c).head(r) = known.row(0).head(r) / -pivot;
      row_order.push_back(row);
      col_order.push_back(c);
    } else {
      known.col(r).setZero();
      e_(c, r) = 1.0;
      reduced.row(rows).head(r) = known.row(0).head(r);
      reduced(rows, r) = pivot;
      ++rows;
      ++r;
      kept_rows.push_back(row);
      kept_cols.push_back(c);
    }
    e_.block(c + 1, 0, d, r).noalias() =
        -known.block(1, 0, d, r) - a.block(row + 1, c, d, 1) * e_.row(c).head(r);
    for (int j = 1; j <= d; ++j) {
      row_order.push_back(row + j);
      col_order.push_back(c + j);
    }
  }
  // The last duration, then the last block's rows (periodicity, phase) and the border rows.
  const int last = (k_ - 1) * n_;
  e_(last + d, r) = 1.0;
  kept_cols.push_back(last + d);
  ++r;
  for (int j = 0; j < n_; ++j) kept_rows.push_back(last + j);
  for (int j = 0; j < q; ++j) kept_rows.push_back(m + j);
  reduced.block(rows, 0, n_ + q, r).noalias() =
      a.block(last, 0, n_ + q, m) * e_.topLeftCorner(m, r);
  reduced.block(rows, 0, n_ + q, q) += a.block(last, m, n_ + q, q);
  rows += n_ + q;
  if (rows != r) return false;
  growth_ = e_.topLeftCorner(m, r).cwiseAbs().rowwise().sum().maxCoeff();
  if (!std::isfinite(growth_) || !reduced.topLeftCorner(r, r).allFinite()) return false;
  reduced_lu_.compute(reduced.topLeftCorner(r, r));
  row_order.insert(row_order.end(), kept_rows.begin(), kept_rows.end());
  for (int j = 0; j < q; ++j) col_order.push_back(m + j);
  for (int j = 0; j < d; ++j) col_order.push_back(j);
  col_order.insert(col_order.end(), kept_cols.begin(), kept_cols.end());
  sign_ = sign * Sign(reduced_lu_.determinant());
  return true;
}

Eigen::VectorXd CondensedLu::Solve(const Eigen::VectorXd& b) const {
  if (!condensed_) return dense_lu_.solve(b);
  const int size = static_cast<int>(a_.rows()), m = k_ * n_, d = n_ - 1, q = size - m;
  const int r = static_cast<int>(reduced_lu_.rows());
  // The right-hand side's part of every unknown (xi's own entries stay 0), and the reduced rows'
  // right-hand side.
  Eigen::VectorXd v = Eigen::VectorXd::Zero(size), rhs(r);
  int rows = 0;
  Eigen::VectorXd t(n_);
  for (int i = 0; i + 1 < k_; ++i) {
    const int row = i * n_, c = i * n_ + d;
    t.noalias() = b.segment(row, n_) - a_.block(row, 0, n_, c) * v.head(c);
    if (pivot_[i] != 0.0) {
      v[c] = t[0] / pivot_[i];
    } else {
      rhs[rows++] = t[0];
    }
    v.segment(c + 1, d) = t.tail(d) - a_.block(row + 1, c, d, 1) * v[c];
  }
  const int last = (k_ - 1) * n_;
  rhs.segment(rows, n_ + q).noalias() =
      b.segment(last, n_ + q) - a_.block(last, 0, n_ + q, m) * v.head(m);
  const Eigen::VectorXd xi = reduced_lu_.solve(rhs);
  v.noalias() += e_.leftCols(r) * xi;
  return v;
}

double CondensedLu::DeterminantSign() const {
  if (!condensed_) return Sign(dense_lu_.determinant());
  return sign_ * PermutationSign(row_order_) * PermutationSign(col_order_);
}

}  // namespace drillbif::internal
