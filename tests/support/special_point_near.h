// The located special point of a kind nearest a value of the continuation parameter, within a
// tolerance: how tests pick the point they start from on a branch.
#ifndef DRILLBIF_TESTS_SUPPORT_SPECIAL_POINT_NEAR_H_
#define DRILLBIF_TESTS_SUPPORT_SPECIAL_POINT_NEAR_H_

#include <gtest/gtest.h>

#include <cmath>
#include <string>

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

// Two runs of one branch locate the same special points: as many, each of either within `tol` of
// one of the same kind of the other. `name_a` / `name_b` say which run is which in a failure.
inline void ExpectSameSpecialPoints(const ContinuationResult& a, const std::string& name_a,
                                    const ContinuationResult& b, const std::string& name_b,
                                    double tol) {
  EXPECT_EQ(a.special_points.size(), b.special_points.size());
  for (const SpecialPoint& p : a.special_points) {
    EXPECT_NE(SpecialPointNear(b, p.kind, p.point.value, tol), nullptr)
        << SpecialPointKindName(p.kind) << " at " << p.point.value << " only " << name_a;
  }
  for (const SpecialPoint& p : b.special_points) {
    EXPECT_NE(SpecialPointNear(a, p.kind, p.point.value, tol), nullptr)
        << SpecialPointKindName(p.kind) << " at " << p.point.value << " only " << name_b;
  }
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_SPECIAL_POINT_NEAR_H_
