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

}  // namespace drillbif::internal

#endif  // DRILLBIF_COMMON_SMALL_ARG_H_
