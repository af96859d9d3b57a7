// The period-2 grazing curves leaving flip-grazing points (trace_internal.h): given only the
// period-1 PD curve from the omega-branch's doubling at omega = 1.6258 (a = 0.3), which ends at
// the two flip-grazings (1.3946, 6.7289) and (0.4734, 0.1616) of issue 4's box, the step finds
// the period-2 grazing curve leaving each. Checked independently: each such curve ends where its
// second pass grazes too (DOUBLE_GRAZING) at the flip-grazing point, its orbits have h = h' = 0
// at the tangent end, and they are genuinely of period 2 by direct simulation.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <string>

#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/issue4_box.h"
#include "problems/reference_orbit.h"
#include "support/period_two.h"
#include "support/tangent_end.h"
#include "trace_internal.h"

namespace drillbif::internal {
namespace {

TEST(FlipGrazingSwitch, GrazingCurveOfPeriodTwoLeavesEachFlipGrazing) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const StatusOr<PeriodicOrbit> start =
      testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  ASSERT_TRUE(start.ok());
  const TraceOptions box = testing::Issue4Box();
  ContinuationOptions branch;
  branch.param = "omega";
  branch.min = box.min1, branch.max = box.max1;
  const ContinuationResult omega = Continue(model, prop, *start, branch);
  const SpecialPoint* pd = nullptr;
  for (const SpecialPoint& s : omega.special_points) {
    if (s.kind == SpecialPointKind::kPeriodDoubling && std::abs(s.point.value - 1.6258) < 1e-3) {
      pd = &s;
    }
  }
  ASSERT_NE(pd, nullptr);
  CurveOptions co = box.curve;
  co.param1 = box.param1, co.min1 = box.min1, co.max1 = box.max1;
  co.param2 = box.param2, co.min2 = box.min2, co.max2 = box.max2;
  TraceResult result;
  result.curves.push_back({*pd, "omega", ContinueCurve(model, prop, *pd, co)});
  int flips = 0;
  for (const Codim2Point& q : result.curves[0].curve.codim2) {
    flips += q.kind == Codim2Kind::kFlipGrazing;
  }
  ASSERT_EQ(flips, 2);

  TraceOptions opt = box;
  opt.max_period = 2;
  ASSERT_TRUE(GrazingCurvesAtFlipGrazings(
      model, prop, opt, [](double) { return true; }, 0, &result));
  EXPECT_EQ(result.summary.notes.back(),
            "period-2 grazing curves leave 2 of 2 period-1 "
            "flip-grazing points");
  const double w1 = box.max1 - box.min1, w2 = box.max2 - box.min2;
  for (const Codim2Point& q : result.curves[0].curve.codim2) {
    if (q.kind != Codim2Kind::kFlipGrazing) continue;
    // The curve leaving it: a period-2 grazing curve from curve 0 with a DOUBLE_GRAZING end at
    // the point. The end is bisected to `bracket` in arclength (parameters included), the
    // flip-grazing to 1e-11 here (its own bracket): parameter distance <= bracket + 1e-9.
    const TracedCurve* leaving = nullptr;
    for (size_t c = 1; c < result.curves.size(); ++c) {
      const TracedCurve& t = result.curves[c];
      for (const Codim2Point& z : t.curve.codim2) {
        if (z.kind == Codim2Kind::kDoubleGrazing &&
            std::hypot(z.point.value1 - q.point.value1, z.point.value2 - q.point.value2) <=
                z.bracket + 1e-9) {
          leaving = &t;
        }
      }
    }
    ASSERT_NE(leaving, nullptr) << "flip-grazing at omega = " << q.point.value1;
    EXPECT_EQ(leaving->curve.kind, CurveKind::kGrazing);
    EXPECT_EQ(leaving->from_curve, 0);
    EXPECT_LE(DistanceToCurve(leaving->curve, q.point.value1, q.point.value2, w1, w2), 1e-2);
    for (const CurvePoint& p : leaving->curve.points) {
      ASSERT_EQ(p.orbit.signature.periods, 2);
      EXPECT_TRUE(CheckAdmissible(model, prop, p.orbit).admissible);
      const std::optional<GuardValue> g = testing::TangentEndGuard(model, prop, p.orbit);
      ASSERT_TRUE(g.has_value());
      // The corrector's tolerance 1e-10 on scaled unknowns, h and h' O(1)-Lipschitz in them.
      EXPECT_LE(std::abs(g->h), 1e-9);
      EXPECT_LE(std::abs(g->dh), 1e-9);
    }
    // Direct simulation from the middle vertex's section state: back after two forcing periods
    // (to the corrector's 1e-10 amplified by the multipliers over two periods, < 1e-7), not
    // after one (its passes differ there by far more than 1e-5).
    const PeriodicOrbit& mid = leaving->curve.points[leaving->curve.points.size() / 2].orbit;
    testing::ExpectPeriodTwoBySimulation(model, prop, mid, 1e-7, 1e-5);
  }
}

}  // namespace
}  // namespace drillbif::internal
