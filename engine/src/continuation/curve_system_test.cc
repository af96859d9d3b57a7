// CurveSystem's Jacobian: the condition's row of a grazing curve.
#include "curve_system.h"

#include <gtest/gtest.h>

#include <bit>
#include <cstdint>

#include "drillbif/continuation/continuation.h"
#include "problems/reference_box.h"
#include "support/reference_orbit_test.h"
#include "support/special_point_near.h"
#include "tangent_grazing.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

class CurveSystemTest : public testing::ReferenceOrbitTest {};

// A grazing curve's condition is h' at the end of its first tangent segment; its row of the
// Jacobian leaves out the evaluations of the unknowns that do not move that segment's flow. The
// row must be the full forward differences' to the bit: every entry is compared (bit patterns,
// no tolerance) with (Condition(y + h e_j) - Condition(y)) / h, on an orbit of the l1 grazing
// curve through the omega-branch's grazing at omega = 0.5088 (a = 0.3), where some entries are
// left out (exact zeros) and others are not.
TEST_F(CurveSystemTest, GrazingConditionRowIsTheFullForwardDifferences) {
  ContinuationOptions branch;
  branch.param = "omega";
  branch.min = 0.05;
  branch.max = 2.0;
  const ContinuationResult ro = Continue(model_, prop_, start_, branch);
  const SpecialPoint* graze =
      testing::SpecialPointNear(ro, SpecialPointKind::kGrazingL1, 0.5088, 1e-3);
  ASSERT_NE(graze, nullptr);
  const TraceOptions box = testing::ReferenceBox();
  CurveOptions opt;
  opt.param1 = box.param1, opt.min1 = box.min1, opt.max1 = box.max1;
  opt.param2 = box.param2, opt.min2 = box.min2, opt.max2 = box.max2;
  opt.steps.max_steps = 3;
  const CurveResult curve = ContinueCurve(model_, prop_, *graze, opt);
  ASSERT_GE(curve.points.size(), 2u) << curve.summary.message;
  const PeriodicOrbit& orbit = curve.points[1].orbit;
  int tangents = 0;
  for (const SegmentSpec& s : orbit.signature.segments) tangents += s.tangent ? 1 : 0;
  ASSERT_GE(tangents, 1) << "not the tangent form";

  const internal::CurveSystem sys(model_, prop_, opt, CurveKind::kGrazing, DO::kOmega, DO::kA,
                                  orbit);
  const Eigen::VectorXd y = sys.Pack(orbit);
  Eigen::VectorXd f;
  Eigen::MatrixXd jac;
  ASSERT_TRUE(sys.Evaluate(y, &f, &jac));
  const int m = sys.m();
  ASSERT_EQ(f[m], sys.Condition(y));
  int zeros = 0, nonzeros = 0;
  for (int j = 0; j < sys.n(); ++j) {
    const double h = internal::ForwardStep(y[j]);
    Eigen::VectorXd yp = y;
    yp[j] += h;
    const double expected = (sys.Condition(yp) - f[m]) / h;
    EXPECT_EQ(std::bit_cast<uint64_t>(jac(m, j)), std::bit_cast<uint64_t>(expected))
        << "unknown " << j << ": " << jac(m, j) << " against " << expected;
    (expected == 0.0 ? zeros : nonzeros) += 1;
  }
  EXPECT_GT(zeros, 0);
  EXPECT_GT(nonzeros, 0);
}

}  // namespace
}  // namespace drillbif
