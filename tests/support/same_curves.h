// Two traces' curves compared: the same kind, start, message, and every point's and
// codimension-2 point's parameters to the bit (a trace on threads or on a task runner against
// one thread).
#ifndef DRILLBIF_TESTS_SUPPORT_SAME_CURVES_H_
#define DRILLBIF_TESTS_SUPPORT_SAME_CURVES_H_

#include <gtest/gtest.h>

#include "drillbif/continuation/trace.h"
#include "support/same_bits.h"

namespace drillbif::testing {

// The same curve: kind, start, message, and every point's and codimension-2 point's parameters
// to the bit.
inline void ExpectSameCurve(const TracedCurve& a, const TracedCurve& b, int index) {
  EXPECT_EQ(a.curve.kind, b.curve.kind) << index;
  EXPECT_EQ(a.start.kind, b.start.kind) << index;
  EXPECT_EQ(a.from_curve, b.from_curve) << index;
  EXPECT_EQ(a.curve.summary.message, b.curve.summary.message) << index;
  ASSERT_EQ(a.curve.points.size(), b.curve.points.size()) << index;
  for (size_t k = 0; k < a.curve.points.size(); ++k) {
    EXPECT_TRUE(SameBits(a.curve.points[k].value1, b.curve.points[k].value1) &&
                SameBits(a.curve.points[k].value2, b.curve.points[k].value2))
        << index << " " << k;
  }
  ASSERT_EQ(a.curve.codim2.size(), b.curve.codim2.size()) << index;
  for (size_t k = 0; k < a.curve.codim2.size(); ++k) {
    EXPECT_EQ(a.curve.codim2[k].kind, b.curve.codim2[k].kind) << index << " " << k;
    EXPECT_EQ(a.curve.codim2[k].detail, b.curve.codim2[k].detail) << index << " " << k;
    EXPECT_TRUE(SameBits(a.curve.codim2[k].point.value1, b.curve.codim2[k].point.value1))
        << index << " " << k;
  }
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_SAME_CURVES_H_
