// How SolveWithConditions (tangent_grazing.h) ends where its Newton converges only linearly: at
// a root of order p of its condition Newton's steps shrink by 1 - 1/p each, so the number of
// iterations its tolerance needs is known in advance from the order and the first distance.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "../orbit/orbit_bvp.h"  // the engine's internal headers, by their path from here
#include "support/reference_orbit_test.h"
#include "tangent_grazing.h"

namespace drillbif {
namespace {

using internal::ExtraCondition;

// The reference orbit with a free, held by the condition (a - target)^order = 0: the orbit of
// a = target, a root of that order. `evaluations` counts the condition's evaluations.
class LinearConvergence : public testing::ReferenceOrbitTest {
 protected:
  StatusOr<PeriodicOrbit> Solve(int order, double distance, int* evaluations) {
    const int a = model_.ParamIndex("a").value();
    const double target = start_.params[a] + distance;
    const ExtraCondition condition =
        ExtraCondition::OfOrbit([a, target, order, evaluations](const PeriodicOrbit& o) {
          ++*evaluations;
          return std::pow(o.params[a] - target, order);
        });
    return internal::SolveWithConditions(model_, prop_, start_, {a}, {condition}, 1e-12,
                                         "test system");
  }

  internal::OrbitBvp Bvp() {
    return internal::OrbitBvp(model_, prop_, start_.signature, model_.ParamIndex("a").value());
  }

  // The condition's evaluations per Newton iteration: its value, and two per column of its row
  // (central differences over the orbit's unknowns and a; ConditionRow).
  int EvaluationsPerIteration() { return 1 + 2 * (Bvp().size() + 1); }
};

// A root of order 4: steps shrink by 0.75 each, and from 1e-3 away the 1e-12 tolerance would
// take ~70 iterations of the 30. The solve is given up once five steps have shown that ratio
// (after at most 8 iterations: the first may differ, the orbit's own correction to the moved
// parameter). The stagnation test alone did not stop it before its 30th iteration: 0.75^8 =
// 0.1001 lies at the edge of the tenfold shrinking over 8 iterations that test asks for.
TEST_F(LinearConvergence, AQuarticRootIsGivenUpOnceItsRatioShows) {
  int evaluations = 0;
  const StatusOr<PeriodicOrbit> solved = Solve(4, 1e-3, &evaluations);
  ASSERT_FALSE(solved.ok());
  EXPECT_NE(solved.status().message().find("stagnated"), std::string::npos)
      << solved.status().ToString();
  const int iterations = evaluations / EvaluationsPerIteration();
  EXPECT_EQ(evaluations % EvaluationsPerIteration(), 0);
  EXPECT_GE(iterations, 6);
  EXPECT_LE(iterations, 8);
}

// A double root: steps halve, and from 1e-5 away the tolerance takes ~25 iterations. Such a
// phase (a fixed-length orbit's Newton halving its step towards a tangent end's double root) is
// not cut short: the ratio 0.5 lies below the linear test's 0.7.
TEST_F(LinearConvergence, ADoubleRootIsSolvedByHalvingSteps) {
  int evaluations = 0;
  const StatusOr<PeriodicOrbit> solved = Solve(2, 1e-5, &evaluations);
  ASSERT_TRUE(solved.ok()) << solved.status().ToString();
  const int a = model_.ParamIndex("a").value();
  // Newton's last step, at most 1e-12 (1 + |y|) (y: the orbit's unknowns and a, which move by
  // 1e-5 at most), is the distance it leaves to the root, halving each step; twofold margin.
  const double scale =
      1.0 + std::max(Bvp().Pack(start_).lpNorm<Eigen::Infinity>(), std::abs(start_.params[a])) +
      1e-5;
  EXPECT_NEAR(solved->params[a], start_.params[a] + 1e-5, 2e-12 * scale);
  // Halving from 1e-5 to the tolerance takes log2(1e-5 / (1e-12 scale)) iterations.
  EXPECT_GE(evaluations / EvaluationsPerIteration(),
            static_cast<int>(std::log2(1e-5 / (1e-12 * scale))));
}

}  // namespace
}  // namespace drillbif
