// A branch run by direction (continuation/directions.h) and joined is Continue's, bit for bit:
// on two threads with a propagator each, when the first direction ends the branch, and when the
// start is refused.
#include "continuation/directions.h"

#include <gtest/gtest.h>

#include <memory>
#include <thread>
#include <utility>
#include <vector>

#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif::internal {
namespace {

using DO = DriftingOscillator;

// Every point, special point and count of the two results equal, to the bit.
void ExpectSameBranch(const ContinuationResult& a, const ContinuationResult& b) {
  EXPECT_EQ(a.summary.termination, b.summary.termination);
  EXPECT_EQ(a.summary.status.code(), b.summary.status.code());
  EXPECT_EQ(a.summary.message, b.summary.message);
  EXPECT_EQ(a.summary.steps, b.summary.steps);
  EXPECT_EQ(a.summary.rejected_steps, b.summary.rejected_steps);
  EXPECT_EQ(a.summary.newton_iterations, b.summary.newton_iterations);
  ASSERT_EQ(a.points.size(), b.points.size());
  for (size_t k = 0; k < a.points.size(); ++k) {
    const ContinuationPoint &p = a.points[k], &q = b.points[k];
    EXPECT_EQ(p.value, q.value) << "point " << k;
    EXPECT_EQ(p.orbit.durations, q.orbit.durations) << "point " << k;
    ASSERT_EQ(p.orbit.starts.size(), q.orbit.starts.size());
    for (size_t i = 0; i < p.orbit.starts.size(); ++i) {
      EXPECT_EQ(p.orbit.starts[i], q.orbit.starts[i]) << "point " << k << ", segment " << i;
    }
    EXPECT_EQ(p.stability.multipliers, q.stability.multipliers) << "point " << k;
    EXPECT_EQ(p.measures, q.measures) << "point " << k;
  }
  ASSERT_EQ(a.special_points.size(), b.special_points.size());
  for (size_t k = 0; k < a.special_points.size(); ++k) {
    const SpecialPoint &s = a.special_points[k], &t = b.special_points[k];
    EXPECT_EQ(s.kind, t.kind) << "special point " << k;
    EXPECT_EQ(s.point.value, t.point.value) << "special point " << k;
    EXPECT_EQ(s.near_grazing.near, t.near_grazing.near) << "special point " << k;
    EXPECT_EQ(s.near_grazing.distance, t.near_grazing.distance) << "special point " << k;
  }
}

class DirectionsTest : public ::testing::Test {
 protected:
  DirectionsTest() {
    StatusOr<PeriodicOrbit> orbit =
        drillbif::testing::SolvedOrbitFromRest(model_, prop_, drillbif::testing::ReferenceParams());
    EXPECT_TRUE(orbit.ok()) << orbit.status().ToString();
    if (orbit.ok()) start_ = *std::move(orbit);
    // The reference b-branch over [0, 0.2]: folds, period doublings and grazings both ways.
    options_.param = "b";
    options_.min = 0.0;
    options_.max = 0.2;
  }

  DO model_;
  ExactPropagator prop_{model_};
  PeriodicOrbit start_;
  ContinuationOptions options_;
};

TEST_F(DirectionsTest, BothWaysOnTwoThreadsJoinToContinuesResult) {
  ASSERT_EQ(DirectionCount(options_), 2u);
  const ContinuationResult whole = Continue(model_, prop_, start_, options_);
  ASSERT_EQ(whole.summary.termination, Termination::kCompleted) << whole.summary.message;
  ASSERT_GE(whole.special_points.size(), 4u);
  std::vector<BranchDirection> runs(2);
  std::vector<std::unique_ptr<Propagator>> props;
  std::vector<std::thread> threads;
  for (size_t d = 0; d < 2; ++d) props.push_back(prop_.Clone());
  for (size_t d = 0; d < 2; ++d) {
    threads.emplace_back(
        [&, d] { runs[d] = ContinueDirection(model_, *props[d], start_, options_, d); });
  }
  for (std::thread& t : threads) t.join();
  EXPECT_EQ(runs[0].sign, 1);
  EXPECT_EQ(runs[1].sign, -1);
  ExpectSameBranch(JoinDirections(std::move(runs)), whole);
}

TEST_F(DirectionsTest, OneWayIsOneDirection) {
  options_.direction = ContinuationDirection::kDecreasing;
  ASSERT_EQ(DirectionCount(options_), 1u);
  const ContinuationResult whole = Continue(model_, prop_, start_, options_);
  std::vector<BranchDirection> runs;
  runs.push_back(ContinueDirection(model_, prop_, start_, options_, 0));
  EXPECT_EQ(runs[0].sign, -1);
  ExpectSameBranch(JoinDirections(std::move(runs)), whole);
}

// Stopped by its callback in the first direction, Continue never runs the second; run anyway, the
// second is not read.
TEST_F(DirectionsTest, ADirectionThatEndsTheBranchLeavesTheNextUnread) {
  int calls = 0;
  const ContinuationCallback stop_at_ten = [&](const ContinuationPoint&, double) {
    return ++calls < 10;
  };
  const ContinuationResult whole = Continue(model_, prop_, start_, options_, stop_at_ten);
  ASSERT_EQ(whole.summary.termination, Termination::kCancelled);
  calls = 0;
  std::vector<BranchDirection> runs;
  runs.push_back(ContinueDirection(model_, prop_, start_, options_, 0, stop_at_ten));
  runs.push_back(ContinueDirection(model_, prop_, start_, options_, 1));
  EXPECT_TRUE(runs[0].cancelled);
  EXPECT_FALSE(runs[1].cancelled);
  EXPECT_GT(runs[1].part.points.size(), 0u);
  ExpectSameBranch(JoinDirections(std::move(runs)), whole);
}

TEST_F(DirectionsTest, ARefusedStartIsContinuesFailure) {
  options_.max = 0.1;  // the start's b = 0.15 lies outside
  const ContinuationResult whole = Continue(model_, prop_, start_, options_);
  ASSERT_EQ(whole.summary.termination, Termination::kFailed);
  std::vector<BranchDirection> runs;
  for (size_t d = 0; d < 2; ++d) {
    runs.push_back(ContinueDirection(model_, prop_, start_, options_, d));
    EXPECT_TRUE(runs.back().refused.has_value());
  }
  const ContinuationResult joined = JoinDirections(std::move(runs));
  ExpectSameBranch(joined, whole);
  EXPECT_EQ(joined.summary.status.message(), whole.summary.status.message());
}

}  // namespace
}  // namespace drillbif::internal
