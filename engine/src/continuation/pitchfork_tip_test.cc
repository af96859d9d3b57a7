// internal::PitchforkTip (period_doubling.h): where the period-2 omega-branch at a = 0.3 meets
// the period-1 orbit traversed twice. The reference is independent: the period-1 branch's own
// doubling, located by its multiplier test (Illinois on prod (mu + 1), the parameter bracketed to
// locate_tolerance); PitchforkTip solves the period-1 orbit's doubling condition (sigma of M + I)
// by Newton from the period-2 orbit's first pass, to a scaled step of 1e-12. The two agree to the
// bracket plus the solve: 2 x locate_tolerance.
#include <gtest/gtest.h>

#include <cmath>

#include "continuation/period_doubling.h"
#include "support/reference_orbit_test.h"
#include "support/special_point_near.h"

namespace drillbif::internal {
namespace {

using DO = DriftingOscillator;

class PitchforkTipTest : public testing::ReferenceOrbitTest {
 protected:
  // The period-1 omega-branch's doubling near `near`.
  SpecialPoint Doubling(double near) {
    ContinuationOptions branch;
    branch.param = "omega";
    branch.min = 0.05, branch.max = 2.0;
    const ContinuationResult r = Continue(model_, prop_, start_, branch);
    const SpecialPoint* pd =
        testing::SpecialPointNear(r, SpecialPointKind::kPeriodDoubling, near, 1e-3);
    if (!pd) ADD_FAILURE() << "no doubling near omega = " << near;
    return pd ? *pd : SpecialPoint{};
  }
};

TEST_F(PitchforkTipTest, IsThePeriodOneDoublingTraversedTwiceFromAnyOrbitNextToIt) {
  const SpecialPoint pd = Doubling(0.2698);
  ASSERT_EQ(pd.kind, SpecialPointKind::kPeriodDoubling);
  const StatusOr<PeriodicOrbit> next =
      SwitchAtPeriodDoublingAlgebraic(model_, prop_, pd.point.orbit, "omega");
  ASSERT_TRUE(next.ok()) << next.status().ToString();
  // From the switch's orbit, next to the turn, and from one six steps further along the branch.
  ContinuationOptions along;
  along.param = "omega";
  along.min = 0.05, along.max = 2.0;
  along.steps.max_steps = 6;
  along.direction = next->params[DO::kOmega] > pd.point.value ? ContinuationDirection::kIncreasing
                                                              : ContinuationDirection::kDecreasing;
  const ContinuationResult r = Continue(model_, prop_, *next, along);
  ASSERT_GE(r.points.size(), 2u);
  for (const PeriodicOrbit& near : {*next, r.points.back().orbit}) {
    SCOPED_TRACE("from omega = " + std::to_string(near.params[DO::kOmega]));
    EXPECT_FALSE(TraversedTwice(model_, prop_, near));
    const StatusOr<PeriodicOrbit> tip = PitchforkTip(model_, prop_, near, DO::kOmega);
    ASSERT_TRUE(tip.ok()) << tip.status().ToString();
    EXPECT_NEAR(tip->params[DO::kOmega], pd.point.value, 2.0 * along.locate_tolerance);
    EXPECT_TRUE(tip->signature == near.signature);
    EXPECT_TRUE(TraversedTwice(model_, prop_, *tip));
    EXPECT_TRUE(CheckAdmissible(model_, prop_, *tip).admissible);
  }
}

TEST_F(PitchforkTipTest, NeedsAnOrbitWhoseSignatureIsOneOfHalfThePeriodsDoubled) {
  const StatusOr<PeriodicOrbit> one = PitchforkTip(model_, prop_, start_, DO::kOmega);
  EXPECT_EQ(one.status().code(), StatusCode::kFailedPrecondition);
  // Two periods on start_'s signature of one pass (five segments): no pass repeated.
  PeriodicOrbit two = start_;
  two.signature.periods = 2;
  EXPECT_EQ(PitchforkTip(model_, prop_, two, DO::kOmega).status().code(),
            StatusCode::kFailedPrecondition);
}

}  // namespace
}  // namespace drillbif::internal
