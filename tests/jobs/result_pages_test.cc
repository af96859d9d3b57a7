// KeepRepeatedRange: the items kept, in order, for every range of a short repeated field, and
// ranges beyond the items there are clamped.
#include "jobs/result_pages.h"

#include <gtest/gtest.h>

#include <cstdint>

#include "drillbif/v1/sweep.pb.h"

namespace drillbif::jobs {
namespace {

v1::SweepResult WithUpValues(int n) {
  v1::SweepResult r;
  for (int i = 0; i < n; ++i) r.add_up()->set_value(i);
  r.add_down()->set_value(-1.0);
  return r;
}

// Every [lo, hi) of 0 .. 6 items keeps exactly the values lo .. hi - 1 in order, and leaves the
// other repeated field alone.
TEST(KeepRepeatedRange, KeepsEveryRangeInOrder) {
  const auto* field = v1::SweepResult::descriptor()->FindFieldByName("up");
  for (int n = 0; n <= 6; ++n) {
    for (int lo = 0; lo <= n; ++lo) {
      for (int hi = lo; hi <= n; ++hi) {
        v1::SweepResult r = WithUpValues(n);
        KeepRepeatedRange(field, lo, hi, &r);
        ASSERT_EQ(r.up_size(), hi - lo) << n << " [" << lo << ", " << hi << ")";
        for (int i = 0; i < hi - lo; ++i) EXPECT_EQ(r.up(i).value(), lo + i);
        EXPECT_EQ(r.down_size(), 1);
      }
    }
  }
}

// A range past the items (a chunk that declares more items than it holds) keeps what there is.
TEST(KeepRepeatedRange, ClampsARangeBeyondTheItems) {
  const auto* field = v1::SweepResult::descriptor()->FindFieldByName("up");
  v1::SweepResult r = WithUpValues(4);
  KeepRepeatedRange(field, 2, int64_t{1} << 40, &r);
  ASSERT_EQ(r.up_size(), 2);
  EXPECT_EQ(r.up(0).value(), 2);
  EXPECT_EQ(r.up(1).value(), 3);
  v1::SweepResult s = WithUpValues(3);
  KeepRepeatedRange(field, 5, 9, &s);
  EXPECT_EQ(s.up_size(), 0);
}

}  // namespace
}  // namespace drillbif::jobs
