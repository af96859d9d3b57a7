// Functions with removable singularities at 0, evaluated without cancellation for small arguments.
// They make the closed-form flows exact and robust as omega * t -> 0 (slow forcing, short steps).
#ifndef DRILLBIF_COMMON_SMALL_ARG_H_
#define DRILLBIF_COMMON_SMALL_ARG_H_

#include <cmath>

namespace drillbif::internal {

// (x - sin x) / x^3. Taylor series below |x| = 0.5 (the x^14 term is < 1e-16 relative there);
// above, the direct form loses at most a factor 6/x^2 <= 25 of precision (about 5e-15 relative).
inline double XMinusSinOverCube(double x) {
  const double x2 = x * x;
  if (x2 < 0.25) {
    // 1/3! - x^2/5! + x^4/7! - ... + x^12/15!, Horner.
    return (1.0 / 6.0) +
           x2 * (-1.0 / 120.0 +
                 x2 * (1.0 / 5040.0 +
                       x2 * (-1.0 / 362880.0 +
                             x2 * (1.0 / 39916800.0 +
                                   x2 * (-1.0 / 6227020800.0 + x2 * (1.0 / 1307674368000.0))))));
  }
  return (x - std::sin(x)) / (x2 * x);
}

// -(d/dx) C2(x) with C2(x) = (1 - cos x) / x^2, i.e. (2 C2(x) - sin(x)/x) / x = the integral of
// (1 - u) u sin(x u) over [0, 1]. Odd, ~ x / 12. Series below |x| = 1 (sum_k (-1)^k x^(2k+1) /
// ((2k+1)! (2k+3)(2k+4)); the k = 9 term is < 1e-20 there); above, the direct form loses at most
// a factor (2 C2 + sinc) / |2 C2 - sinc| <= 23 of precision (at |x| = 1).
inline double MinusC2Derivative(double x) {
  const double x2 = x * x;
  if (x2 < 1.0) {
    double sum = 0.0, term = x;  // x^(2k+1) / (2k+1)!
    for (int k = 0; k < 10; ++k) {
      sum += term / ((2.0 * k + 3.0) * (2.0 * k + 4.0));
      term *= -x2 / ((2.0 * k + 2.0) * (2.0 * k + 3.0));
    }
    return sum;
  }
  const double sh = std::sin(0.5 * x);
  const double c2 = 2.0 * (sh / x) * (sh / x);
  return (2.0 * c2 - std::sin(x) / x) / x;
}

}  // namespace drillbif::internal

#endif  // DRILLBIF_COMMON_SMALL_ARG_H_
