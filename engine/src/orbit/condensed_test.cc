// CondensedLu against the dense PartialPivLU on the shooting systems of real orbits.
#include "condensed.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <vector>

#include "drillbif/continuation/continuation.h"
#include "drillbif/continuation/curve.h"
#include "drillbif/flow/exact_propagator.h"
#include "orbit_bvp.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;
using internal::CondensedMode;
using Mat = Eigen::MatrixXd;
using Vec = Eigen::VectorXd;

constexpr double kEps = std::numeric_limits<double>::epsilon();

// A bordered shooting system of `orbit` as the correctors build it: q = 0 (the orbit solver),
// 1 (the branch corrector in a) or 2 (the curve corrector in omega and a); the border rows are an
// orthonormal basis of the kernel of [G_X G_p] (the tangent space the arclength rows take), the
// right-hand side the residual at the orbit's unknowns moved by 1e-4 (a Newton step's system).
struct System {
  Mat a;
  Vec b;
  int segments = 0, block = 0;
};

System MakeSystem(const DO& model, Propagator& prop, const PeriodicOrbit& orbit, int q) {
  const internal::OrbitBvp bvp(model, prop, orbit.signature, q >= 1 ? DO::kA : -1,
                               q >= 2 ? DO::kOmega : -1);
  const Vec x = bvp.Pack(orbit);
  const int m = bvp.size();
  Vec g, gp1, gp2;
  Mat gx;
  EXPECT_TRUE(
      bvp.Evaluate(x, orbit.params, &g, &gx, q >= 1 ? &gp1 : nullptr, q >= 2 ? &gp2 : nullptr)
          .ok());
  Mat top(m, m + q);
  top.leftCols(m) = gx;
  if (q >= 1) top.col(m) = gp1;
  if (q >= 2) top.col(m + 1) = gp2;
  System s;
  s.segments = bvp.segments();
  s.block = m / bvp.segments();
  s.a.resize(m + q, m + q);
  s.a.topRows(m) = top;
  if (q > 0) {
    const Eigen::JacobiSVD<Mat> svd(top, Eigen::ComputeFullV);
    s.a.bottomRows(q) = svd.matrixV().rightCols(q).transpose();
  }
  Vec moved = x;
  for (int i = 0; i < m; ++i) moved[i] += 1e-4 * std::sin(1.0 + i);
  Vec gm;
  EXPECT_TRUE(bvp.Evaluate(moved, orbit.params, &gm, nullptr, nullptr).ok());
  s.b = Vec::Zero(m + q);
  s.b.head(m) = -gm;
  return s;
}

double Condition(const Mat& a) {
  const Eigen::JacobiSVD<Mat> svd(a);
  const Vec& sv = svd.singularValues();
  return sv[0] / sv[sv.size() - 1];
}

double MaxModulus(const Stability& st) {
  double mu = 0.0;
  for (const auto& z : st.multipliers) mu = std::max(mu, std::abs(z));
  return mu;
}

struct Orbits {
  PeriodicOrbit reference, ten_segments, unstable;
};

// The reference orbit; from the a-branch over [0.01, 8] at omega = 0.07 (the reference box's
// snaking branches below omega = 0.1) through the orbit reached from rest at a = 0.3: the least
// unstable of its orbits with 10 to 12 segments, and its most unstable orbit (past its folds;
// the box's curves have multipliers up to ~100 in modulus, docs/engine.md); both with every
// segment at least 0.01 long.
const Orbits& TestOrbits() {
  static const Orbits* orbits = [] {
    auto* o = new Orbits;
    DO model;
    ExactPropagator prop(model);
    o->reference = *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
    const PeriodicOrbit start =
        *testing::SolvedOrbitFromRest(model, prop, DO::MakeParams(0.3, 0.15, 0.07));
    ContinuationOptions opt;
    opt.param = "a";
    opt.min = 0.01;
    opt.max = 8.0;
    opt.locate_measure_maxima = false;
    opt.point_measures = 0;
    const ContinuationResult r = Continue(model, prop, start, opt);
    double least = std::numeric_limits<double>::infinity(), most = 0.0;
    for (const ContinuationPoint& p : r.points) {
      // Not the grazing points, where a segment of zero length makes the system singular.
      const std::vector<double>& tau = p.orbit.durations;
      if (*std::min_element(tau.begin(), tau.end()) < 1e-2) continue;
      const double mu = MaxModulus(p.stability);
      if (tau.size() >= 10 && tau.size() <= 12 && mu < least) {
        least = mu;
        o->ten_segments = p.orbit;
      }
      if (mu > most) {
        most = mu;
        o->unstable = p.orbit;
      }
    }
    return o;
  }();
  return *orbits;
}

// Both solves are backward stable with a backward error of at most ~N eps |a| (partial pivoting,
// modest pivot growth; the condensed one is also an elimination with pivots, the segments'
// event-row entries and the reduced system's partial pivoting), so each is within ~N kappa eps of
// the exact solution, and they differ by at most 2 N kappa(a) eps |x|; kappa from the SVD.
void ExpectSolvesAsDense(const Mat& a, const Vec& b, internal::CondensedLu& lu,
                         const std::string& what) {
  const Eigen::PartialPivLU<Mat> dense(a);
  const Vec xd = dense.solve(b);
  const Vec xc = lu.Solve(b);
  const double kappa = Condition(a);
  const double bound = 2.0 * static_cast<double>(a.rows()) * kappa * kEps * xd.norm();
  EXPECT_LE((xc - xd).norm(), bound) << what;
  std::printf(
      "%s: size %d, reduced %d, growth %.3g, kappa %.3g, |xc - xd| / (kappa eps |xd|) %.3g\n",
      what.c_str(), static_cast<int>(a.rows()), lu.reduced_size(), lu.growth(), kappa,
      (xc - xd).norm() / (kappa * kEps * xd.norm()));
  EXPECT_EQ(lu.DeterminantSign(), dense.determinant() > 0.0 ? 1.0 : -1.0) << what;
}

class CondensedLuTest : public ::testing::TestWithParam<int> {};

// q = 0, 1, 2 border rows: the orbit solver's, the branch corrector's and the curve corrector's
// systems. The reduced system is small (the first start, the last duration, the parameters and
// the borders: d + 1 + 2q unknowns with the kernel rows, more only where a duration is kept).
TEST_P(CondensedLuTest, SolvesTheShootingSystemsOfRealOrbitsAsDenseLu) {
  DO model;
  ExactPropagator prop(model);
  const Orbits& orbits = TestOrbits();
  ASSERT_GE(orbits.ten_segments.durations.size(), 10u);
  ASSERT_LE(orbits.ten_segments.durations.size(), 12u);
  ASSERT_GT(MaxModulus(OrbitStability(model, prop, orbits.unstable)), 10.0);
  const int q = GetParam();
  for (const auto& [name, orbit] :
       {std::pair<std::string, const PeriodicOrbit*>{"reference", &orbits.reference},
        {"10 segments at omega 0.07", &orbits.ten_segments},
        {"unstable at omega 0.07", &orbits.unstable}}) {
    const System s = MakeSystem(model, prop, *orbit, q);
    internal::CondensedLu lu(s.segments, s.block);
    ASSERT_TRUE(lu.Compute(s.a)) << name << ": growth " << lu.growth();
    EXPECT_LT(lu.reduced_size(), s.a.rows() / 2) << name;
    ExpectSolvesAsDense(s.a, s.b, lu, name);
    // The tangent's right-hand side (the last unit vector), solved with the same factorization.
    ExpectSolvesAsDense(s.a, Vec::Unit(s.a.rows(), s.a.rows() - 1), lu, name + ", e_last");
  }
}

INSTANTIATE_TEST_SUITE_P(Borders, CondensedLuTest, ::testing::Values(0, 1, 2));

// An event row whose own-duration entry is zero (a tangent end, where grad h . f = 0) cannot be
// solved for that duration: it stays a reduced unknown, and the row a reduced row. Here the entry
// of the 10-segment orbit's branch system is set to 0 (the matrix stays regular, checked).
TEST(CondensedLu, KeepsADurationWhoseEventRowCannotBeSolvedForIt) {
  DO model;
  ExactPropagator prop(model);
  System s = MakeSystem(model, prop, TestOrbits().ten_segments, 1);
  internal::CondensedLu plain(s.segments, s.block);
  ASSERT_TRUE(plain.Compute(s.a));
  const int event_row = 2 * s.block, duration = 2 * s.block + s.block - 1;
  s.a(event_row, duration) = 0.0;
  ASSERT_GT(1.0 / Condition(s.a), 1e-12);
  internal::CondensedLu lu(s.segments, s.block);
  ASSERT_TRUE(lu.Compute(s.a));
  EXPECT_EQ(lu.reduced_size(), plain.reduced_size() + 1);
  ExpectSolvesAsDense(s.a, s.b, lu, "kept duration");
}

// The elimination relies on no later unknown in a block's rows, not on OrbitBvp's zeros before
// them (its earlier segments' start columns): a cheaper product that assumed those zeros would
// be wrong for other shooting systems. Here a block's rows also get entries in an earlier start's
// columns, and the solution is still the dense one.
TEST(CondensedLu, UsesEveryNonzeroColumnOfABlocksRows) {
  DO model;
  ExactPropagator prop(model);
  System s = MakeSystem(model, prop, TestOrbits().ten_segments, 1);
  const int block = 3, row = block * s.block;  // an inner block, past three segments
  ASSERT_LT(block + 1, s.segments);
  ASSERT_TRUE(s.a.block(row, s.block, s.block, s.block - 1).isZero(0.0));
  const double scale = s.a.block(row, row, s.block, s.block).cwiseAbs().maxCoeff();
  for (int r = 0; r < s.block; ++r) {
    s.a(row + r, s.block + r % (s.block - 1)) = 0.5 * scale * std::cos(1.0 + r);
  }
  ASSERT_GT(1.0 / Condition(s.a), 1e-12);
  internal::CondensedLu lu(s.segments, s.block, CondensedMode::kCondensed);
  ASSERT_TRUE(lu.Compute(s.a));
  ExpectSolvesAsDense(s.a, s.b, lu, "entries in an earlier start's columns");
}

// The correctors keep one CondensedLu across signatures (Reshape): factorizing systems of other
// sizes, borders and kept durations in between changes no bit of a system's solution or
// determinant sign.
TEST(CondensedLu, ReusedForOtherSystemsSolvesAsAFreshOne) {
  DO model;
  ExactPropagator prop(model);
  const Orbits& orbits = TestOrbits();
  std::vector<System> systems;
  for (int q = 0; q <= 2; ++q) systems.push_back(MakeSystem(model, prop, orbits.ten_segments, q));
  systems.push_back(MakeSystem(model, prop, orbits.reference, 1));
  systems.push_back(systems[1]);
  systems.back().a(2 * systems.back().block, 3 * systems.back().block - 1) =
      0.0;  // a kept duration
  internal::CondensedLu reused(0, 0, CondensedMode::kCondensed);
  // Twice through, so that every system follows a different one.
  for (int pass = 0; pass < 2; ++pass) {
    for (size_t i = 0; i < systems.size(); ++i) {
      const System& s = systems[i];
      internal::CondensedLu fresh(s.segments, s.block, CondensedMode::kCondensed);
      ASSERT_TRUE(fresh.Compute(s.a)) << i;
      reused.Reshape(s.segments, s.block);
      ASSERT_TRUE(reused.Compute(s.a)) << i;
      EXPECT_EQ(reused.reduced_size(), fresh.reduced_size()) << i;
      EXPECT_EQ(reused.Solve(s.b), fresh.Solve(s.b)) << i;
      EXPECT_EQ(reused.DeterminantSign(), fresh.DeterminantSign()) << i;
    }
  }
  EXPECT_EQ(systems[1].a.rows(), systems[0].a.rows() + 1);
}

// Above the growth bound, and where the matrix is not a shooting system, the dense factorization
// answers: the same solution bit for bit as PartialPivLU.
TEST(CondensedLu, FallsBackToDenseLuAboveTheGrowthBoundOrWithoutTheStructure) {
  DO model;
  ExactPropagator prop(model);
  const System s = MakeSystem(model, prop, TestOrbits().unstable, 2);
  internal::CondensedLu measure(s.segments, s.block);
  ASSERT_TRUE(measure.Compute(s.a));
  ASSERT_GT(measure.growth(), 1.0);
  const Vec dense = s.a.partialPivLu().solve(s.b);
  internal::CondensedLu bounded(s.segments, s.block, CondensedMode::kAuto, measure.growth() / 2);
  EXPECT_FALSE(bounded.Compute(s.a));
  EXPECT_EQ(bounded.Solve(s.b), dense);
  Mat scrambled = s.a;
  scrambled.row(0).swap(scrambled.row(1));  // the event row no longer zero in the next start
  internal::CondensedLu wrong(s.segments, s.block);
  EXPECT_FALSE(wrong.Compute(scrambled));
  EXPECT_EQ(wrong.growth(), 0.0);
  internal::CondensedLu dense_mode(s.segments, s.block, CondensedMode::kDense);
  EXPECT_FALSE(dense_mode.Compute(s.a));
  EXPECT_EQ(dense_mode.Solve(s.b), dense);
}

// The same special points, of the same kinds at the same parameter values (each located to
// 1e-10; 1e-8 allowed for the rounding differences of the two solves, the bound the trace
// comparison uses), on the b-branch of the reference orbit over [0, 0.2] both ways with the
// condensed corrector as with the dense one.
TEST(CondensedSolve, BranchFindsTheSameSpecialPointsAsTheDenseCorrector) {
  DO model;
  ExactPropagator prop(model);
  ContinuationOptions opt;
  opt.param = "b";
  opt.min = 0.0;
  opt.max = 0.2;
  const ContinuationResult dense = Continue(model, prop, TestOrbits().reference, opt);
  opt.steps.condensed_solve = true;
  const ContinuationResult condensed = Continue(model, prop, TestOrbits().reference, opt);
  ASSERT_EQ(dense.summary.termination, Termination::kCompleted);
  EXPECT_EQ(condensed.summary.termination, Termination::kCompleted) << condensed.summary.message;
  ASSERT_GE(dense.special_points.size(), 4u);
  ASSERT_EQ(condensed.special_points.size(), dense.special_points.size());
  for (size_t i = 0; i < dense.special_points.size(); ++i) {
    EXPECT_EQ(condensed.special_points[i].kind, dense.special_points[i].kind) << i;
    EXPECT_NEAR(condensed.special_points[i].point.value, dense.special_points[i].point.value, 1e-8)
        << SpecialPointKindName(dense.special_points[i].kind);
  }
}

// Likewise the l1 grazing curve from the omega-branch's grazing above omega = 0.4 (a = 0.3): the
// same codimension-2 points in (omega, a) to 1e-8.
TEST(CondensedSolve, CurveFindsTheSameCodimensionTwoPointsAsTheDenseCorrector) {
  DO model;
  ExactPropagator prop(model);
  ContinuationOptions branch;
  branch.param = "omega";
  branch.min = 0.05, branch.max = 2.0;
  const ContinuationResult omega = Continue(model, prop, TestOrbits().reference, branch);
  const SpecialPoint* graze = nullptr;
  for (const SpecialPoint& s : omega.special_points) {
    if (s.kind == SpecialPointKind::kGrazingL1 && s.point.value > 0.4) graze = &s;
  }
  ASSERT_NE(graze, nullptr);
  CurveOptions opt;
  opt.param1 = "omega";
  opt.param2 = "a";
  opt.min1 = 0.05, opt.max1 = 2.0, opt.min2 = 0.01, opt.max2 = 8.0;
  const CurveResult dense = ContinueCurve(model, prop, *graze, opt);
  opt.steps.condensed_solve = true;
  const CurveResult condensed = ContinueCurve(model, prop, *graze, opt);
  ASSERT_GE(dense.codim2.size(), 2u);
  ASSERT_EQ(condensed.codim2.size(), dense.codim2.size());
  for (size_t i = 0; i < dense.codim2.size(); ++i) {
    EXPECT_EQ(condensed.codim2[i].kind, dense.codim2[i].kind) << i;
    EXPECT_NEAR(condensed.codim2[i].point.value1, dense.codim2[i].point.value1, 1e-8);
    EXPECT_NEAR(condensed.codim2[i].point.value2, dense.codim2[i].point.value2, 1e-8);
  }
}

// The orbit solver's Newton with condensed steps reaches the orbit the QR steps reach, to the
// solver's tolerance (1e-11 of the unknowns' size; 1e-10 asserted).
TEST(CondensedSolve, OrbitSolverConvergesToTheSameOrbit) {
  DO model;
  ExactPropagator prop(model);
  for (const PeriodicOrbit* solved : {&TestOrbits().reference, &TestOrbits().unstable}) {
    PeriodicOrbit qr = *solved, condensed = *solved;
    for (PeriodicOrbit* o : {&qr, &condensed}) {
      o->starts[0][DO::kY] += 1e-3;  // a start off the orbit
      o->durations[0] *= 1.001;
    }
    OrbitSolverOptions opt;
    const OrbitSolveSummary by_qr = SolveOrbit(model, prop, opt, &qr);
    opt.condensed_solve = true;
    const OrbitSolveSummary by_condensing = SolveOrbit(model, prop, opt, &condensed);
    ASSERT_EQ(by_qr.termination, Termination::kCompleted);
    ASSERT_EQ(by_condensing.termination, Termination::kCompleted);
    EXPECT_GE(by_condensing.iterations, 2);  // Newton steps were taken
    for (size_t i = 0; i < qr.durations.size(); ++i) {
      EXPECT_NEAR(condensed.durations[i], qr.durations[i], 1e-10 * (1.0 + qr.durations[i]));
      EXPECT_LE((condensed.starts[i] - qr.starts[i]).lpNorm<Eigen::Infinity>(),
                1e-10 * (1.0 + qr.starts[i].lpNorm<Eigen::Infinity>()));
    }
  }
}

}  // namespace
}  // namespace drillbif
