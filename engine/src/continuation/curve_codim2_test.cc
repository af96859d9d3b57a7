// CurveCodim2's cusp search on one step: the search of a curve's last step, whose inner probes
// bound the interval before the whole step does, locates the same cusp as the plain search of
// the step (each probe predicted on the step's chord and read by its corrector's tangent; the
// search's trial points predicted between the corrected points that bracket them).
#include "continuation/curve_codim2.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "continuation/curve_system.h"
#include "drillbif/continuation/continuation.h"
#include "drillbif/continuation/curve.h"
#include "drillbif/flow/exact_propagator.h"
#include "support/cusp_fold_curve.h"

namespace drillbif {
namespace {

using Vec = Eigen::VectorXd;

// The fold curve through the a-branch's fold at a = 0.156617 (omega = 0.1) has a cusp near
// (omega, a) = (0.10435, 0.15436) (tests/continuation/cusp_test.cc checks it is one). Its steps
// next to the reported cusp are searched again on their own: the plain search (no probes) of
// the step that holds the cusp finds it where the curve reported it, and the search with the
// 7 probes of a curve's last step finds the same point. Both locate psi's root to
// |psi| <= 1e-10 |u|; at a cusp the parameters are stationary along the curve, so two such roots
// lie far closer in the parameter plane than the 1e-9 (box-scaled) within which the curve
// counts two cusps as one, the tolerance asserted.
TEST(CurveCodim2Cusp, ProbedSearchOfAStepFindsTheCuspThePlainSearchFinds) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const std::optional<SpecialPoint> fold = testing::CuspCurveFold(model, prop);
  ASSERT_TRUE(fold.has_value());
  const CurveOptions co = testing::CuspCurveOptions();
  const CurveResult curve = ContinueCurve(model, prop, *fold, co);
  const Codim2Point* cusp = nullptr;
  for (const Codim2Point& q : curve.codim2) {
    if (q.kind == Codim2Kind::kCusp && std::abs(q.point.value2 - 0.10435) < 1e-4) cusp = &q;
  }
  ASSERT_NE(cusp, nullptr) << curve.summary.message;
  const std::vector<CurvePoint>& points = curve.points;
  ASSERT_GE(points.size(), 3u);
  const double w1 = co.max1 - co.min1, w2 = co.max2 - co.min2;
  auto apart = [&](const CurvePoint& a, const CurvePoint& b) {
    return std::hypot((a.value1 - b.value1) / w1, (a.value2 - b.value2) / w2);
  };
  // The vertex nearest the cusp; the cusp lies on one of its two steps.
  size_t nearest = 1;
  for (size_t i = 1; i + 1 < points.size(); ++i) {
    if (apart(points[i], cusp->point) < apart(points[nearest], cusp->point)) nearest = i;
  }
  internal::CurveSystem system(model, prop, co, CurveKind::kFold, model.ParamIndex("a").value(),
                               model.ParamIndex("omega").value(), points[nearest].orbit);
  const internal::CurveCodim2 codim2(system);
  int plain_found = 0, probed_found = 0;
  for (size_t i = nearest - 1; i <= nearest; ++i) {
    const PeriodicOrbit& o0 = points[i].orbit;
    const PeriodicOrbit& o1 = points[i + 1].orbit;
    ASSERT_EQ(o0.signature.segments.size(), o1.signature.segments.size());
    const Vec y = system.Pack(o0), y1 = system.Pack(o1);
    // The tangents along the curve's direction of travel on this step.
    Vec t, t1;
    ASSERT_TRUE(system.Tangent(y, y1 - y, &t));
    ASSERT_TRUE(system.Tangent(y1, t, &t1));
    std::vector<Codim2Point> plain, probed;
    codim2.CuspOnStep(y, t, y1, t1, &plain);
    codim2.CuspOnStep(y, t, y1, t1, &probed, 1e-10, 7);
    plain_found += static_cast<int>(plain.size());
    probed_found += static_cast<int>(probed.size());
    ASSERT_EQ(plain.size(), probed.size()) << "step " << i;
    for (size_t k = 0; k < plain.size(); ++k) {
      EXPECT_LE(apart(plain[k].point, cusp->point), 1e-9)
          << "plain search: (" << plain[k].point.value2 << ", " << plain[k].point.value1 << ")";
      EXPECT_LE(apart(probed[k].point, plain[k].point), 1e-9)
          << "probed search: (" << probed[k].point.value2 << ", " << probed[k].point.value1 << ")";
    }
  }
  EXPECT_EQ(plain_found, 1);
  EXPECT_EQ(probed_found, 1);
}

}  // namespace
}  // namespace drillbif
