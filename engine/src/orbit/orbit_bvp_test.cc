// OrbitBvp's parameter derivatives, one parameter or two in one pass of flows.
#include "orbit_bvp.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

// ProductOnColumns must give the bits of Eigen's product (the Jacobian it feeds is factorized,
// and the continuation's results must not depend on how it was multiplied): compared bit for bit
// (signed zeros included) for every size of a state (n = 2..8) and every width up to 40 columns,
// across Eigen's switch from its coefficient-based to its general product, with random zero
// columns and entries that are exact zeros, negative zeros and cancelling values.
TEST(ProductOnColumns, GivesTheBitsOfEigensProduct) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<double> u(-1.0, 1.0);
  std::uniform_int_distribution<int> pick(0, 9);
  auto entry = [&]() {
    switch (pick(rng)) {
      case 0:
        return 0.0;
      case 1:
        return -0.0;
      case 2:
        return 1.0;
      default:
        return u(rng) * std::pow(10.0, 4.0 * u(rng));
    }
  };
  int compared = 0;
  for (int n = 2; n <= 8; ++n) {
    for (int m = 1; m <= 40; ++m) {
      StateMatrix a(n, n);
      for (int i = 0; i < n; ++i) {
        for (int j = 0; j < n; ++j) a(i, j) = entry();
      }
      Eigen::MatrixXd b = Eigen::MatrixXd::Zero(n, m);
      std::vector<int> columns;
      for (int c = 0; c < m; ++c) {
        if (pick(rng) < 4) continue;
        columns.push_back(c);
        for (int i = 0; i < n; ++i) b(i, c) = entry();
      }
      Eigen::MatrixXd expected, got;
      expected.noalias() = a * b;
      internal::ProductOnColumns(a, b, columns, &got);
      ASSERT_EQ(got.rows(), n);
      ASSERT_EQ(got.cols(), m);
      for (int i = 0; i < n; ++i) {
        for (int c = 0; c < m; ++c) {
          ASSERT_EQ(std::bit_cast<uint64_t>(got(i, c)), std::bit_cast<uint64_t>(expected(i, c)))
              << "n " << n << " m " << m << " entry (" << i << ", " << c << "): " << got(i, c)
              << " against " << expected(i, c);
          ++compared;
        }
      }
    }
  }
  EXPECT_GT(compared, 0);
}

class OrbitBvpTest : public ::testing::TestWithParam<std::pair<int, int>> {};

// The two-parameter evaluation gives each column as the one-parameter one does (the same
// arithmetic: to rounding), and both agree with central differences of G in that parameter:
// with step h = 1e-6 (1 + |p|) truncation h^2 |G'''| / 6 and rounding eps |G| / h are both
// below 1e-9 for these O(1)..O(10) quantities; asserted 1e-7 (1 + |dG/dp|).
TEST_P(OrbitBvpTest, TwoParameterDerivativesMatchOneAtATimeAndDifferences) {
  DO model;
  ExactPropagator prop(model);
  const StatusOr<PeriodicOrbit> orbit =
      testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  ASSERT_TRUE(orbit.ok()) << orbit.status().ToString();
  const auto [p1, p2] = GetParam();
  const internal::OrbitBvp both(model, prop, orbit->signature, p1, p2);
  const Eigen::VectorXd x = both.Pack(*orbit);
  Eigen::VectorXd g, gp1, gp2;
  Eigen::MatrixXd gx;
  ASSERT_TRUE(both.Evaluate(x, orbit->params, &g, &gx, &gp1, &gp2).ok());
  for (const auto& [index, column] : {std::pair{p1, &gp1}, std::pair{p2, &gp2}}) {
    const internal::OrbitBvp one(model, prop, orbit->signature, index);
    Eigen::VectorXd g1, gp;
    ASSERT_TRUE(one.Evaluate(x, orbit->params, &g1, nullptr, &gp).ok());
    EXPECT_LE((gp - *column).lpNorm<Eigen::Infinity>(),
              1e-14 * (1.0 + gp.lpNorm<Eigen::Infinity>()))
        << model.param_names()[index];
    const double h = 1e-6 * (1.0 + std::abs(orbit->params[index]));
    Params plus = orbit->params, minus = orbit->params;
    plus[index] += h;
    minus[index] -= h;
    Eigen::VectorXd gplus, gminus;
    ASSERT_TRUE(one.Evaluate(x, plus, &gplus, nullptr, nullptr).ok());
    ASSERT_TRUE(one.Evaluate(x, minus, &gminus, nullptr, nullptr).ok());
    const Eigen::VectorXd fd = (gplus - gminus) / (2.0 * h);
    EXPECT_LE((fd - *column).lpNorm<Eigen::Infinity>(),
              1e-7 * (1.0 + column->lpNorm<Eigen::Infinity>()))
        << model.param_names()[index];
  }
}

// (omega, a) as the reference box's curves; (a, xi) with xi's derivative by Van Loan in contact.
INSTANTIATE_TEST_SUITE_P(Pairs, OrbitBvpTest,
                         ::testing::Values(std::pair{DO::kOmega, DO::kA},
                                           std::pair{DO::kA, DO::kXi}, std::pair{DO::kB, DO::kG}));

}  // namespace
}  // namespace drillbif
