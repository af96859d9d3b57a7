// Codimension-2 points on two-parameter curves in (omega, a), found two independent ways:
// along the l1 grazing curve as roots of det(M -+ I), and at the ends of the period-doubling and
// fold curves as the boundary where their orbits stop being admissible. The same flip-grazing
// points must come out of both, and each point satisfies both of its defining conditions.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <string>
#include <utility>
#include <vector>

#include "drillbif/continuation/curve.h"
#include "support/multipliers.h"
#include "support/reference_orbit_test.h"
#include "support/special_point_near.h"
#include "support/tangent_end.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

class Codim2Test : public testing::ReferenceOrbitTest {
 protected:
  void SetUp() override {
    ReferenceOrbitTest::SetUp();
    if (HasFatalFailure()) return;
    ContinuationOptions opt;
    opt.param = "omega";
    opt.min = 0.05;
    opt.max = 2.0;
    omega_branch_ = Continue(model_, prop_, start_, opt);
    ASSERT_EQ(omega_branch_.summary.termination, Termination::kCompleted);
  }

  // The first special point of this kind with omega in [lo, hi].
  const SpecialPoint* Find(SpecialPointKind kind, double lo, double hi) const {
    for (const SpecialPoint& s : omega_branch_.special_points) {
      if (s.kind == kind && s.point.value >= lo && s.point.value <= hi) return &s;
    }
    return nullptr;
  }

  CurveResult Curve(const SpecialPoint& start, std::vector<double> crossings1 = {}) {
    CurveOptions opt;
    opt.crossings1 = std::move(crossings1);
    opt.param1 = std::string("omega");  // not = "omega": GCC 12 -Wrestrict false positive
    opt.param2 = "a";
    opt.min1 = 0.05, opt.max1 = 2.0;
    opt.min2 = 0.01, opt.max2 = 8.0;
    return ContinueCurve(model_, prop_, start, opt);
  }

  ContinuationResult omega_branch_;
};

// The acceptance check of two-parameter curves: a curve traced in (omega, a) from the
// omega-continuation at a = 0.3 crosses omega = 0.1 where the a-continuation at omega = 0.1 locates
// the same kind of point.
TEST_F(Codim2Test, PeriodDoublingCurveCrossesOmegaOneTenthWhereTheABranchLocatesIt) {
  const SpecialPoint* pd = Find(SpecialPointKind::kPeriodDoubling, 0.09, 0.1);
  ASSERT_NE(pd, nullptr);
  const CurveResult curve = Curve(*pd, {0.1});
  ASSERT_EQ(curve.crossings.size(), 1u) << curve.summary.message;
  const CurvePoint& c = curve.crossings.front();
  EXPECT_EQ(c.value1, 0.1);
  ContinuationOptions opt;
  opt.param = "a";
  opt.min = 0.01;
  opt.max = 8.0;
  const ContinuationResult a_branch = Continue(model_, prop_, start_, opt);
  double nearest = std::numeric_limits<double>::infinity();
  for (const SpecialPoint& s : a_branch.special_points) {
    if (s.kind == SpecialPointKind::kPeriodDoubling) {
      nearest = std::min(nearest, std::abs(s.point.value - c.value2));
    }
  }
  // Both are located to 1e-10 in a (the crossing to the corrector's 1e-10, the branch's point to
  // locate_tolerance); 1e-7 is required.
  EXPECT_LE(nearest, 1e-7) << "crossing at a = " << c.value2;
  EXPECT_LE(testing::DistanceToMultiplier(c.stability, -1.0), 1e-8);
}

// Two different l2 grazing curves, traced from the a-branch at omega = 0.1 (grazings at
// a = 0.16756 and 0.16938), each end where its orbit touches a second boundary: they meet there,
// and each locates that double grazing independently (by bisection on its own admissibility).
TEST_F(Codim2Test, TwoGrazingCurvesMeetAtTheDoubleGrazingEachLocates) {
  ContinuationOptions opt;
  opt.param = "a";
  opt.min = 0.01;
  opt.max = 8.0;
  const ContinuationResult a_branch = Continue(model_, prop_, start_, opt);
  std::vector<std::vector<CurvePoint>> ends;
  for (const double a : {0.16756, 0.16938}) {
    const SpecialPoint* graze =
        testing::SpecialPointNear(a_branch, SpecialPointKind::kGrazingL2, a, 1e-4);
    ASSERT_NE(graze, nullptr) << "no l2 grazing near a = " << a;
    CurveOptions co;
    co.param1 = "a", co.param2 = std::string("omega");
    co.min1 = 0.01, co.max1 = 8.0, co.min2 = 0.05, co.max2 = 2.0;
    const CurveResult curve = ContinueCurve(model_, prop_, *graze, co);
    ends.emplace_back();
    for (const Codim2Point& q : curve.codim2) {
      if (q.kind != Codim2Kind::kDoubleGrazing) continue;
      ends.back().push_back(q.point);
      // The curve's own condition holds at its end: h = h' = 0 at the tangent end (1e-9 as on
      // the crossings).
      const PeriodicOrbit& o = q.point.orbit;
      int k = 0;
      while (k < static_cast<int>(o.signature.segments.size()) && !o.signature.segments[k].tangent)
        ++k;
      ASSERT_LT(k, static_cast<int>(o.signature.segments.size()));
      const SegmentSpec& seg = o.signature.segments[k];
      const StateVector xe = prop_.FlowMap(seg.mode, o.starts[k], o.durations[k], o.params, {}).x;
      const GuardValue g = model_.Guard(seg.mode, seg.guard, xe, o.params);
      EXPECT_LE(std::abs(g.h), 1e-9);
      EXPECT_LE(std::abs(g.dh), 1e-9);
    }
    ASSERT_FALSE(ends.back().empty()) << curve.summary.message;
  }
  // A common end. The bisections stop where the corrector stalls beyond the boundary, so a
  // `bracket` can be wide although the last admissible point lies next to the boundary; the two
  // locations agree to 1.4e-12 measured, 1e-7 asked (the required bound for crossings).
  double nearest = std::numeric_limits<double>::infinity();
  for (const CurvePoint& p : ends[0]) {
    for (const CurvePoint& q : ends[1]) {
      nearest =
          std::min(nearest, std::max(std::abs(p.value1 - q.value1), std::abs(p.value2 - q.value2)));
    }
  }
  EXPECT_LE(nearest, 1e-7);
}

TEST_F(Codim2Test, GrazingCurveCarriesFlipAndFoldGrazingsSatisfyingBothConditions) {
  const SpecialPoint* graze = Find(SpecialPointKind::kGrazingL1, 0.4, 0.6);
  ASSERT_NE(graze, nullptr);
  const CurveResult curve = Curve(*graze);
  ASSERT_EQ(curve.summary.termination, Termination::kCompleted) << curve.summary.message;
  int flips = 0, folds = 0;
  for (const Codim2Point& q : curve.codim2) {
    if (q.kind == Codim2Kind::kDoubleGrazing) continue;  // its end: TwoGrazingCurvesMeet...
    const bool flip = q.kind == Codim2Kind::kFlipGrazing;
    flips += flip;
    folds += q.kind == Codim2Kind::kFoldGrazing;
    // The multiplier: the root is located to |det(M -+ I)| <= 1e-10, so the critical multiplier
    // is within 1e-10 / |mu_other -+ 1| (>= 0.09 here) plus the corrector's 1e-10 amplified by
    // dmu/dY = O(10): 1e-8 bounds both.
    EXPECT_LE(testing::DistanceToMultiplier(q.point.stability, flip ? -1.0 : 1.0), 1e-8)
        << Codim2KindName(q.kind) << " at omega = " << q.point.value1;
    // The grazing: the tangent segment end has h = 0 and h' = 0 to the corrector's accuracy.
    const std::optional<GuardValue> g = testing::TangentEndGuard(model_, prop_, q.point.orbit);
    ASSERT_TRUE(g.has_value());
    EXPECT_LE(std::abs(g->h), 1e-9);
    EXPECT_LE(std::abs(g->dh), 1e-9);
  }
  EXPECT_EQ(flips, 2) << curve.summary.message;
  EXPECT_EQ(folds, 1) << curve.summary.message;
}

TEST_F(Codim2Test, PeriodDoublingCurveEndsAtTheFlipGrazingsOfTheGrazingCurve) {
  const SpecialPoint* graze = Find(SpecialPointKind::kGrazingL1, 0.4, 0.6);
  const SpecialPoint* pd = Find(SpecialPointKind::kPeriodDoubling, 1.0, 2.0);
  ASSERT_NE(graze, nullptr);
  ASSERT_NE(pd, nullptr);
  const CurveResult grazing_curve = Curve(*graze);
  const CurveResult pd_curve = Curve(*pd);
  ASSERT_EQ(pd_curve.summary.termination, Termination::kCompleted) << pd_curve.summary.message;
  ASSERT_EQ(pd_curve.codim2.size(), 2u) << pd_curve.summary.message;
  for (const Codim2Point& end : pd_curve.codim2) {
    EXPECT_EQ(end.kind, Codim2Kind::kFlipGrazing);
    // The boundary bisection converged (no stalled corrector next to it).
    EXPECT_LE(end.bracket, 1e-9) << end.detail;
    // Still a period doubling: the PD curve's own condition, 1e-8 as on the crossings.
    EXPECT_LE(testing::DistanceToMultiplier(end.point.stability, -1.0), 1e-8);
    // The same point from the grazing curve's determinant root. Each is located to ~1e-10 in
    // arclength (boundary bracket 1e-12, corrector 1e-10; |det| <= 1e-10 with d det/ds = O(1)),
    // and both curves cross there at an O(1) angle: 1e-7 leaves a factor 100 for the slopes.
    double nearest = std::numeric_limits<double>::infinity();
    for (const Codim2Point& q : grazing_curve.codim2) {
      if (q.kind != Codim2Kind::kFlipGrazing) continue;
      nearest = std::min(nearest, std::max(std::abs(q.point.value1 - end.point.value1),
                                           std::abs(q.point.value2 - end.point.value2)));
    }
    EXPECT_LE(nearest, 1e-7) << "omega = " << end.point.value1 << ", a = " << end.point.value2;
  }
}

TEST_F(Codim2Test, FoldCurveEndsAtAFoldGrazing) {
  const SpecialPoint* fold = Find(SpecialPointKind::kFold, 0.05, 0.1);
  ASSERT_NE(fold, nullptr);
  const CurveResult curve = Curve(*fold);
  ASSERT_EQ(curve.summary.termination, Termination::kCompleted) << curve.summary.message;
  ASSERT_EQ(curve.codim2.size(), 1u) << curve.summary.message;
  const Codim2Point& end = curve.codim2.front();
  EXPECT_EQ(end.kind, Codim2Kind::kFoldGrazing);
  EXPECT_LE(end.bracket, 1e-9) << end.detail;
  EXPECT_LE(testing::DistanceToMultiplier(end.point.stability, 1.0), 1e-8);
  EXPECT_TRUE(CheckAdmissible(model_, prop_, end.point.orbit).admissible);
}

// A curve goes on where an event of its orbit reaches the Poincare section (an impact at s = 0:
// the first segment vanishes, a change of representation, not a grazing). The PD curve from the
// omega-branch's doubling at 0.0944 (a = 0.3), in omega [0.05, 0.2] x a [0.27, 0.32], crosses the
// section near omega = 0.1844 and goes on in the rotated signature to the box. Beyond the
// crossing, at omega = 0.19: the curve's crossing has the multiplier -1 (eigenvalues, independent
// of the extended system's sigma) and is a doubling of the one-parameter family in a (the
// multiplier passes -1 between a -+ 1e-7, orbits solved by Newton at fixed a).
TEST_F(Codim2Test, CurveGoesOnThroughAPoincareSectionCrossing) {
  const SpecialPoint* pd = Find(SpecialPointKind::kPeriodDoubling, 0.09, 0.1);
  ASSERT_NE(pd, nullptr);
  CurveOptions opt;
  opt.param1 = std::string("omega");
  opt.param2 = "a";
  opt.min1 = 0.05, opt.max1 = 0.2;
  opt.min2 = 0.27, opt.max2 = 0.32;
  opt.crossings1 = {0.19};
  const CurveResult curve = ContinueCurve(model_, prop_, *pd, opt);
  ASSERT_EQ(curve.summary.termination, Termination::kCompleted) << curve.summary.message;
  EXPECT_NE(curve.summary.message.find("through 1 section crossings, left the box"),
            std::string::npos)
      << curve.summary.message;
  for (const Codim2Point& q : curve.codim2) {
    EXPECT_GT(std::abs(q.point.value1 - 0.1844), 1e-2) << "a codimension-2 end at the crossing";
  }
  ASSERT_EQ(curve.crossings.size(), 1u);
  const CurvePoint& x = curve.crossings.front();
  EXPECT_EQ(x.value1, 0.19);
  // The corrector's 1e-10 amplified by d mu / d Y = O(10).
  EXPECT_LE(testing::DistanceToMultiplier(x.stability, -1.0), 1e-8);
  // Either side in a: the critical multiplier (the largest; the others are ~1e-8 here) is real
  // and on opposite sides of -1. It moves fast (measured mu + 1 = -0.034 and +0.035 at a -+ 1e-7:
  // d mu / d a ~ 3.5e5, the orbit is close to grazing), so the sides are taken 1e-7 away, where
  // that is far above the orbits' 1e-11 accuracy.
  const int ia = model_.ParamIndex("a").value();
  std::vector<double> side;
  for (double da : {-1e-7, 1e-7}) {
    PeriodicOrbit o = x.orbit;
    o.params[ia] += da;
    const OrbitSolveSummary solved = SolveOrbit(model_, prop_, {}, &o);
    ASSERT_EQ(solved.termination, Termination::kCompleted) << solved.message;
    const std::complex<double> critical = OrbitStability(model_, prop_, o).multipliers.front();
    EXPECT_EQ(critical.imag(), 0.0);
    side.push_back(critical.real() + 1.0);
  }
  EXPECT_LT(side[0] * side[1], 0.0) << side[0] << " " << side[1];
  RecordProperty("mu_plus_one_either_side",
                 std::to_string(side[0]) + " " + std::to_string(side[1]));
}

}  // namespace
}  // namespace drillbif
