// ProgressThrottle (common/include/drillbif/common/progress.h): when the callback is called, how a
// stop is remembered, how fractions are recorded.
#include "drillbif/common/progress.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <vector>

namespace drillbif {
namespace {

using std::chrono::milliseconds;
constexpr auto kHour = std::chrono::hours(1);

TEST(ProgressThrottle, WithoutACallbackNeverStopsUnlessAsked) {
  ProgressThrottle t;
  for (int i = 0; i < 1000; ++i) EXPECT_TRUE(t.Continue(i / 1000.0));
  EXPECT_TRUE(t.Tick());
  EXPECT_FALSE(t.stopped());
  EXPECT_EQ(t.calls(), 0);
  t.Stop();
  EXPECT_TRUE(t.stopped());
  EXPECT_FALSE(t.Continue());
  EXPECT_FALSE(t.Tick());
}

// With the clock out of the way (an interval of an hour), the callback is called exactly when the
// fraction reaches each multiple of the step: 100 calls for a fraction going 0 -> 1 in 1000 steps.
TEST(ProgressThrottle, CallsAtEveryFractionStep) {
  std::vector<double> seen;
  ProgressThrottle t(
      [&](double f) {
        seen.push_back(f);
        return true;
      },
      kHour, 0.01);
  for (int i = 1; i <= 1000; ++i) ASSERT_TRUE(t.Tick(i / 1000.0));
  ASSERT_EQ(seen.size(), 100u);
  for (size_t k = 0; k < seen.size(); ++k) {
    // The first poll at or past (k + 1) / 100.
    EXPECT_NEAR(seen[k], (k + 1) / 100.0, 1e-12) << k;
  }
  EXPECT_EQ(t.calls(), 100);
}

// A callback that returns false stops the throttle for good: no further call, every poll false.
TEST(ProgressThrottle, RemembersAStop) {
  int calls = 0;
  ProgressThrottle t([&](double) { return ++calls < 3; }, kHour, 0.25);
  int polls_true = 0;
  for (int i = 1; i <= 100; ++i) polls_true += t.Continue(i / 100.0) ? 1 : 0;
  EXPECT_EQ(calls, 3);  // at 0.25, 0.5 and 0.75, which stopped it
  EXPECT_EQ(polls_true, 74);
  EXPECT_TRUE(t.stopped());
  EXPECT_FALSE(t.Continue(1.0));
  EXPECT_EQ(calls, 3);
}

// The recorded fraction never goes back, ignores NaN and is clamped to 1.
TEST(ProgressThrottle, FractionIsMonotoneAndClamped) {
  ProgressThrottle t([](double) { return true; }, kHour, 0.0);
  t.Continue(0.5);
  t.Continue(0.2);
  EXPECT_EQ(t.fraction(), 0.5);
  t.Continue(std::numeric_limits<double>::quiet_NaN());
  EXPECT_EQ(t.fraction(), 0.5);
  t.Continue(7.0);
  EXPECT_EQ(t.fraction(), 1.0);
  EXPECT_EQ(t.calls(), 0);  // no step, and an hour has not passed
}

// Tick() reads the clock every kTickStride-th call only: with a zero interval every clock read
// makes a call, so 10 strides of Tick() make 10 calls and Continue() one each.
TEST(ProgressThrottle, TickReadsTheClockEveryStride) {
  ProgressThrottle t([](double) { return true; }, milliseconds(0), 0.0);
  for (int i = 0; i < 10 * ProgressThrottle::kTickStride; ++i) t.Tick();
  EXPECT_EQ(t.calls(), 10);
  for (int i = 0; i < 5; ++i) t.Continue();
  EXPECT_EQ(t.calls(), 15);
}

// On the clock alone (no fraction step) the callback is never called twice within the interval,
// and, polled continuously, at least once in every few intervals. The lower bound is loose
// (a quarter of the intervals elapsed) because a loaded machine can deschedule the polling
// thread for whole intervals; the upper bound is exact (elapsed / interval, plus the first).
TEST(ProgressThrottle, CallsAtMostOncePerInterval) {
  using Clock = std::chrono::steady_clock;
  std::vector<Clock::time_point> at;
  const milliseconds interval(5);
  ProgressThrottle t(
      [&](double) {
        at.push_back(Clock::now());
        return true;
      },
      interval, 0.0);
  const Clock::time_point start = Clock::now();
  while (Clock::now() - start < milliseconds(100)) t.Continue();
  const double elapsed_intervals = (Clock::now() - start) / std::chrono::duration<double>(interval);
  ASSERT_GE(at.size(), 2u);
  for (size_t k = 1; k < at.size(); ++k) EXPECT_GE(at[k] - at[k - 1], interval) << k;
  EXPECT_LE(static_cast<double>(at.size()), elapsed_intervals + 1.0);
  EXPECT_GE(static_cast<double>(at.size()), elapsed_intervals / 4.0);
}

}  // namespace
}  // namespace drillbif
