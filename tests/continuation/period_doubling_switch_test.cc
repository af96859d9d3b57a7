// Branch switching at period doubling: the period-2 orbit born at the reference branch's PD point
// (b = 0.11001173, MODEL.md) is found, solved, and agrees with direct simulation.
#include <gtest/gtest.h>

#include <cmath>

#include "drillbif/continuation/continuation.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

TEST(PeriodDoublingSwitch, FindsTheAttractingPeriodTwoOrbitBornAtTheDoubling) {
  DO model;
  ExactPropagator prop(model);
  const StatusOr<PeriodicOrbit> found =
      testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  const PeriodicOrbit& start = *found;
  ContinuationOptions opt;
  opt.param = "b";
  opt.min = 0.05;
  opt.max = 0.2;
  opt.direction = ContinuationDirection::kDecreasing;
  opt.stop_at = {SpecialPointKind::kPeriodDoubling};
  const ContinuationResult r = Continue(model, prop, start, opt);
  ASSERT_FALSE(r.special_points.empty());
  const SpecialPoint& pd = r.special_points.back();
  ASSERT_EQ(pd.kind, SpecialPointKind::kPeriodDoubling);
  EXPECT_NEAR(pd.point.value, 0.11001173, 1e-6 * 0.11001173);

  const StatusOr<PeriodicOrbit> doubled = SwitchAtPeriodDoubling(model, prop, pd, "b");
  ASSERT_TRUE(doubled.ok()) << doubled.status().ToString();
  EXPECT_EQ(doubled->signature.periods, 2);
  EXPECT_TRUE(CheckAdmissible(model, prop, *doubled).admissible);
  const Stability st = OrbitStability(model, prop, *doubled);
  EXPECT_TRUE(st.stable);

  // Direct simulation from the orbit's section state: it returns after two periods, not after
  // one (the halves differ by ~sqrt(offset) = 3e-2 relative, far above the 1e-9 return).
  SimulationOptions two;
  two.transient_periods = 0;
  two.sample_periods = 2;
  two.outputs = SimulationOutputs{false, true, false, false, 0.0};
  const SimulationResult s = Simulate(model, prop, doubled->params, doubled->starts[0], two);
  ASSERT_EQ(s.poincare.size(), 2u);
  const StateVector& x0 = doubled->starts[0];
  EXPECT_LT((s.poincare[1].x - x0).head(3).norm(), 1e-9 * (1 + x0.norm()));
  EXPECT_GT((s.poincare[0].x - x0).head(3).norm(), 1e-3);
}

// Continued towards the doubling, the period-2 branch meets the (doubled) period-1 branch there:
// in the period-2 boundary-value system that is a branch point, located at the PD value.
TEST(PeriodDoublingSwitch, PeriodTwoBranchHasABranchPointAtTheDoubling) {
  DO model;
  ExactPropagator prop(model);
  const StatusOr<PeriodicOrbit> found =
      testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  ASSERT_TRUE(found.ok());
  ContinuationOptions opt;
  opt.param = "b";
  opt.min = 0.05;
  opt.max = 0.2;
  opt.direction = ContinuationDirection::kDecreasing;
  opt.stop_at = {SpecialPointKind::kPeriodDoubling};
  const ContinuationResult r = Continue(model, prop, *found, opt);
  ASSERT_FALSE(r.special_points.empty());
  const SpecialPoint& pd = r.special_points.back();
  const StatusOr<PeriodicOrbit> doubled = SwitchAtPeriodDoubling(model, prop, pd, "b");
  ASSERT_TRUE(doubled.ok()) << doubled.status().ToString();
  ContinuationOptions up;
  up.param = "b";
  up.min = 0.1;
  up.max = 0.12;
  up.direction = ContinuationDirection::kIncreasing;
  up.stop_at = {SpecialPointKind::kBranchPoint};
  const ContinuationResult r2 = Continue(model, prop, *doubled, up);
  const SpecialPoint* bp = nullptr;
  for (const SpecialPoint& s : r2.special_points) {
    if (s.kind == SpecialPointKind::kBranchPoint) bp = &s;
  }
  ASSERT_NE(bp, nullptr) << r2.summary.message;
  // Both located to 1e-10 in b.
  EXPECT_NEAR(bp->point.value, pd.point.value, 1e-9);
}

TEST(PeriodDoublingSwitch, RejectsAPointThatIsNotAPeriodDoubling) {
  DO model;
  ExactPropagator prop(model);
  SpecialPoint fold;
  fold.kind = SpecialPointKind::kFold;
  const StatusOr<PeriodicOrbit> r = SwitchAtPeriodDoubling(model, prop, fold, "b");
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace drillbif
