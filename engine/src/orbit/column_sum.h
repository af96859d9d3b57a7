// A sum of scaled columns, a(:, p0) x0 + a(:, p1) x1 + ..., summed the way Eigen's general
// product kernel sums a column of a product: each entry from +0, the terms added in the order
// given. Written by hand where a product over only some columns (those not known to be zero) must
// give the bits of Eigen's product over all of them (ProductOnColumns, CondensedLu).
#ifndef DRILLBIF_ORBIT_COLUMN_SUM_H_
#define DRILLBIF_ORBIT_COLUMN_SUM_H_

namespace drillbif::internal {

// N: the number of rows when known at compile time, so that the rows, innermost, are unrolled
// (0: given at run time, at most kMax).
template <int N, int kMax = N>
class ColumnSum {
 public:
  static_assert(N > 0 ? kMax == N : kMax > 0, "kMax is N, or the bound of a run-time N");
  explicit ColumnSum(int rows) : rows_(N > 0 ? N : rows) {}

  // += column * x (column: `rows` adjacent entries).
  void Add(const double* column, double x) {
    const int n = N > 0 ? N : rows_;
    for (int j = 0; j < n; ++j) acc_[j] = column[j] * x + acc_[j];
  }
  void StoreTo(double* out) const {
    const int n = N > 0 ? N : rows_;
    for (int j = 0; j < n; ++j) out[j] = acc_[j];
  }

 private:
  int rows_;
  double acc_[kMax] = {};
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_ORBIT_COLUMN_SUM_H_
