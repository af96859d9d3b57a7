// The distance of an orbit's nearest nontrivial multiplier to a target (+1 at a fold, -1 at a
// period doubling): how tests check the fold / PD condition of a located point.
#ifndef DRILLBIF_TESTS_SUPPORT_MULTIPLIERS_H_
#define DRILLBIF_TESTS_SUPPORT_MULTIPLIERS_H_

#include <algorithm>
#include <complex>
#include <limits>

#include "drillbif/orbit/periodic_orbit.h"

namespace drillbif::testing {

// Infinity when the orbit has no nontrivial multiplier.
inline double DistanceToMultiplier(const Stability& st, double target) {
  double closest = std::numeric_limits<double>::infinity();
  for (const std::complex<double>& mu : st.multipliers) {
    closest = std::min(closest, std::abs(mu - target));
  }
  return closest;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_MULTIPLIERS_H_
