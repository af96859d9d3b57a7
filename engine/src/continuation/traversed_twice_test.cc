// internal::TraversedTwice (trace_internal.h): on the period-2 omega-branch at a = 0.3
// (born at the period-1 doubling near omega = 0.2698, continued to the one near 1.6258), the
// fold located next to that second doubling is the period-1 orbit traversed twice, which
// TraceCurves must not trace as a period-2 fold curve; the branch's other folds are genuine.
// Checked independently of the predicate's own simulation: the doubled orbit's two passes,
// matched segment by segment in its boundary-value representation, coincide.
#include <gtest/gtest.h>

#include <cmath>

#include "support/reference_orbit_test.h"
#include "support/special_point_near.h"
#include "trace_internal.h"

namespace drillbif::internal {
namespace {

using DO = DriftingOscillator;
using TraversedTwiceTest = testing::ReferenceOrbitTest;

TEST_F(TraversedTwiceTest, TellsTheDoubledOrbitFromGenuinePeriodTwoFolds) {
  EXPECT_FALSE(TraversedTwice(model_, prop_, start_));  // period 1
  ContinuationOptions branch;
  branch.param = "omega";
  branch.min = 0.05, branch.max = 2.0;
  const ContinuationResult omega = Continue(model_, prop_, start_, branch);
  const SpecialPoint* pd =
      testing::SpecialPointNear(omega, SpecialPointKind::kPeriodDoubling, 0.2698, 1e-3);
  ASSERT_NE(pd, nullptr);
  const StatusOr<PeriodicOrbit> doubled =
      SwitchAtPeriodDoublingAlgebraic(model_, prop_, pd->point.orbit, "omega");
  ASSERT_TRUE(doubled.ok()) << doubled.status().ToString();
  ContinuationOptions two = branch;
  two.direction = doubled->params[DO::kOmega] > pd->point.value
                      ? ContinuationDirection::kIncreasing
                      : ContinuationDirection::kDecreasing;
  two.stop_at = {SpecialPointKind::kBranchPoint};
  const ContinuationResult r = Continue(model_, prop_, *doubled, two);
  int folds = 0, twice = 0;
  for (const SpecialPoint& s : r.special_points) {
    if (s.kind != SpecialPointKind::kFold) continue;
    ++folds;
    const PeriodicOrbit& o = s.point.orbit;
    ASSERT_EQ(o.signature.periods, 2);
    // The two passes of the period-2 orbit, matched segment by segment where its signature is
    // one pass repeated (k = 2p + 1 segments, the section inside segment 0 / 2p: segment i of
    // the first pass is segment p + i of the second; a pass of one event cannot start and end
    // in one mode, so p >= 2).
    const int k = static_cast<int>(o.starts.size());
    double split = 1e300;
    if (k % 2 == 1 && k >= 5) {
      const int p = (k - 1) / 2;
      split = 0.0;
      for (int i = 1; i < p; ++i) {
        if (!(o.signature.segments[i] == o.signature.segments[p + i])) split = 1e300;
        for (int j = 0; j < model_.state_dim() && split < 1e300; ++j) {
          if (j == model_.phase_index()) continue;
          split = std::max(split, std::abs(o.starts[i][j] - o.starts[p + i][j]));
        }
      }
    }
    const bool is_twice = TraversedTwice(model_, prop_, o);
    twice += is_twice;
    if (is_twice) {
      EXPECT_NEAR(s.point.value, 1.6258, 1e-3);
      EXPECT_LE(split, 1e-8) << "omega = " << s.point.value;
    } else {
      EXPECT_GT(split, 1e-2) << "omega = " << s.point.value;
    }
  }
  EXPECT_GE(folds, 4);
  EXPECT_EQ(twice, 1);
}

}  // namespace
}  // namespace drillbif::internal
