// Two-parameter curves of folds, period doublings and l1 grazings: consistent with the
// one-parameter continuations (each curve crosses a = 0.28 and a = 0.32 where the b-continuation at
// that a locates the point), and every crossing satisfies its defining condition.
#include "drillbif/continuation/curve.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <tuple>

#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"
#include "support/multipliers.h"
#include "support/special_point_near.h"
#include "support/tangent_end.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

// The b-continuation at amplitude a of the family of MODEL.md's start orbit: the start orbit
// (a = 0.3, b = 0.15) continued in a to the requested value first, since from rest at another a
// the simulation may settle on a coexisting period-1 orbit of another family. Up to the fold and
// down to b = 0 (through the PD and the l1 grazing).
ContinuationResult BBranch(const DO& model, Propagator& prop, double a) {
  const StatusOr<PeriodicOrbit> reference =
      testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  EXPECT_TRUE(reference.ok()) << reference.status().ToString();
  PeriodicOrbit start = *reference;
  if (a != start.params[DO::kA]) {
    ContinuationOptions to_a;
    to_a.param = "a";
    to_a.min = std::min(a, start.params[DO::kA]);
    to_a.max = std::max(a, start.params[DO::kA]);
    to_a.direction = a < start.params[DO::kA] ? ContinuationDirection::kDecreasing
                                              : ContinuationDirection::kIncreasing;
    const ContinuationResult moved = Continue(model, prop, start, to_a);
    EXPECT_EQ(moved.summary.termination, Termination::kCompleted) << moved.summary.message;
    start = (a < start.params[DO::kA] ? moved.points.front() : moved.points.back()).orbit;
    EXPECT_NEAR(start.params[DO::kA], a, 1e-9);
  }
  ContinuationOptions opt;
  opt.param = "b";
  opt.min = 0.0;
  opt.max = 0.2;
  opt.stop_at = {SpecialPointKind::kFold};
  return Continue(model, prop, start, opt);
}

const SpecialPoint* FindKind(const ContinuationResult& r, SpecialPointKind kind) {
  for (const SpecialPoint& s : r.special_points) {
    if (s.kind == kind) return &s;
  }
  return nullptr;
}

// Curves in (b, a) from the b-branch's points: b in [0, 0.3], a in [min_a, max_a].
CurveOptions BABox(double min_a, double max_a) {
  CurveOptions opt;
  opt.param1 = "b";
  opt.param2 = "a";
  opt.min1 = 0.0;
  opt.max1 = 0.3;
  opt.min2 = min_a;
  opt.max2 = max_a;
  return opt;
}

class CurveConsistencyTest : public ::testing::TestWithParam<SpecialPointKind> {};

TEST_P(CurveConsistencyTest, CrossesNeighbouringAmplitudesWhereTheOneParameterRunsLocate) {
  DO model;
  ExactPropagator prop(model);
  const ContinuationResult reference = BBranch(model, prop, 0.3);
  const SpecialPoint* start = FindKind(reference, GetParam());
  ASSERT_NE(start, nullptr);
  CurveOptions opt = BABox(0.25, 0.35);
  opt.crossings2 = {0.28, 0.32};
  const CurveResult curve = ContinueCurve(model, prop, *start, opt);
  ASSERT_EQ(curve.summary.termination, Termination::kCompleted) << curve.summary.message;
  ASSERT_EQ(curve.crossings.size(), 2u) << curve.summary.message;
  const double target = GetParam() == SpecialPointKind::kFold ? 1.0 : -1.0;
  const bool grazing = GetParam() == SpecialPointKind::kGrazingL1;
  for (const CurvePoint& c : curve.crossings) {
    const ContinuationResult one = BBranch(model, prop, c.value2);
    const SpecialPoint* located = FindKind(one, GetParam());
    ASSERT_NE(located, nullptr) << "a = " << c.value2;
    // Both are located to 1e-10 in b (the curve's crossing to the corrector's 1e-10); agreement
    // to 1e-7 is required.
    EXPECT_NEAR(c.value1, located->point.value, 1e-7) << "a = " << c.value2;
    if (grazing) {
      // Independent check of the crossing: the original-signature orbit (with its CwP phase)
      // solved by Newton at b = crossing + 1e-6 has a short positive CwP phase, and at
      // b = crossing - 1e-6 none exists (no convergence, or a negative duration).
      // Natural-parameter Newton steps from the regular start orbit: b down to 0.029 at a = 0.3,
      // then a to the crossing's value, then b down to just above the crossing.
      PeriodicOrbit above = *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
      auto step_to = [&](int index, double to, double step) {
        const double from = above.params[index];
        const int n = std::max(1, static_cast<int>(std::ceil(std::abs(to - from) / step)));
        for (int k = 1; k <= n; ++k) {
          above.params[index] = from + (to - from) * k / n;
          ASSERT_EQ(SolveOrbit(model, prop, {}, &above).termination, Termination::kCompleted)
              << model.param_names()[index] << " = " << above.params[index];
        }
      };
      step_to(DO::kB, 0.029, 5e-4);
      step_to(DO::kA, c.value2, 1e-3);
      step_to(DO::kB, c.value1 + 1e-4, 1e-4);
      step_to(DO::kB, c.value1 + 1e-5, 1e-5);
      above.params[DO::kB] = c.value1 + 1e-6;
      ASSERT_EQ(SolveOrbit(model, prop, {}, &above).termination, Termination::kCompleted);
      EXPECT_GT(above.durations[2], 0.0) << "a = " << c.value2;
      EXPECT_LT(above.durations[2], 0.05) << "a = " << c.value2;
      PeriodicOrbit below = above;
      below.params[DO::kB] = c.value1 - 1e-6;
      const OrbitSolveSummary sb = SolveOrbit(model, prop, {}, &below);
      EXPECT_TRUE(sb.termination != Termination::kCompleted || below.durations[2] <= 0.0)
          << "a = " << c.value2;
      // The touching point: the tangent segment end has h = 0 (an equation of the orbit) and
      // h' = 0 (the curve's condition), to the corrector's accuracy.
      const std::optional<GuardValue> g = testing::TangentEndGuard(model, prop, c.orbit);
      ASSERT_TRUE(g.has_value());
      EXPECT_LE(std::abs(g->h), 1e-9) << "a = " << c.value2;
      EXPECT_LE(std::abs(g->dh), 1e-9) << "a = " << c.value2;
      continue;
    }
    // The crossing's defining condition: a multiplier at +1 (fold) or -1 (period doubling), to the
    // corrector's accuracy (1e-10 relative to the unknowns, amplified by dmu/dY = O(10)).
    EXPECT_LE(testing::DistanceToMultiplier(c.stability, target), 1e-8) << "a = " << c.value2;
  }
  for (const CurvePoint& p : curve.points) {
    EXPECT_GE(p.value2, opt.min2);
    EXPECT_LE(p.value2, opt.max2);
    EXPECT_TRUE(CheckAdmissible(model, prop, p.orbit).admissible) << p.value1 << ", " << p.value2;
  }
}

INSTANTIATE_TEST_SUITE_P(FoldAndPeriodDoubling, CurveConsistencyTest,
                         ::testing::Values(SpecialPointKind::kFold,
                                           SpecialPointKind::kPeriodDoubling,
                                           SpecialPointKind::kGrazingL1),
                         [](const auto& test_info) {
                           return std::string(SpecialPointKindName(test_info.param));
                         });

TEST(Curve, OtherStartsAreClearErrors) {
  DO model;
  ExactPropagator prop(model);
  SpecialPoint rop_max;
  rop_max.kind = SpecialPointKind::kRopMax;
  CurveOptions opt;
  opt.param1 = "b";
  opt.param2 = "a";
  opt.min1 = 0.0, opt.max1 = 1.0, opt.min2 = 0.0, opt.max2 = 1.0;
  const CurveResult not_a_curve = ContinueCurve(model, prop, rop_max, opt);
  EXPECT_EQ(not_a_curve.summary.termination, Termination::kFailed);
  EXPECT_EQ(not_a_curve.summary.status.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(not_a_curve.summary.message, not_a_curve.summary.status.message());
  SpecialPoint graze;  // a malformed orbit (no start states, no parameters)
  graze.kind = SpecialPointKind::kGrazingPi;
  graze.point.orbit.signature.segments = {{0, 0}, {1, 1}, {0, -1}};
  graze.point.orbit.durations = {1.0, 1.0, 1.0};
  EXPECT_EQ(ContinueCurve(model, prop, graze, opt).summary.status.code(),
            StatusCode::kUnimplemented);
  // The reference orbit called a grazing: no segment vanishes and no guard touches zero inside a
  // segment (each only reaches it at the segment's end), so there is no tangent form.
  SpecialPoint not_grazing;
  not_grazing.kind = SpecialPointKind::kGrazingPi;
  not_grazing.point.orbit = *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  EXPECT_EQ(ContinueCurve(model, prop, not_grazing, opt).summary.status.code(),
            StatusCode::kUnimplemented);
  CurveOptions same = opt;
  same.param2 = "b";
  SpecialPoint fold;
  fold.kind = SpecialPointKind::kFold;
  EXPECT_EQ(ContinueCurve(model, prop, fold, same).summary.status.code(),
            StatusCode::kInvalidArgument);
}

// Near xi = 0.5 the grazing condition's velocity coefficient (1 - 4 xi^2 in
// F' = y (1 - 4 xi^2) + 2 xi (a cos(s + phi0) + b - q)) vanishes. Grazing curves in (a, xi) and
// (omega, a) traced from the reference branches through xi = 0.5 must cross it where the
// one-parameter continuations at xi = 0.5 locate the grazings, and touch with h = h' = 0 there.
TEST(Curve, GrazingCurvesCrossXiOneHalfWhereTheBranchesThereLocate) {
  DO model;
  ExactPropagator prop(model);
  const StatusOr<PeriodicOrbit> reference =
      testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  ASSERT_TRUE(reference.ok());
  // The start orbit's family at xi = 0.5 (a = 0.3, omega = 0.1): continued in xi, which also keeps
  // it period-1 (from rest at xi = 0.5 the simulation settles on a period-2 orbit).
  ContinuationOptions to_half;
  to_half.param = "xi";
  to_half.min = reference->params[DO::kXi];
  to_half.max = 0.5;
  to_half.direction = ContinuationDirection::kIncreasing;
  const ContinuationResult moved = Continue(model, prop, *reference, to_half);
  ASSERT_EQ(moved.summary.termination, Termination::kCompleted) << moved.summary.message;
  ASSERT_NEAR(moved.points.back().value, 0.5, 1e-12);
  PeriodicOrbit half = moved.points.back().orbit;
  half.params[DO::kXi] = 0.5;  // exactly (the run ends within rounding of it)
  ASSERT_EQ(SolveOrbit(model, prop, {}, &half).termination, Termination::kCompleted);
  int crossings = 0;
  for (const auto& [param, kind, near, min, max] :
       {std::tuple{"a", SpecialPointKind::kGrazingL2, 0.1485, 0.01, 8.0},
        std::tuple{"omega", SpecialPointKind::kGrazingL1, 0.5088, 0.05, 2.0}}) {
    ContinuationOptions branch;
    branch.param = param;
    branch.min = min;
    branch.max = max;
    const ContinuationResult at_reference = Continue(model, prop, *reference, branch);
    const ContinuationResult at_half = Continue(model, prop, half, branch);
    // The grazing of the reference branch near a = 0.1485 (a-branch) or omega = 0.5088
    // (omega-branch), and its curve in (param, xi).
    const SpecialPoint* start = testing::SpecialPointNear(at_reference, kind, near, 1e-3);
    ASSERT_NE(start, nullptr) << param;
    CurveOptions opt;
    opt.param1 = param;
    opt.param2 = "xi";
    opt.min1 = min, opt.max1 = max;
    opt.min2 = 0.01, opt.max2 = 1.0;
    opt.crossings2 = {0.5};
    const CurveResult curve = ContinueCurve(model, prop, *start, opt);
    ASSERT_NE(curve.summary.termination, Termination::kFailed) << curve.summary.message;
    ASSERT_EQ(curve.crossings.size(), 1u) << param << ": " << curve.summary.message;
    const CurvePoint& c = curve.crossings[0];
    double best = std::numeric_limits<double>::infinity();
    for (const SpecialPoint& s : at_half.special_points) {
      if (s.kind == kind) best = std::min(best, std::abs(s.point.value - c.value1));
    }
    // Both located to 1e-10 (corrector, location); the required bound for curves vs branches.
    EXPECT_LE(best, 1e-7) << param << " crossing at " << c.value1;
    const std::optional<GuardValue> g = testing::TangentEndGuard(model, prop, c.orbit);
    ASSERT_TRUE(g.has_value());
    EXPECT_LE(std::abs(g->h), 1e-9) << param;
    EXPECT_LE(std::abs(g->dh), 1e-9) << param;
    ++crossings;
  }
  EXPECT_EQ(crossings, 2);
}

// A grazing seen from the side without the event: on the a-branch at omega = 0.1 the free flight
// touches Pi at a = 0.29848 with no segment vanishing (it is the impacting orbit beyond). The curve
// is traced from the flight split at its touching point: at every point the tangent end has
// h = h' = 0 (to the corrector's accuracy) and h'' > 0 (the flight turns back from Pi, a touch,
// not a crossing), and the curve crosses a = 0.3 where the omega-branch locates its Pi grazing.
TEST(Curve, PiGrazingCurveFromTheNonImpactingSide) {
  DO model;
  ExactPropagator prop(model);
  const StatusOr<PeriodicOrbit> reference =
      testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  ASSERT_TRUE(reference.ok());
  ContinuationOptions a_branch;
  a_branch.param = "a";
  a_branch.min = 0.25, a_branch.max = 0.35;
  const ContinuationResult ra = Continue(model, prop, *reference, a_branch);
  const SpecialPoint* start =
      testing::SpecialPointNear(ra, SpecialPointKind::kGrazingPi, 0.29848, 1e-4);
  ASSERT_NE(start, nullptr);
  for (double d : start->point.orbit.durations) EXPECT_GT(std::abs(d), 1e-3);  // none vanishes
  CurveOptions opt;
  opt.param1 = "a";
  opt.param2 = "omega";
  opt.min1 = 0.25, opt.max1 = 0.35;
  opt.min2 = 0.05, opt.max2 = 0.2;
  opt.crossings1 = {0.3};
  const CurveResult curve = ContinueCurve(model, prop, *start, opt);
  ASSERT_NE(curve.summary.termination, Termination::kFailed) << curve.summary.message;
  ASSERT_GT(curve.points.size(), 10u);
  for (size_t n = 0; n < curve.points.size(); n += curve.points.size() / 10) {
    std::string surface;
    const std::optional<GuardValue> g =
        testing::TangentEndGuard(model, prop, curve.points[n].orbit, &surface);
    ASSERT_TRUE(g.has_value());
    EXPECT_EQ(surface, "Pi");
    EXPECT_LE(std::abs(g->h), 1e-9) << "point " << n;
    EXPECT_LE(std::abs(g->dh), 1e-9) << "point " << n;
    EXPECT_GT(g->ddh, 0.0) << "point " << n;
  }
  ContinuationOptions omega_branch;
  omega_branch.param = "omega";
  omega_branch.min = 0.05, omega_branch.max = 0.2;
  const ContinuationResult ro = Continue(model, prop, *reference, omega_branch);
  ASSERT_FALSE(curve.crossings.empty());
  for (const CurvePoint& x : curve.crossings) {
    double best = 1e300;
    for (const SpecialPoint& s : ro.special_points) {
      if (s.kind == SpecialPointKind::kGrazingPi)
        best = std::min(best, std::abs(s.point.value - x.value2));
    }
    EXPECT_LE(best, 1e-7) << "crossing a = 0.3 at omega = " << x.value2;  // the required bound
  }
}

// A grazing curve's orbit touches its surface at a tangent end only to the corrector's accuracy:
// h(tau) of a few 1e-12 below zero puts a crossing of the guard sqrt(2 |h| / h'') before the
// end, farther than rounding alone explains. Such a dip (in the reference box: h = -4e-12,
// h'' = 0.065, the crossing 1.1e-5 before the end) ended a grazing curve at a spurious double
// grazing. The orbit is admissible at the corrector's residual, and not when its end is off the
// surface by more than the corrector's tolerance (1e-10 (1 + |x|)).
TEST(Curve, TangentEndOffTheSurfaceByTheCorrectorsResidualIsAdmissible) {
  DO model;
  ExactPropagator prop(model);
  const ContinuationResult reference = BBranch(model, prop, 0.3);
  const SpecialPoint* start = FindKind(reference, SpecialPointKind::kGrazingL1);
  ASSERT_NE(start, nullptr);
  const CurveOptions opt = BABox(0.29, 0.31);
  const CurveResult curve = ContinueCurve(model, prop, *start, opt);
  ASSERT_GE(curve.points.size(), 3u) << curve.summary.message;
  const PeriodicOrbit on = curve.points[curve.points.size() / 2].orbit;
  ASSERT_TRUE(CheckAdmissible(model, prop, on).admissible);
  int i = 0;
  while (i < static_cast<int>(on.durations.size()) && !on.signature.segments[i].tangent) ++i;
  ASSERT_LT(i, static_cast<int>(on.durations.size()));
  const SegmentSpec seg = on.signature.segments[i];
  const double tau = on.durations[i];
  // Lowers the touch by depth: the start moved against the gradient of h(tau) in the start state
  // (h is linear in it to O(depth^2), far below rounding here).
  auto lowered = [&](double depth) {
    FlowRequest req;
    req.state_jacobian = true;
    const FlowResult fr = prop.FlowMap(seg.mode, on.starts[i], tau, on.params, req);
    StateRow r = model.GuardGradient(seg.mode, seg.guard, fr.x, on.params) * fr.state_jacobian;
    r[model.phase_index()] = 0.0;
    PeriodicOrbit o = on;
    o.starts[i] -= depth * r.transpose() / r.squaredNorm();
    return o;
  };
  auto end_guard = [&](const PeriodicOrbit& o) {
    return model.Guard(seg.mode, seg.guard,
                       prop.FlowMap(seg.mode, o.starts[i], tau, o.params, {}).x, o.params);
  };
  // Lowered by 2e-11 from where the corrector left it (its own residual, a few 1e-12 at most,
  // comes on top); the first-order move is exact to O(depth^2) plus rounding, 1e-13 here.
  const double h_on = end_guard(on).h;
  const PeriodicOrbit residual = lowered(2e-11);
  const GuardValue g = end_guard(residual);
  ASSERT_NEAR(g.h - h_on, -2e-11, 1e-13);
  ASSERT_GT(g.ddh, 0.0);
  // The event locator sees the dip: a crossing of the tangent guard, before the end by more
  // than 1e-6 tau and than rounding's window sqrt(2e-13 (1 + |x|) / h'') (so that only the
  // residual can excuse it).
  AdvanceRequest req;
  req.mode = seg.mode, req.x0 = residual.starts[i], req.t_max = tau;
  const AdvanceResult r = prop.Advance(req, residual.params);
  ASSERT_EQ(r.end, AdvanceEnd::kEvent);
  ASSERT_EQ(r.guard, seg.guard);
  const double scale = 1.0 + r.x.lpNorm<Eigen::Infinity>();
  EXPECT_GT(tau - r.duration, 1e-6 * tau);
  EXPECT_GT(tau - r.duration, 2.0 * std::sqrt(2e-13 * scale / g.ddh));
  EXPECT_TRUE(CheckAdmissible(model, prop, residual).admissible)
      << CheckAdmissible(model, prop, residual).message;
  // Off the surface by 1e-8, 100 times the corrector's tolerance: a crossing.
  const Admissibility deep = CheckAdmissible(model, prop, lowered(1e-8));
  EXPECT_FALSE(deep.admissible);
  EXPECT_EQ(deep.segment, i);
  EXPECT_EQ(deep.guard, seg.guard);
}

}  // namespace
}  // namespace drillbif
