// Neimark-Sacker detection and location on a problem with a closed-form answer: the forced linear
// rotation of tests/problems/forced_rotation.h has multipliers exp((mu +- i) T), a complex pair
// crossing the unit circle at mu = 0.
#include <gtest/gtest.h>

#include <cmath>

#include "drillbif/continuation/continuation.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/forced_rotation.h"

namespace drillbif {
namespace {

using testing::ForcedRotation;

TEST(NeimarkSacker, LocatedWhereTheComplexPairCrossesTheUnitCircle) {
  ForcedRotation model;
  ExactPropagator prop(model);
  // Start: the forced orbit at mu = -0.05 from a rough guess (one segment ending at the section).
  PeriodicOrbit start;
  start.params = ForcedRotation::MakeParams(-0.05);
  start.signature.periods = 1;
  start.signature.segments = {{0, -1}};
  start.starts = {(StateVector(3) << 0.0, 0.0, 0.0).finished()};
  start.durations = {kTwoPi / start.params[ForcedRotation::kOmega]};
  ASSERT_EQ(SolveOrbit(model, prop, {}, &start).status, SolveStatus::kConverged);
  const Stability st0 = OrbitStability(model, prop, start);
  ASSERT_EQ(st0.multipliers.size(), 2u);
  const double period = start.durations[0];
  // |mu_i| = exp(mu T) to rounding of the matrix exponential (~1e-13 relative here).
  EXPECT_NEAR(std::abs(st0.multipliers[0]), std::exp(-0.05 * period), 1e-12);
  EXPECT_TRUE(st0.stable);

  ContinuationOptions opt;
  opt.param = "mu";
  opt.min = -0.05;
  opt.max = 0.05;
  opt.direction = ContinuationDirection::kIncreasing;
  const ContinuationResult r = Continue(model, prop, start, opt);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.message;
  int ns = 0;
  for (const SpecialPoint& s : r.special_points) {
    if (s.kind != SpecialPointKind::kNeimarkSacker) continue;
    ++ns;
    // Located to 1e-10 in the parameter; at mu = 0 the pair sits on the unit circle.
    EXPECT_NEAR(s.point.value, 0.0, 1e-10);
    ASSERT_EQ(s.point.stability.multipliers.size(), 2u);
    for (const auto& mu : s.point.stability.multipliers) {
      EXPECT_NEAR(std::abs(mu), 1.0, 1e-9);
      EXPECT_GT(std::abs(mu.imag()), 0.1);
    }
  }
  EXPECT_EQ(ns, 1);
  EXPECT_FALSE(r.points.back().stability.stable);
}

}  // namespace
}  // namespace drillbif
