// The located special point of a kind nearest a value of the continuation parameter, within a
// tolerance: how tests pick the point they start from on a branch.
#ifndef DRILLBIF_TESTS_SUPPORT_SPECIAL_POINT_NEAR_H_
#define DRILLBIF_TESTS_SUPPORT_SPECIAL_POINT_NEAR_H_

#include <cmath>

#include "drillbif/continuation/continuation.h"

namespace drillbif::testing {

// nullptr when no point of that kind lies within `tol` of `value`.
inline const SpecialPoint* SpecialPointNear(const ContinuationResult& r, SpecialPointKind kind,
                                            double value, double tol) {
  const SpecialPoint* best = nullptr;
  for (const SpecialPoint& s : r.special_points) {
    if (s.kind != kind || std::abs(s.point.value - value) > tol) continue;
    if (!best || std::abs(s.point.value - value) < std::abs(best->point.value - value)) best = &s;
  }
  return best;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_SPECIAL_POINT_NEAR_H_
