// RunsAhead: what a switching round's later tasks see of the curves earlier runs traced.
#include "runs_ahead.h"

#include <gtest/gtest.h>

#include <thread>

namespace drillbif::internal {
namespace {

// A run whose one try traced a curve of `kind` through (v, 2 v) and (v + 1, 2 v), or failed.
CandidateRun RunOf(CurveKind kind, double v, bool failed = false) {
  CurveResult curve;
  curve.kind = kind;
  for (const double u : {v, v + 1.0}) {
    CurvePoint& p = curve.points.emplace_back();
    p.value1 = u, p.value2 = 2 * v;
  }
  curve.summary.termination = failed ? Termination::kFailed : Termination::kCompleted;
  CandidateRun run;
  run.tries.emplace_back(SpecialPoint{}, std::move(curve));
  return run;
}

// Whether a recorded curve starts at value1 = v (the outline is the curve's, in its order).
auto StartsAt(double v) {
  return [v](const TracedCurve& t) {
    return !t.outline.values1.empty() && t.outline.values1.front() == v;
  };
}

TEST(RunsAhead, AnItemSeesTheCurvesOfEarlierItemsOnly) {
  RunsAhead ahead;
  ahead.Add(3, RunOf(CurveKind::kFold, 0.5));
  EXPECT_TRUE(ahead.AnyBefore(4, StartsAt(0.5)));
  EXPECT_TRUE(ahead.AnyBefore(100, StartsAt(0.5)));
  EXPECT_FALSE(ahead.AnyBefore(3, StartsAt(0.5)));  // its own item's
  EXPECT_FALSE(ahead.AnyBefore(2, StartsAt(0.5)));
  EXPECT_FALSE(ahead.AnyBefore(4, StartsAt(0.25)));  // the predicate decides
}

TEST(RunsAhead, RecordsTheKindOutlineAndOnlyTriesThatTracedACurve) {
  RunsAhead ahead;
  ahead.Add(1, RunOf(CurveKind::kPeriodDoubling, 0.5, /*failed=*/true));
  CandidateRun empty = RunOf(CurveKind::kFold, 0.75);
  empty.tries.front().second.points.clear();
  ahead.Add(1, empty);
  EXPECT_FALSE(ahead.AnyBefore(2, [](const TracedCurve&) { return true; }));
  ahead.Add(1, RunOf(CurveKind::kGrazing, 0.5));
  EXPECT_TRUE(ahead.AnyBefore(2, [](const TracedCurve& t) {
    return t.curve.kind == CurveKind::kGrazing && t.outline.values1.size() == 2 &&
           t.outline.values2.front() == 1.0;
  }));
}

TEST(RunsAhead, CountsTheCurvesRecorded) {
  RunsAhead ahead;
  EXPECT_EQ(ahead.added(), 0u);
  ahead.Add(1, RunOf(CurveKind::kFold, 0.5, /*failed=*/true));
  EXPECT_EQ(ahead.added(), 0u);
  CandidateRun two = RunOf(CurveKind::kFold, 0.5);
  two.tries.push_back(RunOf(CurveKind::kFold, 0.75).tries.front());
  ahead.Add(2, two);
  EXPECT_EQ(ahead.added(), 2u);
  ahead.Applied(2);  // forgetting is no recording: the count stays
  EXPECT_EQ(ahead.added(), 2u);
}

TEST(RunsAhead, ForgetsTheItemsUpToTheOneApplied) {
  RunsAhead ahead;
  ahead.Add(1, RunOf(CurveKind::kFold, 0.5));
  ahead.Add(5, RunOf(CurveKind::kFold, 0.25));
  ahead.Applied(1);
  EXPECT_FALSE(ahead.AnyBefore(6, StartsAt(0.5)));
  EXPECT_TRUE(ahead.AnyBefore(6, StartsAt(0.25)));
  ahead.Applied(5);
  EXPECT_FALSE(ahead.AnyBefore(6, StartsAt(0.25)));
}

// Workers add while others check: a curve once seen stays seen until its item is applied, and
// every one added is there when the adding is done.
TEST(RunsAhead, AddsAndChecksFromSeveralThreads) {
  RunsAhead ahead;
  int lost = 0;  // checks that no longer saw the first item's curve after seeing it
  std::thread adder([&] {
    for (int item = 0; item < 200; ++item) ahead.Add(item, RunOf(CurveKind::kFold, item));
  });
  std::thread checker([&] {
    bool seen = false;
    for (int k = 0; k < 2000; ++k) {
      const bool now = ahead.AnyBefore(1000, StartsAt(0.0));
      lost += seen && !now ? 1 : 0;
      seen = seen || now;
    }
  });
  adder.join();
  checker.join();
  EXPECT_EQ(lost, 0);
  for (int item = 0; item < 200; ++item) {
    ASSERT_TRUE(ahead.AnyBefore(1000, StartsAt(item))) << item;
  }
  ahead.Applied(198);
  EXPECT_FALSE(ahead.AnyBefore(1000, StartsAt(0.0)));
  EXPECT_TRUE(ahead.AnyBefore(1000, StartsAt(199.0)));
}

}  // namespace
}  // namespace drillbif::internal
