// The Newton systems of multiple shooting (orbit/orbit_bvp.h), solved by condensing: the segment
// unknowns are eliminated block by block through the flows and saltations, and only a small
// system (the first start state, the durations that cannot be eliminated, the parameters and the
// border rows) is factorized. Shared by the orbit solver and the one- and two-parameter
// correctors.
#ifndef DRILLBIF_ORBIT_CONDENSED_H_
#define DRILLBIF_ORBIT_CONDENSED_H_

#include <Eigen/Dense>
#include <vector>

namespace drillbif::internal {

// How CondensedLu factorizes.
enum class CondensedMode {
  kAuto,       // condensed, dense where the structure or the growth bound rules condensing out
  kCondensed,  // condensed wherever the structure allows, whatever the growth (tests)
  kDense,      // always the dense PartialPivLU (the reference)
};

// An LU-like factorization of the bordered shooting matrix
//   a = [ G_X  G_p ]   G_X: the k (d + 1) square Jacobian of OrbitBvp::Evaluate (k segments),
//       [ C    D   ]   G_p: q parameter columns, [C D]: q border rows (condition, arclength), q >=
//       0.
// Segment i's block of rows (i < k - 1) is its event row, then d continuity rows equal to the next
// segment's start (an identity in those columns) minus the jump of its end; it involves no later
// unknown. Forward elimination expresses every unknown through the reduced unknowns xi (the
// parameters, the first start's d components, the last duration, and any duration whose event
// row cannot be solved for it: a tangent end, where the event row's own-duration entry grad h . f
// vanishes), leaving a square system of q + d + 1 + (kept durations) rows: the kept event rows,
// the last block's periodicity and phase rows, and the border rows. Its solution is that of the
// dense system up to rounding, amplified by how far the elimination grows: growth() is the largest
// row sum of |E|, where every unknown is E xi + e (for a periodic orbit, the largest norm of the
// partial products of the segments' saltation-flow matrices, i.e. of the monodromy's growth along
// the orbit). Above max_growth the dense factorization is used instead (docs/engine.md: where
// that switch happens in the reference box).
class CondensedLu {
 public:
  // Condensing loses up to ~growth * eps * cond(reduced system) to rounding, dense LU
  // ~cond(a) * eps; above this growth the dense factorization is used.
  static constexpr double kDefaultMaxGrowth = 1e6;

  // `segments` k >= 1 and `block` d + 1 (state dimension with the phase) of the shooting system.
  CondensedLu(int segments, int block, CondensedMode mode = CondensedMode::kAuto,
              double max_growth = kDefaultMaxGrowth);
  // Without a shape: dense until Reshape().
  CondensedLu() = default;

  // The shape of the systems the next Compute() calls factorize (a signature's).
  void Reshape(int segments, int block) {
    k_ = segments;
    n_ = block;
  }

  // Factorizes a (square, k (d + 1) + q rows). Returns condensed().
  bool Compute(const Eigen::MatrixXd& a);
  // The solution x of a x = b of the last Compute().
  Eigen::VectorXd Solve(const Eigen::VectorXd& b) const;
  // The sign of det(a): +1, -1, or 0 where a factor is exactly singular.
  double DeterminantSign() const;

  // Whether the last Compute() condensed (else it factorized densely).
  bool condensed() const { return condensed_; }
  // The elimination's growth measured by the last Compute() (0 where the structure ruled
  // condensing out before it was measured).
  double growth() const { return growth_; }
  // Size of the reduced system of the last condensed Compute().
  int reduced_size() const { return static_cast<int>(reduced_lu_.rows()); }

 private:
  // Forward elimination; false where the structure is not that of a shooting system.
  bool Condense(const Eigen::MatrixXd& a);

  int k_ = 0, n_ = 0;  // segments, rows and unknowns per segment (d + 1)
  CondensedMode mode_ = CondensedMode::kAuto;
  double max_growth_ = kDefaultMaxGrowth;
  bool condensed_ = false;
  double growth_ = 0.0;
  Eigen::MatrixXd a_;      // the factorized matrix (Solve's forward pass)
  Eigen::MatrixXd e_;      // unknowns = e_ xi + (right-hand side part), in the first
                           // reduced_size() columns
  Eigen::VectorXd pivot_;  // event row i's own-duration entry; 0: duration kept
  // Condense's workspace, kept between calls: the reduced matrix, a block's rows applied to the
  // unknowns expressed so far, the kept event rows and durations.
  Eigen::MatrixXd reduced_, known_;
  std::vector<int> kept_rows_, kept_cols_;
  Eigen::PartialPivLU<Eigen::MatrixXd> reduced_lu_;
  Eigen::PartialPivLU<Eigen::MatrixXd> dense_lu_;
  // det(a)'s sign but the permutations' (the eliminated pivots' and the reduced LU's), and the
  // permutations, whose signs are taken only when asked for (condensed).
  double sign_ = 0.0;
  std::vector<int> row_order_, col_order_;
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_ORBIT_CONDENSED_H_
