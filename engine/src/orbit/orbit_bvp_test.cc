// OrbitBvp's parameter derivatives, one parameter or two in one pass of flows.
#include "orbit_bvp.h"

#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include "drillbif/flow/exact_propagator.h"
#include "problems/awkward_entries.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

// ProductOnColumns must give the bits of Eigen's product in the columns it is asked for (the
// Jacobian it feeds is factorized, and the continuation's results must not depend on how it was
// multiplied): compared bit for bit (signed zeros included) for every size of a state (n = 2..8)
// and every width up to 40 columns, across Eigen's switch from its coefficient-based to its
// general product, with random zero columns and entries that are exact zeros, negative zeros and
// cancelling values.
TEST(ProductOnColumns, GivesTheBitsOfEigensProduct) {
  testing::AwkwardEntries entry(11);
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
        if (!entry.Keep()) continue;
        columns.push_back(c);
        for (int i = 0; i < n; ++i) b(i, c) = entry();
      }
      Eigen::MatrixXd expected, got;
      expected.noalias() = a * b;
      internal::ProductOnColumns(a, b, columns, &got);
      ASSERT_EQ(got.rows(), n);
      ASSERT_EQ(got.cols(), m);
      for (int i = 0; i < n; ++i) {
        for (const int c : columns) {
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

// Bit patterns of a matrix's entries, for comparisons that tell -0 from +0 and NaN from NaN.
std::vector<uint64_t> Bits(const Eigen::Ref<const Eigen::MatrixXd>& a) {
  std::vector<uint64_t> bits;
  for (int j = 0; j < a.cols(); ++j) {
    for (int i = 0; i < a.rows(); ++i) bits.push_back(std::bit_cast<uint64_t>(a(i, j)));
  }
  return bits;
}

// dG/dX written into a block of a larger matrix holding NaN gives the bits of a fresh Evaluate
// (so every entry of the block is written, none left from before) and leaves the entries around
// the block alone; and an OrbitBvp that evaluated elsewhere first (its workspace holding that
// evaluation's values) gives the bits of a fresh one; those bits are dG/dX's.
TEST(OrbitBvp, JacobianIntoABlockHasTheBitsOfAFreshEvaluation) {
  DO model;
  ExactPropagator prop(model);
  const StatusOr<PeriodicOrbit> orbit =
      testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  ASSERT_TRUE(orbit.ok()) << orbit.status().ToString();
  const Eigen::VectorXd x0 =
      internal::OrbitBvp(model, prop, orbit->signature, DO::kOmega).Pack(*orbit);
  // Moved off the orbit so that the two evaluations' Jacobians differ in every segment.
  const Eigen::VectorXd x1 = x0 + 1e-3 * Eigen::VectorXd::Ones(x0.size());
  const int m = static_cast<int>(x0.size());

  const internal::OrbitBvp fresh(model, prop, orbit->signature, DO::kOmega);
  ASSERT_GE(fresh.segments(), 2) << "a single segment leaves the workspace reuse untested";
  Eigen::VectorXd g, gp;
  Eigen::MatrixXd expected;
  ASSERT_TRUE(fresh.Evaluate(x1, orbit->params, &g, &expected, &gp).ok());

  const internal::OrbitBvp reused(model, prop, orbit->signature, DO::kOmega);
  Eigen::VectorXd g0, gp0;
  Eigen::MatrixXd gx0;
  ASSERT_TRUE(reused.Evaluate(x0, orbit->params, &g0, &gx0, &gp0).ok());
  ASSERT_NE(Bits(gx0), Bits(expected));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  Eigen::MatrixXd big = Eigen::MatrixXd::Constant(m + 2, m + 3, nan);
  Eigen::VectorXd g1, gp1;
  ASSERT_TRUE(reused.EvaluateInto(x1, orbit->params, &g1, big.block(1, 2, m, m), &gp1).ok());
  EXPECT_EQ(Bits(big.block(1, 2, m, m)), Bits(expected));
  EXPECT_EQ(Bits(g1), Bits(g));
  EXPECT_EQ(Bits(gp1), Bits(gp));
  int untouched = 0;
  for (int j = 0; j < big.cols(); ++j) {
    for (int i = 0; i < big.rows(); ++i) {
      const bool inside = i >= 1 && i <= m && j >= 2 && j < m + 2;
      if (!inside && std::isnan(big(i, j))) ++untouched;
    }
  }
  EXPECT_EQ(untouched, (m + 2) * (m + 3) - m * m);
  // And the bits are dG/dX's: central differences of G in each unknown, with step
  // h = 1e-6 (1 + |x_j|) (truncation h^2 |G'''| / 6 and rounding eps |G| / h both below 1e-9
  // for these O(1)..O(10) quantities; asserted 1e-6 (1 + |dG/dX|), far below the O(1) error of
  // an entry left from another segment).
  const double scale = 1.0 + expected.lpNorm<Eigen::Infinity>();
  for (int j = 0; j < m; ++j) {
    const double h = 1e-6 * (1.0 + std::abs(x1[j]));
    Eigen::VectorXd plus = x1, minus = x1, gplus, gminus;
    plus[j] += h;
    minus[j] -= h;
    ASSERT_TRUE(fresh.Evaluate(plus, orbit->params, &gplus, nullptr, nullptr).ok());
    ASSERT_TRUE(fresh.Evaluate(minus, orbit->params, &gminus, nullptr, nullptr).ok());
    EXPECT_LE(((gplus - gminus) / (2.0 * h) - expected.col(j)).lpNorm<Eigen::Infinity>(),
              1e-6 * scale)
        << "column " << j;
  }
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
