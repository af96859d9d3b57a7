// The rows of SolveWithConditions' extra conditions (tangent_grazing.h: ConditionRow), each
// checked against central differences of the condition's value.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <vector>

#include "../orbit/monodromy.h"  // the engine's internal headers, by their path from here
#include "../orbit/orbit_bvp.h"
#include "bordered_sigma.h"
#include "support/reference_orbit_test.h"
#include "tangent_grazing.h"

namespace drillbif {
namespace {

using internal::ExtraCondition;

// The reference orbit with omega and a free (the two-parameter trace's parameters).
class ExtraConditionRows : public testing::ReferenceOrbitTest {
 protected:
  void SetUp() override {
    ReferenceOrbitTest::SetUp();
    if (HasFatalFailure()) return;
    free_ = {model_.ParamIndex("omega").value(), model_.ParamIndex("a").value()};
    ASSERT_GE(start_.durations.size(), 3u) << "the check wants events between segments";
  }

  internal::OrbitBvp Bvp() {
    return internal::OrbitBvp(model_, prop_, start_.signature, free_[0], free_[1]);
  }

  // y = (X, omega, a) of the reference orbit.
  Eigen::VectorXd Unknowns(const internal::OrbitBvp& bvp) const {
    const int m = bvp.size();
    Eigen::VectorXd y(m + 2);
    y.head(m) = bvp.Pack(start_);
    y[m] = start_.params[free_[0]];
    y[m + 1] = start_.params[free_[1]];
    return y;
  }

  // The condition's value at y.
  double ValueAt(const internal::OrbitBvp& bvp, const Eigen::VectorXd& y,
                 const ExtraCondition& condition) {
    const int m = bvp.size();
    Params p = start_.params;
    p[free_[0]] = y[m];
    p[free_[1]] = y[m + 1];
    PeriodicOrbit o;
    bvp.Unpack(y.head(m), p, &o);
    return internal::ConditionValue(model_, prop_, o, condition);
  }

  // Central differences of the condition's value, step h (1 + |y_j|).
  Eigen::RowVectorXd CentralRow(const internal::OrbitBvp& bvp, const Eigen::VectorXd& y,
                                const ExtraCondition& condition, double h) {
    Eigen::RowVectorXd row(y.size());
    for (int j = 0; j < y.size(); ++j) {
      const double step = h * (1.0 + std::abs(y[j]));
      Eigen::VectorXd yp = y, ym = y;
      yp[j] += step;
      ym[j] -= step;
      row[j] = (ValueAt(bvp, yp, condition) - ValueAt(bvp, ym, condition)) / (2.0 * step);
    }
    return row;
  }

  // Expects `row` (ConditionRow's, central differences of step h_j = 1e-6 (1 + |y_j|)) to be the
  // condition's derivative at y, two ways. The truncation of central differences of step H,
  // ~H^2 |c'''| / 6, is estimated by Richardson's D(2 H) - D(H) = 3 H^2 c''' / 6 + O(H^4) at
  // H = 1e-5 (1 + |y_j|) as T = |D(2 H) - D(H)| / 3 (fourfold margin below: the estimate's own
  // O(H^4) and rounding). (1) Against central differences of whole evaluations of the row's own
  // step, the quotient the row stands for: they differ by rounding (each value of c is a product
  // of the k segments' factors, in another order, then sigma: k eps (1 + |c|) each, so
  // k eps (1 + |c|) / h over the quotient; twofold margin) and, in the durations' columns, by the
  // second-order terms MonodromyRow leaves out, which cancel to O(h^2) like the truncation:
  // 4 T (h / H)^2. (2) Against the derivative, central differences of step H: that bound plus the
  // reference's own truncation 4 T and rounding eps (1 + |c|) / H. A wrong row (a missing term, a
  // misplaced column) errs by the size of its entries, far above either.
  void ExpectCentralRow(const internal::OrbitBvp& bvp, const Eigen::VectorXd& y,
                        const ExtraCondition& condition, double c0, const Eigen::RowVectorXd& row) {
    constexpr double kEps = 2.2e-16, kStep = 1e-6, kReference = 1e-5;
    ASSERT_EQ(row.size(), y.size());
    const double k = static_cast<double>(start_.durations.size());
    const Eigen::RowVectorXd same = CentralRow(bvp, y, condition, kStep);
    const Eigen::RowVectorXd d1 = CentralRow(bvp, y, condition, kReference);
    const Eigen::RowVectorXd d2 = CentralRow(bvp, y, condition, 2.0 * kReference);
    double worst_same = 0.0, worst_reference = 0.0;  // the largest errors relative to bounds
    for (int j = 0; j < y.size(); ++j) {
      const double h = kStep * (1.0 + std::abs(y[j]));
      const double h_ref = kReference * (1.0 + std::abs(y[j]));
      const double truncation = 4.0 * std::abs(d2[j] - d1[j]) / 3.0;  // 4 T at H
      const double same_bound =
          2.0 * k * kEps * (1.0 + std::abs(c0)) / h + truncation * (h / h_ref) * (h / h_ref);
      EXPECT_LE(std::abs(row[j] - same[j]), same_bound)
          << "column " << j << " of " << y.size() << ": " << row[j] << " against " << same[j];
      const double bound = truncation + same_bound + kEps * (1.0 + std::abs(c0)) / h_ref;
      EXPECT_LE(std::abs(row[j] - d1[j]), bound)
          << "column " << j << " of " << y.size() << ": " << row[j] << " against " << d1[j];
      worst_same = std::max(worst_same, std::abs(row[j] - same[j]) / same_bound);
      worst_reference = std::max(worst_reference, std::abs(row[j] - d1[j]) / bound);
    }
    std::printf("largest error / bound: %.3f (same step), %.3f (derivative)\n", worst_same,
                worst_reference);
  }

  std::vector<int> free_;
};

TEST_F(ExtraConditionRows, DurationRowIsTheUnitRowOfThatDuration) {
  const internal::OrbitBvp bvp = Bvp();
  const Eigen::VectorXd y = Unknowns(bvp);
  const int segment = 1;
  const double length = 1e-3;
  const ExtraCondition condition = ExtraCondition::Duration(segment, length);
  Eigen::RowVectorXd row;
  const double value =
      internal::ConditionRow(model_, prop_, bvp, free_, start_.params, y, condition, &row);
  EXPECT_EQ(value, start_.durations[segment] - length);
  ASSERT_EQ(row.size(), y.size());
  // The condition is linear in y: central differences are exact but for rounding, eps |y_j| / h
  // with h = 1e-4 (1 + |y_j|): below 1e-11.
  const Eigen::RowVectorXd fd = CentralRow(bvp, y, condition, 1e-4);
  EXPECT_LE((row - fd).lpNorm<Eigen::Infinity>(), 1e-11);
  EXPECT_EQ(row[bvp.DurationIndex(segment)], 1.0);
  EXPECT_EQ(row.cwiseAbs().sum(), 1.0);
}

// sigma of the shifted monodromy, bordered at the reference orbit, for a fold and a period
// doubling: the row reusing the monodromy factors (MonodromyRow; its durations' columns take the
// later factors' phase shift to first order) against central differences of whole evaluations.
TEST_F(ExtraConditionRows, MonodromyRowMatchesCentralDifferences) {
  const internal::OrbitBvp bvp = Bvp();
  const Eigen::VectorXd y = Unknowns(bvp);
  const Eigen::MatrixXd m0 =
      internal::ReducedMonodromy(model_, internal::MonodromyFactors(model_, prop_, start_));
  for (const CurveKind kind : {CurveKind::kFold, CurveKind::kPeriodDoubling}) {
    SCOPED_TRACE(CurveKindName(kind));
    const internal::BorderedSigma sigma(internal::ShiftedMonodromy(kind, m0));
    const ExtraCondition condition =
        ExtraCondition::OfMonodromy([kind, sigma](const Eigen::MatrixXd& m) {
          return sigma(internal::ShiftedMonodromy(kind, m));
        });
    Eigen::RowVectorXd row;
    const double value =
        internal::ConditionRow(model_, prop_, bvp, free_, start_.params, y, condition, &row);
    // The residual is the whole evaluation's, bit for bit.
    EXPECT_EQ(value, ValueAt(bvp, y, condition));
    ExpectCentralRow(bvp, y, condition, value, row);
  }
}

// sigma's gradient in the monodromy (SigmaWithGradient: -w^T (dA) v, carried through the
// bialternate square for Neimark-Sacker) against central differences of sigma in each entry of M,
// step H = 1e-5: truncation H^2 |sigma'''| / 6 and rounding eps (1 + |sigma|) / H, both ~1e-11 for
// these O(1) quantities (the borders are A's own singular vectors, so the bordered matrix is well
// conditioned); bound 1e-8 (a thousandfold margin). Two monodromies: the reference orbit's, and a
// generic one with no zero entry and a complex pair of multipliers (the reference's has rank one:
// its bialternate square vanishes, and with it some of that gradient's terms, which a wrong term
// would then pass unseen). A wrong sign or a missing term errs by the gradient's own entries.
TEST_F(ExtraConditionRows, SigmaGradientMatchesCentralDifferencesInTheMonodromy) {
  Eigen::MatrixXd generic(3, 3);
  generic << 0.3, -0.8, 0.2, 0.7, 0.4, -0.1, 0.1, 0.25, 0.6;
  const Eigen::MatrixXd reference =
      internal::ReducedMonodromy(model_, internal::MonodromyFactors(model_, prop_, start_));
  for (const Eigen::MatrixXd& m0 : {reference, generic}) {
    for (const CurveKind kind :
         {CurveKind::kFold, CurveKind::kPeriodDoubling, CurveKind::kNeimarkSacker}) {
      SCOPED_TRACE(CurveKindName(kind));
      const internal::BorderedSigma sigma(internal::ShiftedMonodromy(kind, m0));
      Eigen::MatrixXd gradient;
      const double value = internal::SigmaWithGradient(kind, sigma, m0, &gradient);
      EXPECT_EQ(value, sigma(internal::ShiftedMonodromy(kind, m0)));
      ASSERT_EQ(gradient.rows(), m0.rows());
      ASSERT_EQ(gradient.cols(), m0.cols());
      constexpr double kH = 1e-5;
      double worst = 0.0;
      for (int p = 0; p < m0.rows(); ++p) {
        for (int q = 0; q < m0.cols(); ++q) {
          Eigen::MatrixXd mp = m0, mm = m0;
          mp(p, q) += kH;
          mm(p, q) -= kH;
          const double fd = (sigma(internal::ShiftedMonodromy(kind, mp)) -
                             sigma(internal::ShiftedMonodromy(kind, mm))) /
                            (2.0 * kH);
          EXPECT_NEAR(gradient(p, q), fd, 1e-8) << "entry (" << p << ", " << q << ")";
          worst = std::max(worst, std::abs(gradient(p, q) - fd));
        }
      }
      std::printf("largest gradient error: %.2e (largest entry %.2e)\n", worst,
                  gradient.cwiseAbs().maxCoeff());
    }
  }
}

// sigma's row over X from its gradient (MonodromyGradientRow, the fold / PD curves' row) against
// the derivative, central differences of whole evaluations at H = 1e-5 (1 + |y_j|), for a fold
// and a period doubling (not Neimark-Sacker: the reference monodromy has rank one, its bialternate
// square and that square's derivatives along X vanish, and the row is zero either way; its
// gradient is checked above on a generic monodromy). The row is, per column, forward differences
// of step h = ForwardStep(y_j) of sigma's linearization along the factors the unknown moves: for a
// start's component that is g(t) = <G, M(y + t e_j)> with G the gradient at y (one factor moves),
// for a duration its own factor and the later phases, each differenced alone. Its truncation is
// h |g''| / 2; g'' is estimated by second central differences of whole evaluations of g at step
// 1e-4 (1 + |y_j|) (their rounding eps |g| / 1e-8, ~1e-8 |g|, below the curvature sought), and
// sigma's own, c'', likewise: in a duration's column the cross terms between the moved factors
// that g has and the row has not are second order in the same changes, of the size of g'' and
// c''; the bound takes 4 max(|g''|, |c''|) h / 2. Rounding: each moved factor's difference
// carries eps |F| / h, contracted over k factors: 2 k eps (1 + |c|) / h as in ExpectCentralRow.
// The reference's error: its Richardson truncation 4 T and eps (1 + |c|) / H. A wrong sign, an
// off-by-one partial product or a missing later phase errs by the row's own entries, the largest
// of which is ~1e6 bounds.
TEST_F(ExtraConditionRows, MonodromyGradientRowMatchesCentralDifferences) {
  const internal::OrbitBvp bvp = Bvp();
  const Eigen::VectorXd y = Unknowns(bvp);
  const int m = bvp.size();
  std::vector<FlowResult> flows;
  const std::vector<StateMatrix> factors =
      internal::MonodromyFactors(model_, prop_, start_, &flows);
  const Eigen::MatrixXd m0 = internal::ReducedMonodromy(model_, factors);
  const double k = static_cast<double>(start_.durations.size());
  for (const CurveKind kind : {CurveKind::kFold, CurveKind::kPeriodDoubling}) {
    SCOPED_TRACE(CurveKindName(kind));
    const internal::BorderedSigma sigma(internal::ShiftedMonodromy(kind, m0));
    Eigen::MatrixXd gradient;
    const double c0 = internal::SigmaWithGradient(kind, sigma, m0, &gradient);
    Eigen::RowVectorXd row = Eigen::RowVectorXd::Zero(m);
    internal::MonodromyGradientRow(model_, prop_, start_, factors, flows, gradient, row);
    const ExtraCondition condition =
        ExtraCondition::OfMonodromy([kind, sigma](const Eigen::MatrixXd& mono) {
          return sigma(internal::ShiftedMonodromy(kind, mono));
        });
    const ExtraCondition linear = ExtraCondition::OfMonodromy(
        [gradient](const Eigen::MatrixXd& mono) { return gradient.cwiseProduct(mono).sum(); });
    constexpr double kEps = 2.2e-16, kReference = 1e-5, kCurvature = 1e-4;
    const Eigen::RowVectorXd d1 = CentralRow(bvp, y, condition, kReference);
    const Eigen::RowVectorXd d2 = CentralRow(bvp, y, condition, 2.0 * kReference);
    const double g0 = ValueAt(bvp, y, linear);
    double worst = 0.0, largest = 0.0;
    for (int j = 0; j < m; ++j) {
      const double h = internal::ForwardStep(y[j]);
      const double h_ref = kReference * (1.0 + std::abs(y[j]));
      const double h2 = kCurvature * (1.0 + std::abs(y[j]));
      Eigen::VectorXd yp = y, ym = y;
      yp[j] += h2;
      ym[j] -= h2;
      const double c2 =
          (ValueAt(bvp, yp, condition) - 2.0 * c0 + ValueAt(bvp, ym, condition)) / (h2 * h2);
      const double g2 =
          (ValueAt(bvp, yp, linear) - 2.0 * g0 + ValueAt(bvp, ym, linear)) / (h2 * h2);
      const double truncation = 4.0 * std::max(std::abs(c2), std::abs(g2)) * h / 2.0;
      const double rounding = 2.0 * k * kEps * (1.0 + std::abs(c0)) / h;
      const double reference =
          4.0 * std::abs(d2[j] - d1[j]) / 3.0 + kEps * (1.0 + std::abs(c0)) / h_ref;
      const double bound = truncation + rounding + reference;
      EXPECT_LE(std::abs(row[j] - d1[j]), bound)
          << "column " << j << " of " << m << ": " << row[j] << " against " << d1[j];
      worst = std::max(worst, std::abs(row[j] - d1[j]) / bound);
      largest = std::max(largest, std::abs(d1[j]) / bound);
    }
    std::printf("largest error / bound: %.3f; largest entry / bound: %.3g\n", worst, largest);
  }
}

// h' of the first segment's guard at its end, a function of the orbit alone: central differences
// of whole evaluations.
TEST_F(ExtraConditionRows, OrbitRowMatchesCentralDifferences) {
  const internal::OrbitBvp bvp = Bvp();
  const Eigen::VectorXd y = Unknowns(bvp);
  const ExtraCondition condition = ExtraCondition::OfOrbit([this](const PeriodicOrbit& o) {
    const SegmentSpec& s = o.signature.segments[0];
    const StateVector end = prop_.FlowMap(s.mode, o.starts[0], o.durations[0], o.params, {}).x;
    return model_.Guard(s.mode, std::max(0, s.guard), end, o.params).dh;
  });
  Eigen::RowVectorXd row;
  const double value =
      internal::ConditionRow(model_, prop_, bvp, free_, start_.params, y, condition, &row);
  EXPECT_EQ(value, ValueAt(bvp, y, condition));
  ExpectCentralRow(bvp, y, condition, value, row);
}

// A function of one segment's flow (OfSegmentFlow) gets the row of the same function as any
// function of the orbit (OfOrbit), bit for bit: the unknowns it skips are those that leave the
// segment's flow alone. Segment 1, so that an earlier duration (through the phase) moves it too.
TEST_F(ExtraConditionRows, SegmentFlowRowIsTheOrbitRowBitForBit) {
  const internal::OrbitBvp bvp = Bvp();
  const Eigen::VectorXd y = Unknowns(bvp);
  const int segment = 1;
  auto rate = [this](const PeriodicOrbit& o) {
    const SegmentSpec& s = o.signature.segments[segment];
    const StateVector end =
        prop_.FlowMap(s.mode, o.starts[segment], o.durations[segment], o.params, {}).x;
    return model_.Guard(s.mode, std::max(0, s.guard), end, o.params).dh;
  };
  Eigen::RowVectorXd of_orbit, of_segment;
  const double value = internal::ConditionRow(model_, prop_, bvp, free_, start_.params, y,
                                              ExtraCondition::OfOrbit(rate), &of_orbit);
  EXPECT_EQ(internal::ConditionRow(model_, prop_, bvp, free_, start_.params, y,
                                   ExtraCondition::OfSegmentFlow(segment, rate), &of_segment),
            value);
  ASSERT_EQ(of_segment.size(), of_orbit.size());
  EXPECT_EQ(std::memcmp(of_segment.data(), of_orbit.data(), sizeof(double) * of_orbit.size()), 0)
      << "OfSegmentFlow:\n"
      << of_segment << "\nOfOrbit:\n"
      << of_orbit;
  // Not trivially: the first segment's duration moves the phase (a nonzero entry), its start
  // components do not (zero entries, the ones skipped).
  const int block = bvp.DurationIndex(0) + 1;
  EXPECT_NE(of_orbit[bvp.DurationIndex(0)], 0.0);
  EXPECT_EQ(of_orbit.head(block - 1).cwiseAbs().maxCoeff(), 0.0);
}

// The rows made with a workspace left over from another orbit (MonodromyRowScratch: more
// segments, other values, its perturbed orbit elsewhere) are the rows made without one, bit for
// bit, for MonodromyGradientRow and for MonodromyRow with both differences; and the workspace's
// orbit, perturbed in place for each unknown, is left the orbit exactly.
TEST_F(ExtraConditionRows, RowsWithAReusedWorkspaceAreTheSameBits) {
  const internal::OrbitBvp bvp = Bvp();
  const int m = bvp.size();
  std::vector<FlowResult> flows;
  const std::vector<StateMatrix> factors =
      internal::MonodromyFactors(model_, prop_, start_, &flows);
  const Eigen::MatrixXd m0 = internal::ReducedMonodromy(model_, factors);
  const internal::BorderedSigma sigma(internal::ShiftedMonodromy(CurveKind::kFold, m0));
  Eigen::MatrixXd gradient;
  const double c0 = internal::SigmaWithGradient(CurveKind::kFold, sigma, m0, &gradient);
  auto f = [&sigma](const Eigen::Ref<const Eigen::MatrixXd>& mono) {
    return sigma(internal::ShiftedMonodromy(CurveKind::kFold, mono));
  };
  // A workspace dirtied by another orbit: one segment more, every value moved.
  internal::MonodromyRowScratch scratch;
  PeriodicOrbit other = start_;
  other.signature.segments.push_back(other.signature.segments.back());
  other.starts.push_back(other.starts.back());
  other.durations.push_back(0.5);
  for (StateVector& x : other.starts) x.array() += 0.25;
  scratch.moved = other;
  const StateMatrix garbage = StateMatrix::Constant(4, 4, 7.0);
  scratch.prefix.assign(factors.size() + 2, garbage);
  scratch.suffix.assign(factors.size() + 2, garbage);
  scratch.weight.assign(factors.size() + 2, garbage);
  scratch.later.assign(factors.size() + 2, garbage);
  scratch.later_rates.assign(factors.size() + 2, 7.0);
  auto same_bits = [m](const Eigen::RowVectorXd& a, const Eigen::RowVectorXd& b) {
    return std::memcmp(a.data(), b.data(), sizeof(double) * m) == 0;
  };
  auto restored = [this](const PeriodicOrbit& o) {
    if (o.starts.size() != start_.starts.size() || o.durations != start_.durations ||
        !(o.signature == start_.signature)) {
      return false;
    }
    for (size_t i = 0; i < o.starts.size(); ++i) {
      if (o.starts[i].size() != start_.starts[i].size() ||
          std::memcmp(o.starts[i].data(), start_.starts[i].data(),
                      sizeof(double) * o.starts[i].size()) != 0) {
        return false;
      }
    }
    return true;
  };
  Eigen::RowVectorXd fresh = Eigen::RowVectorXd::Zero(m), reused = Eigen::RowVectorXd::Zero(m);
  internal::MonodromyGradientRow(model_, prop_, start_, factors, flows, gradient, fresh);
  internal::MonodromyGradientRow(model_, prop_, start_, factors, flows, gradient, reused, &scratch);
  EXPECT_TRUE(same_bits(fresh, reused)) << fresh << "\n" << reused;
  EXPECT_TRUE(restored(scratch.moved));
  // Not vacuous: the row has entries.
  EXPECT_GT(fresh.lpNorm<Eigen::Infinity>(), 0.0);
  for (const internal::RowDifferences differences :
       {internal::RowDifferences::kCentral, internal::RowDifferences::kForward}) {
    scratch.moved = other;
    scratch.later.assign(factors.size() + 2, garbage);
    fresh.setZero();
    reused.setZero();
    internal::MonodromyRow(model_, prop_, start_, factors, flows, f, differences, c0, fresh);
    internal::MonodromyRow(model_, prop_, start_, factors, flows, f, differences, c0, reused,
                           &scratch);
    EXPECT_TRUE(same_bits(fresh, reused)) << fresh << "\n" << reused;
    EXPECT_TRUE(restored(scratch.moved));
    EXPECT_GT(fresh.lpNorm<Eigen::Infinity>(), 0.0);
  }
}

}  // namespace
}  // namespace drillbif
