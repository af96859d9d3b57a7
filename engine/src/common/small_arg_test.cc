// The small-argument functions against the same quantities in long double (80-bit, 11 more bits
// of precision, so its rounding is ~1e-19 relative) from their integral definitions'
// closed forms, where the direct forms' cancellation costs at most the digits the long double has
// to spare. Both sides of each series/direct switch are covered.
#include "small_arg.h"

#include <gtest/gtest.h>

#include <cmath>

namespace drillbif::internal {
namespace {

// (x - sin x) / x^3 and -(d/dx) (1 - cos x) / x^2 directly in long double. At |x| >= 0.3 their
// cancellation loses at most ~ 12/x^2 * 2/x^2 ~ 3e3 of long double's 1e-19: 3e-16, below the
// tolerances asked.
long double SinCubeRef(long double x) { return (x - std::sin(x)) / (x * x * x); }
long double MinusC2DerivativeRef(long double x) {
  const long double c2 = (1.0L - std::cos(x)) / (x * x);
  return (2.0L * c2 - std::sin(x) / x) / x;
}

TEST(SmallArg, MatchLongDoubleOnBothSidesOfTheirSeries) {
  for (double x : {0.3, 0.49, 0.5, 0.51, 0.9, 0.999, 1.0, 1.001, 1.5, 3.0, 10.0, 31.0}) {
    for (double sx : {x, -x}) {
      EXPECT_NEAR(XMinusSinOverCube(sx), static_cast<double>(SinCubeRef(sx)),
                  4e-15 * std::abs(static_cast<double>(SinCubeRef(sx))))
          << "x = " << sx;
      // Direct double form above |x| = 1 loses up to a factor 23 (small_arg.h): 23 eps ~ 5e-15.
      EXPECT_NEAR(MinusC2Derivative(sx), static_cast<double>(MinusC2DerivativeRef(sx)),
                  1e-14 * std::abs(static_cast<double>(MinusC2DerivativeRef(sx))))
          << "x = " << sx;
    }
  }
}

// Below that the references cancel too: the Taylor polynomials instead (-C2' = x/12 - x^3/180 +
// x^5/6720 - ..., (x - sin x)/x^3 = 1/6 - x^2/120 + x^4/5040 - x^6/362880 + ...), whose omitted
// terms are below 1e-17 relative for |x| <= 1e-2; 2e-16 relative allows the rounding of both sides.
TEST(SmallArg, SmallArgumentsFollowTheTaylorPolynomials) {
  for (double x : {1e-300, 1e-12, 1e-6, 1e-4, 1e-3, 1e-2}) {
    const double x2 = x * x;
    const double c2d = x * (1.0 / 12.0 - x2 / 180.0 + x2 * x2 / 6720.0);
    EXPECT_NEAR(MinusC2Derivative(x), c2d, 2e-16 * x) << "x = " << x;
    EXPECT_NEAR(MinusC2Derivative(-x), -c2d, 2e-16 * x) << "x = " << x;
    const double s3 = 1.0 / 6.0 - x2 / 120.0 + x2 * x2 / 5040.0 - x2 * x2 * x2 / 362880.0;
    EXPECT_NEAR(XMinusSinOverCube(x), s3, 2e-16 * s3) << "x = " << x;
  }
  EXPECT_EQ(MinusC2Derivative(0.0), 0.0);
}

}  // namespace
}  // namespace drillbif::internal
