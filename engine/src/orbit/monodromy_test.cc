// The monodromy factor from a given flow (FactorFromFlow): for a model with a LinearForm, moving
// a segment's start in its non-phase part by dx moves the end by Phi dx and leaves Phi as it is,
// so the factor at the moved start is FactorFromFlow at the moved end with the same Phi. The
// curve tracer's sigma row relies on it (continuation/curve.cc).
#include "monodromy.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "problems/awkward_entries.h"
#include "support/reference_orbit_test.h"

namespace drillbif {
namespace {

using Monodromy = testing::ReferenceOrbitTest;

// At every segment of the reference orbit (impact, contact, progression, flight: each mode and
// guard) and for each non-phase state component, a start moved by 1e-2 (far beyond any
// difference step, so that a flow Jacobian depending on the start would show at O(1e-2)): the
// factor recomputed from the moved start and FactorFromFlow at the moved end agree to rounding,
// 1e-11 (1 + |F|) (both are sums of O(|F|) terms computed to ~1e-15 relative, the moved end
// from Phi dx as well). Unmoved, FactorFromFlow is SegmentFactor.
TEST_F(Monodromy, FactorFromAnAffineFlowIsTheFactorAtTheMovedStart) {
  ASSERT_NE(dynamic_cast<const LinearForm*>(&model_), nullptr);
  const int n = model_.state_dim();
  double largest_change = 0.0;
  for (int i = 0; i < static_cast<int>(start_.durations.size()); ++i) {
    FlowRequest req;
    req.state_jacobian = true;
    const FlowResult fr = prop_.FlowMap(start_.signature.segments[i].mode, start_.starts[i],
                                        start_.durations[i], start_.params, req);
    const StateMatrix base = internal::SegmentFactor(model_, prop_, start_, i);
    EXPECT_LE((internal::FactorFromFlow(model_, start_, i, fr.x, fr.state_jacobian) - base)
                  .lpNorm<Eigen::Infinity>(),
              1e-14 * (1.0 + base.lpNorm<Eigen::Infinity>()))
        << "segment " << i;
    for (int j = 0; j < n; ++j) {
      if (j == model_.phase_index()) continue;
      PeriodicOrbit moved = start_;
      moved.starts[i][j] += 1e-2;
      const StateMatrix full = internal::SegmentFactor(model_, prop_, moved, i);
      const StateVector x_end = fr.x + 1e-2 * fr.state_jacobian.col(j);
      const StateMatrix shortcut =
          internal::FactorFromFlow(model_, start_, i, x_end, fr.state_jacobian);
      EXPECT_LE((full - shortcut).lpNorm<Eigen::Infinity>(),
                1e-11 * (1.0 + full.lpNorm<Eigen::Infinity>()))
          << "segment " << i << ", component " << j;
      largest_change = std::max(largest_change, (full - base).lpNorm<Eigen::Infinity>());
    }
  }
  // Not vacuous: the moves do change factors (the saltation depends on the end state), by far
  // more than the agreement asserted above.
  EXPECT_GT(largest_change, 1e-6);
  // MonodromyFactors keeping the flows gives the same factors, and the flows they came from.
  std::vector<FlowResult> flows;
  const std::vector<StateMatrix> kept = internal::MonodromyFactors(model_, prop_, start_, &flows);
  const std::vector<StateMatrix> plain = internal::MonodromyFactors(model_, prop_, start_);
  ASSERT_EQ(flows.size(), plain.size());
  for (size_t i = 0; i < plain.size(); ++i) {
    EXPECT_EQ(kept[i], plain[i]) << "segment " << i;
    EXPECT_EQ(internal::FactorFromFlow(model_, start_, static_cast<int>(i), flows[i].x,
                                       flows[i].state_jacobian),
              plain[i])
        << "segment " << i;
  }
}

// FactorFromFlow multiplies S Phi at fixed size for a 4-dimensional state; the factors must not
// depend on that, so at every segment of the reference orbit, with its own flow Jacobian and with
// random ones (entries of either sign over several decades, where a different order of the sums
// would show in the last bits), it is compared bit for bit with the generic saltation times Phi
// as a dynamic-size product.
TEST_F(Monodromy, FactorFromFlowIsTheGenericSaltationTimesTheFlowBitForBit) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> mantissa(-1.0, 1.0), decade(-3.0, 3.0);
  int salted = 0;
  for (int i = 0; i < static_cast<int>(start_.durations.size()); ++i) {
    const SegmentSpec& seg = start_.signature.segments[i];
    FlowRequest req;
    req.state_jacobian = true;
    const FlowResult fr =
        prop_.FlowMap(seg.mode, start_.starts[i], start_.durations[i], start_.params, req);
    for (int trial = 0; trial < 20; ++trial) {
      StateMatrix phi = fr.state_jacobian;
      if (trial > 0) {
        for (int r = 0; r < 4; ++r) {
          for (int c = 0; c < 4; ++c) phi(r, c) = mantissa(rng) * std::pow(10.0, decade(rng));
        }
      }
      const StateMatrix factor = internal::FactorFromFlow(model_, start_, i, fr.x, phi);
      StateMatrix expected = phi;
      if (seg.guard >= 0 && !seg.tangent) {
        const StateMatrix salt = model_.HybridModel::Saltation(
            seg.mode, seg.guard, start_.signature.segments[i + 1].mode, fr.x, start_.params);
        expected.noalias() = salt * phi;
        ++salted;
      }
      ASSERT_EQ(factor.rows(), 4);
      ASSERT_EQ(factor.cols(), 4);
      EXPECT_EQ(std::memcmp(factor.data(), expected.data(), sizeof(double) * 16), 0)
          << "segment " << i << " trial " << trial << "\n"
          << factor << "\n"
          << expected;
    }
  }
  // Not vacuous: the orbit has events with a saltation.
  EXPECT_GT(salted, 0);
}

// MultiplyFactors multiplies two factors at fixed size for a 4-dimensional state: compared bit
// for bit with the dynamic-size product, for entries of either sign over several decades with
// exact zeros, negative zeros and ones among them, but for the sign of a zero: the fixed-size
// product starts each sum from its first product, the dynamic one from +0, so a sum of products
// that are all -0 is -0 in one and +0 in the other (equal values; a zero's sign changes no sum,
// product or quotient that is not itself zero or a division by it).
TEST(MultiplyFactors, IsTheDynamicProductBitForBit) {
  testing::AwkwardEntries entry(7);
  for (int trial = 0; trial < 200; ++trial) {
    StateMatrix a(4, 4), b(4, 4);
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) {
        a(r, c) = entry();
        b(r, c) = entry();
      }
    }
    StateMatrix expected(4, 4), got;
    expected.noalias() = a * b;
    internal::MultiplyFactors(a, b, &got);
    ASSERT_EQ(got.rows(), 4);
    ASSERT_EQ(got.cols(), 4);
    for (int r = 0; r < 4; ++r) {
      for (int c = 0; c < 4; ++c) {
        const bool same_bits = std::memcmp(&got(r, c), &expected(r, c), sizeof(double)) == 0;
        EXPECT_TRUE(same_bits || (got(r, c) == 0.0 && expected(r, c) == 0.0))
            << "trial " << trial << " entry (" << r << ", " << c << "): " << got(r, c)
            << " against " << expected(r, c);
      }
    }
  }
}

// ReducedMonodromy multiplies the factors at fixed size for a 4-dimensional state; the monodromy
// must not depend on that, so with the reference orbit's factors and with random ones (entries
// of either sign over several decades, 1 to 6 factors, where a different order of the sums would
// show in the last bits) it is compared bit for bit with the dynamic-size product, phase row and
// column dropped.
TEST_F(Monodromy, ReducedMonodromyIsTheDynamicProductBitForBit) {
  ASSERT_EQ(model_.state_dim(), 4);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> mantissa(-1.0, 1.0), decade(-3.0, 3.0);
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<StateMatrix> factors = internal::MonodromyFactors(model_, prop_, start_);
    if (trial > 0) {
      factors.resize(1 + trial % 6);
      for (StateMatrix& f : factors) {
        f.resize(4, 4);
        for (int r = 0; r < 4; ++r) {
          for (int c = 0; c < 4; ++c) f(r, c) = mantissa(rng) * std::pow(10.0, decade(rng));
        }
      }
    }
    StateMatrix full = StateMatrix::Identity(4, 4);
    for (const StateMatrix& f : factors) {
      StateMatrix next(4, 4);
      next.noalias() = f * full;
      full = next;
    }
    const StateMatrix expected = internal::WithoutPhase(model_, full);
    const StateMatrix reduced = internal::ReducedMonodromy(model_, factors);
    ASSERT_EQ(reduced.rows(), 3);
    ASSERT_EQ(reduced.cols(), 3);
    EXPECT_EQ(std::memcmp(reduced.data(), expected.data(), sizeof(double) * 9), 0)
        << "trial " << trial << "\n"
        << reduced << "\n"
        << expected;
  }
}

}  // namespace
}  // namespace drillbif
