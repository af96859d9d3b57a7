// The plane geometry under the stability region and the optimum, against brute force: distances
// against dense sampling of the segment, intersections against the points they claim, bucket
// queries against a scan of every segment.
#include "segment_index.h"

#include <gtest/gtest.h>

#include <random>

namespace drillbif::internal {
namespace {

Eigen::Vector2d RandomPoint(std::mt19937& rng) {
  std::uniform_real_distribution<double> u(-2.0, 2.0);
  return {u(rng), u(rng)};
}

// min over t of the distance to p + t (q - p), sampled at 20001 points: the sampled minimum is
// within half a sample spacing times |q - p| of the true one (the distance is 1-Lipschitz in the
// point along the segment).
template <typename Norm>
double SampledDistance(const Eigen::Vector2d& x, const Eigen::Vector2d& p, const Eigen::Vector2d& q,
                       Norm norm) {
  constexpr int kSamples = 20000;
  double best = 1e300;
  for (int k = 0; k <= kSamples; ++k) {
    best = std::min(best, norm(Eigen::Vector2d(p + (q - p) * (k / double(kSamples)) - x)));
  }
  return best;
}

TEST(SegmentGeometry, DistancesMatchDenseSampling) {
  std::mt19937 rng(7);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector2d x = RandomPoint(rng), p = RandomPoint(rng), q = RandomPoint(rng);
    const double tol = 0.5 * (q - p).norm() / 20000 + 1e-14;
    EXPECT_NEAR(DistanceL2(x, p, q),
                SampledDistance(x, p, q, [](const Eigen::Vector2d& e) { return e.norm(); }), tol);
    EXPECT_NEAR(DistanceLinf(x, p, q),
                SampledDistance(
                    x, p, q, [](const Eigen::Vector2d& e) { return e.lpNorm<Eigen::Infinity>(); }),
                tol);
    // The sampled minimum is an upper bound: the closed form may only be smaller.
    EXPECT_LE(DistanceLinf(x, p, q), SampledDistance(x, p, q, [](const Eigen::Vector2d& e) {
                                       return e.lpNorm<Eigen::Infinity>();
                                     }) + 1e-15);
  }
  // Degenerate segment (a point), axis-parallel and diagonal segments.
  EXPECT_DOUBLE_EQ(DistanceLinf({0, 0}, {3, 1}, {3, 1}), 3.0);
  EXPECT_DOUBLE_EQ(DistanceL2({0, 0}, {3, 4}, {3, 4}), 5.0);
  EXPECT_DOUBLE_EQ(DistanceLinf({0, 0}, {1, -5}, {1, 5}), 1.0);
  EXPECT_DOUBLE_EQ(DistanceLinf({0, 0}, {2, 0}, {0, 2}), 1.0);  // nearest at (1, 1)
}

TEST(SegmentGeometry, IntersectionsLieOnBothSegments) {
  std::mt19937 rng(11);
  int met = 0;
  for (int trial = 0; trial < 500; ++trial) {
    const Eigen::Vector2d a = RandomPoint(rng), b = RandomPoint(rng);
    const Eigen::Vector2d p = RandomPoint(rng), q = RandomPoint(rng);
    double t = -1.0, u = -1.0;
    if (!IntersectSegments(a, b, p, q, &t, &u)) {
      // Not meeting: the two segments' distance is positive (sampled along a-b).
      if (t >= 0 && t <= 1 && u >= 0 && u <= 1) ADD_FAILURE() << "rejected an intersection";
      continue;
    }
    ++met;
    EXPECT_LE((a + t * (b - a) - (p + u * (q - p))).norm(), 1e-12);
  }
  EXPECT_GT(met, 50);  // the trials did exercise crossings
  double t = 0, u = 0;
  EXPECT_FALSE(IntersectSegments({0, 0}, {1, 0}, {0, 1}, {1, 1}, &t, &u));  // parallel
  ASSERT_TRUE(IntersectSegments({0, 0}, {2, 2}, {0, 2}, {2, 0}, &t, &u));
  EXPECT_DOUBLE_EQ(t, 0.5);
  EXPECT_DOUBLE_EQ(u, 0.5);
}

TEST(SegmentIndex, QueryVisitsEverySegmentThatCanLieInTheBox) {
  std::mt19937 rng(3);
  SegmentIndex index({-2, -2}, {2, 2}, 16, 9);
  for (int k = 0; k < 300; ++k) {
    const Eigen::Vector2d p = RandomPoint(rng);
    const Eigen::Vector2d q = p + 0.3 * RandomPoint(rng);  // some leave the grid: clamped
    index.Add({p, q, k, 0});
  }
  for (int trial = 0; trial < 100; ++trial) {
    const Eigen::Vector2d c = RandomPoint(rng);
    const Eigen::Vector2d lo = c - Eigen::Vector2d(0.2, 0.1), hi = c + Eigen::Vector2d(0.2, 0.1);
    std::vector<char> seen(300, 0);
    index.ForEachNear(lo, hi, [&](const Segment& s) { seen[s.tag] = 1; });
    for (const Segment& s : index.segments()) {
      const Eigen::Vector2d a = s.p.cwiseMin(s.q), b = s.p.cwiseMax(s.q);
      const bool overlaps = (a.array() <= hi.array()).all() && (b.array() >= lo.array()).all();
      if (overlaps) {
        EXPECT_TRUE(seen[s.tag]) << "segment " << s.tag << " missed";
      }
    }
  }
}

}  // namespace
}  // namespace drillbif::internal
