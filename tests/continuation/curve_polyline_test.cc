// A curve's polyline (its vertices) stays close to the curve in the parameter plane whatever the
// step length: where a long step's chord would stray, vertices are inserted within the step.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "drillbif/continuation/curve.h"
#include "support/reference_orbit_test.h"
#include "support/special_point_near.h"

namespace drillbif {
namespace {

// Distance, in the box's scaled coordinates, from p to the polyline's segments.
double DistanceToPolyline(const std::vector<CurvePoint>& line, const Eigen::Vector2d& p,
                          const Eigen::Vector2d& scale) {
  auto at = [&](size_t k) {
    return Eigen::Vector2d(line[k].value1 / scale[0], line[k].value2 / scale[1]);
  };
  double best = std::numeric_limits<double>::infinity();
  for (size_t k = 0; k + 1 < line.size(); ++k) {
    const Eigen::Vector2d a = at(k), d = at(k + 1) - a;
    const double s =
        d.squaredNorm() > 0.0 ? std::clamp((p - a).dot(d) / d.squaredNorm(), 0.0, 1.0) : 0.0;
    best = std::min(best, (p - a - s * d).norm());
  }
  return best;
}

// The l1 grazing curve of the omega-branch's grazing at omega = 0.5088 (a = 0.3) in the
// reference (omega, a) box, traced with long steps (target_iterations 4: steps grow until Newton
// needs 4 iterations) and densely (max_step 0.01, a tenth of the long steps' median): every dense
// vertex between the long trace's first and last vertex lies within 2e-5 of the long trace's
// polyline (box-scaled). The inserted vertices bound the chord's sagitta estimated from the
// cubic through the step's ends and tangents by 1e-5; the cubic is the curve to O(h^4), and the
// dense polyline's own chords stray by ~1e-8, so 2e-5 leaves the estimate a factor of 2. Without
// the inserted vertices (68 instead of 138) the long steps' chords stray up to 1.1e-4 here.
using CurvePolyline = testing::ReferenceOrbitTest;

TEST_F(CurvePolyline, LongStepsKeepTheirPolylineOnTheCurve) {
  ContinuationOptions branch;
  branch.param = std::string("omega");  // not ("omega"): GCC 12 -Wrestrict false positive
  branch.min = 0.05, branch.max = 2.0;
  const ContinuationResult omega = Continue(model_, prop_, start_, branch);
  const SpecialPoint* graze =
      testing::SpecialPointNear(omega, SpecialPointKind::kGrazingL1, 0.5088, 1e-3);
  ASSERT_NE(graze, nullptr);
  CurveOptions opt;
  opt.param1 = std::string("omega");
  opt.param2 = std::string("a");
  opt.min1 = 0.05, opt.max1 = 2.0, opt.min2 = 0.01, opt.max2 = 8.0;
  CurveOptions dense = opt;
  opt.steps.target_iterations = 4;
  dense.steps.max_step = 0.01;
  const CurveResult coarse = ContinueCurve(model_, prop_, *graze, opt);
  const CurveResult fine = ContinueCurve(model_, prop_, *graze, dense);
  ASSERT_EQ(coarse.summary.termination, Termination::kCompleted) << coarse.summary.message;
  ASSERT_EQ(fine.summary.termination, Termination::kCompleted) << fine.summary.message;
  ASSERT_GE(coarse.points.size(), 2u);
  const Eigen::Vector2d scale(opt.max1 - opt.min1, opt.max2 - opt.min2);
  // Only the stretch both traces cover: each ends its polyline at its last vertex before the
  // curve's ends, which lie a step beyond.
  const double lo = std::min(coarse.points.front().value1, coarse.points.back().value1);
  const double hi = std::max(coarse.points.front().value1, coarse.points.back().value1);
  double worst = 0.0;
  int compared = 0;
  for (const CurvePoint& p : fine.points) {
    if (p.value1 <= lo || p.value1 >= hi) continue;
    ++compared;
    worst = std::max(worst, DistanceToPolyline(
                                coarse.points,
                                Eigen::Vector2d(p.value1 / scale[0], p.value2 / scale[1]), scale));
  }
  RecordProperty("worst", std::to_string(worst));
  std::printf("%d dense vertices against %zu long-step vertices: farthest %.2g\n", compared,
              coarse.points.size(), worst);
  EXPECT_GE(compared, 100);
  EXPECT_LE(worst, 2e-5);
}

}  // namespace
}  // namespace drillbif
