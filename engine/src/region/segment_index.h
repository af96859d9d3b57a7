// Plane segments bucketed on a uniform grid, and the few geometric primitives the stability region,
// the robust optimum and the trace's duplicate test need (intersection, point-segment distance in
// the Euclidean and max norms). Internal to the engine.
#ifndef DRILLBIF_REGION_SEGMENT_INDEX_H_
#define DRILLBIF_REGION_SEGMENT_INDEX_H_

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <vector>

namespace drillbif::internal {

struct Segment {
  Eigen::Vector2d p, q;
  int tag = 0;   // the caller's label (a curve index)
  int part = 0;  // and a second one (the segment's index along that curve)
};

// Segments in the buckets of an nx x ny grid over [lo, hi]; a segment is stored in every bucket
// its bounding box overlaps (clamped to the grid), so a query visits each segment that can lie in
// the query box, some more than once.
class SegmentIndex {
 public:
  SegmentIndex(const Eigen::Vector2d& lo, const Eigen::Vector2d& hi, int nx, int ny)
      : lo_(lo), nx_(std::max(nx, 1)), ny_(std::max(ny, 1)), buckets_(nx_ * ny_) {
    cell_ = (hi - lo).cwiseQuotient(Eigen::Vector2d(nx_, ny_));
    for (int k = 0; k < 2; ++k) {
      if (!(cell_[k] > 0.0)) cell_[k] = 1.0;
    }
  }

  void Add(const Segment& s) {
    const int id = static_cast<int>(segments_.size());
    segments_.push_back(s);
    const Eigen::Vector2d a = s.p.cwiseMin(s.q), b = s.p.cwiseMax(s.q);
    for (int j = Cell(a[1], 1, ny_); j <= Cell(b[1], 1, ny_); ++j) {
      for (int i = Cell(a[0], 0, nx_); i <= Cell(b[0], 0, nx_); ++i) {
        buckets_[i + nx_ * j].push_back(id);
      }
    }
  }

  // Calls visit(segment) for the segments in the buckets that [a, b] overlaps.
  template <typename Visit>
  void ForEachNear(const Eigen::Vector2d& a, const Eigen::Vector2d& b, Visit&& visit) const {
    for (int j = Cell(a[1], 1, ny_); j <= Cell(b[1], 1, ny_); ++j) {
      for (int i = Cell(a[0], 0, nx_); i <= Cell(b[0], 0, nx_); ++i) {
        for (int id : buckets_[i + nx_ * j]) visit(segments_[id]);
      }
    }
  }

  const std::vector<Segment>& segments() const { return segments_; }

 private:
  int Cell(double x, int axis, int n) const {
    const double c = std::floor((x - lo_[axis]) / cell_[axis]);
    if (!(c >= 0.0)) return 0;  // also NaN
    return c >= n - 1 ? n - 1 : static_cast<int>(c);
  }

  Eigen::Vector2d lo_, cell_;
  int nx_, ny_;
  std::vector<std::vector<int>> buckets_;
  std::vector<Segment> segments_;
};

// Where segment a-b meets segment p-q: a + t (b - a) = p + u (q - p) with t, u in [0, 1].
// False when they do not meet or are parallel (collinear overlaps are not reported).
inline bool IntersectSegments(const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                              const Eigen::Vector2d& p, const Eigen::Vector2d& q, double* t,
                              double* u) {
  const Eigen::Vector2d r = b - a, s = q - p, w = p - a;
  const double den = r[0] * s[1] - r[1] * s[0];
  if (den == 0.0) return false;
  *t = (w[0] * s[1] - w[1] * s[0]) / den;
  *u = (w[0] * r[1] - w[1] * r[0]) / den;
  return *t >= 0.0 && *t <= 1.0 && *u >= 0.0 && *u <= 1.0;
}

// Euclidean distance from x to segment p-q.
inline double DistanceL2(const Eigen::Vector2d& x, const Eigen::Vector2d& p,
                         const Eigen::Vector2d& q) {
  const Eigen::Vector2d d = q - p;
  const double dd = d.squaredNorm();
  const double t = dd > 0.0 ? std::clamp((x - p).dot(d) / dd, 0.0, 1.0) : 0.0;
  return (p + t * d - x).norm();
}

// Max-norm distance from x to segment p-q: min over t in [0, 1] of max(|e0(t)|, |e1(t)|),
// e = p + t (q - p) - x. The function is convex and piecewise linear in t, so its minimum is at
// an end or a kink: where a component vanishes or the two components have equal magnitude.
inline double DistanceLinf(const Eigen::Vector2d& x, const Eigen::Vector2d& p,
                           const Eigen::Vector2d& q) {
  const Eigen::Vector2d e0 = p - x, d = q - p;
  auto f = [&](double t) {
    return std::max(std::abs(e0[0] + t * d[0]), std::abs(e0[1] + t * d[1]));
  };
  double best = std::min(f(0.0), f(1.0));
  auto consider = [&](double num, double den) {
    if (den == 0.0) return;
    const double t = num / den;
    if (t > 0.0 && t < 1.0) best = std::min(best, f(t));
  };
  consider(-e0[0], d[0]);                 // e_0(t) = 0
  consider(-e0[1], d[1]);                 // e_1(t) = 0
  consider(e0[1] - e0[0], d[0] - d[1]);   // e_0 = e_1
  consider(-e0[1] - e0[0], d[0] + d[1]);  // e_0 = -e_1
  return best;
}

}  // namespace drillbif::internal

#endif  // DRILLBIF_REGION_SEGMENT_INDEX_H_
