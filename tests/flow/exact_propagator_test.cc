// The exact propagator: closed-form flows and their derivatives against the matrix exponential of
// the augmented linear system (two independent computations of the same flow), flow derivatives
// against finite differences, measures against quadrature of their rates, and event location.
#include "drillbif/flow/exact_propagator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "drillbif/model/drifting_oscillator.h"
#include "problems/grazing.h"
#include "problems/parameter_sets.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

StateVector ContactState(double q, double y, double s, const Params& prm) {
  StateVector x(4);
  x << q + prm[DO::kG], y, q, s;
  return x;
}

// Durations that span the regimes of each set: short steps (series branches), a few time units,
// and a whole forcing period (long free flight).
std::vector<double> Durations(const Params& prm) {
  return {1e-9, 1e-3, 0.37, 2.5, 11.0, kTwoPi / prm[DO::kOmega]};
}

class ExactFlowTest : public ::testing::TestWithParam<testing::NamedParams> {};

// Pade scaling-and-squaring computes expm(A t) to about eps * ||A t|| relative to the norm of
// the result (Higham 2005), and the closed forms are accurate to a few eps; positions grow to
// |p| ~ (a + b) t^2 over a period, so the comparison is relative to 1 + |x| with a tolerance of
// 1e-12 * (1 + ||A|| t) (about 1e4 eps at the longest durations).
TEST_P(ExactFlowTest, ClosedFormMatchesMatrixExponential) {
  DO model;
  const Params& prm = GetParam().params;
  ExactOptions by_expm;
  by_expm.use_closed_form = false;
  ExactPropagator closed(model), expm(model, by_expm);
  const std::vector<StateVector> starts = {(StateVector(4) << -3.0, 0.7, 0.4, 0.3).finished(),
                                           ContactState(0.3, 0.6, 2.0, prm),
                                           ContactState(0.9, -0.2, 5.0, prm)};
  Eigen::MatrixXd a;
  for (int mode = 0; mode < 3; ++mode) {
    model.AugmentedMatrix(mode, prm, &a);
    const double norm_a = a.cwiseAbs().rowwise().sum().maxCoeff();
    for (const StateVector& x0 : starts) {
      for (double t : Durations(prm)) {
        const FlowResult c = closed.FlowMap(mode, x0, t, prm, {true, true});
        const FlowResult e = expm.FlowMap(mode, x0, t, prm, {true, true});
        const double tol = 1e-12 * (1.0 + norm_a * t);
        // d x / d params: closed forms (a, b, g, phi0, omega; xi outside contact) against Van
        // Loan's block exponential, whose norm is ~ ||A|| t too: the same relative bound, taken
        // relative to 1 + |value| + |x| (derivatives in omega grow like t |x'|).
        for (int k = 0; k < model.num_params(); ++k) {
          for (int i = 0; i < 4; ++i) {
            EXPECT_NEAR(c.param_jacobian(i, k), e.param_jacobian(i, k),
                        tol * (1.0 + std::abs(e.param_jacobian(i, k)) + std::abs(e.x[i])))
                << "mode " << mode << " t " << t << " d x" << i << "/d " << model.param_names()[k];
          }
        }
        for (int i = 0; i < 4; ++i) {
          EXPECT_NEAR(c.x[i], e.x[i], tol * (1.0 + std::abs(e.x[i])))
              << "mode " << mode << " t " << t << " component " << i;
          for (int j = 0; j < 4; ++j) {
            EXPECT_NEAR(c.state_jacobian(i, j), e.state_jacobian(i, j),
                        tol * (1.0 + std::abs(e.state_jacobian(i, j))))
                << "mode " << mode << " t " << t << " d x" << i << "/d x0" << j;
          }
        }
      }
    }
  }
}

// d x(t) / d x0 (closed form) and d x(t) / d params (Van Loan block exponential) against central
// differences of the closed-form flow. Relative step 1e-6: truncation (1e-6)^2 * |x'''| scale and
// rounding eps |x| / 1e-6 ~ 1e-10 |x|; the tolerance 1e-6 relative to 1 + |value| + |x| covers the
// growth of third derivatives over a long free flight (t^3 terms) with margin.
TEST_P(ExactFlowTest, FlowDerivativesMatchFiniteDifferences) {
  DO model;
  const Params& prm = GetParam().params;
  ExactPropagator prop(model);
  const StateVector starts[3] = {(StateVector(4) << -3.0, 0.7, 0.4, 0.3).finished(),
                                 ContactState(0.3, 0.6, 2.0, prm),
                                 ContactState(0.9, -0.2, 5.0, prm)};
  for (int mode = 0; mode < 3; ++mode) {
    const StateVector& x0 = starts[mode];
    for (double t : {0.37, 7.0}) {
      const FlowResult r = prop.FlowMap(mode, x0, t, prm, {true, true});
      ASSERT_TRUE(r.status.ok());
      for (int j = 0; j < 4; ++j) {
        const double h = 1e-6 * std::max(1.0, std::abs(x0[j]));
        StateVector xp = x0, xm = x0;
        xp[j] += h, xm[j] -= h;
        const StateVector fp = prop.FlowMap(mode, xp, t, prm, {}).x;
        const StateVector fm = prop.FlowMap(mode, xm, t, prm, {}).x;
        for (int i = 0; i < 4; ++i) {
          const double fd = (fp[i] - fm[i]) / (2 * h);
          EXPECT_NEAR(r.state_jacobian(i, j), fd, 1e-6 * (1 + std::abs(fd) + std::abs(r.x[i])))
              << "mode " << mode << " t " << t << " d x" << i << "/d x0_" << j;
        }
      }
      for (int k = 0; k < 6; ++k) {
        const double h = 1e-6 * (prm[k] != 0.0 ? std::abs(prm[k]) : 1.0);
        Params pp = prm, pm = prm;
        pp[k] += h, pm[k] -= h;
        const StateVector fp = prop.FlowMap(mode, x0, t, pp, {}).x;
        const StateVector fm = prop.FlowMap(mode, x0, t, pm, {}).x;
        for (int i = 0; i < 4; ++i) {
          const double fd = (fp[i] - fm[i]) / (2 * h);
          EXPECT_NEAR(r.param_jacobian(i, k), fd, 1e-6 * (1 + std::abs(fd) + std::abs(r.x[i])))
              << "mode " << mode << " t " << t << " d x" << i << "/d " << model.param_names()[k];
        }
      }
    }
  }
}

// d x / d t is the vector field at x(t).
TEST_P(ExactFlowTest, TimeDerivativeIsTheVectorField) {
  DO model;
  const Params& prm = GetParam().params;
  ExactPropagator prop(model);
  const StateVector x0 = ContactState(0.3, 0.6, 2.0, prm);
  for (int mode = 0; mode < 3; ++mode) {
    const double t = 1.3, h = 1e-5 * model.TimeScale(mode, prm);
    const StateVector xp = prop.FlowMap(mode, x0, t + h, prm, {}).x;
    const StateVector xm = prop.FlowMap(mode, x0, t - h, prm, {}).x;
    StateVector f;
    model.VectorField(mode, prop.FlowMap(mode, x0, t, prm, {}).x, prm, &f);
    for (int i = 0; i < 4; ++i) {
      const double fd = (xp[i] - xm[i]) / (2 * h);
      EXPECT_NEAR(f[i], fd, 1e-7 * (1 + std::abs(fd))) << "mode " << mode << " component " << i;
    }
  }
}

// The closed-form measure increments against fine Gauss-Legendre-free quadrature: composite
// Simpson on 20000 panels of the rates along the flow (error ~ (t/20000)^4 |f''''| < 1e-12 here).
TEST_P(ExactFlowTest, MeasureIncrementsMatchQuadratureOfTheirRates) {
  DO model;
  const Params& prm = GetParam().params;
  const StateVector x0 = ContactState(0.3, 0.6, 2.0, prm);
  for (int mode = 0; mode < 3; ++mode) {
    const double t = 3.0;
    const MeasureVector closed = model.MeasureIncrements(mode, x0, t, prm, kAllMeasures);
    const int n = 20000;
    MeasureVector simpson = MeasureVector::Zero(2);
    StateVector x;
    for (int k = 0; k <= n; ++k) {
      model.Flow(mode, x0, t * k / n, prm, &x, nullptr);
      const double w = (k == 0 || k == n) ? 1.0 : (k % 2 ? 4.0 : 2.0);
      simpson += w * model.MeasureRates(mode, x, prm);
    }
    simpson *= t / (3.0 * n);
    for (int m = 0; m < 2; ++m) {
      EXPECT_NEAR(closed[m], simpson[m], 1e-9 * (1 + std::abs(simpson[m])))
          << "mode " << mode << " measure " << model.measure_names()[m];
    }
  }
}

// Event location evaluates prepared segments with guards and bounds; the state it reports must be
// the flow's own, bit for bit, in every mode and over every regime of omega t (the durations
// reach past |omega t| = 1/2, where the free-flight forcing integrals switch from series to
// direct forms), whether or not the guards are asked for.
TEST_P(ExactFlowTest, PreparedSegmentStateIsTheFlowsBitForBit) {
  DO model;
  const Params& prm = GetParam().params;
  const std::vector<StateVector> starts = {(StateVector(4) << -3.0, 0.7, 0.4, 0.3).finished(),
                                           ContactState(0.3, 0.6, 2.0, prm)};
  for (int mode = 0; mode < 3; ++mode) {
    for (const StateVector& x0 : starts) {
      PreparedSegment seg;
      model.PrepareSegment(mode, x0, prm, &seg);
      for (double t : Durations(prm)) {
        StateVector flow;
        model.Flow(mode, x0, t, prm, &flow, nullptr);
        SegmentPoint with, without;
        model.EvaluateSegment(seg, t, prm, true, &with);
        model.EvaluateSegment(seg, t, prm, false, &without);
        ASSERT_EQ(with.x.size(), 4);
        ASSERT_EQ(without.x.size(), 4);
        for (int i = 0; i < 4; ++i) {
          EXPECT_EQ(with.x[i], flow[i]) << "mode " << mode << " t " << t << " component " << i;
          EXPECT_EQ(without.x[i], flow[i]) << "mode " << mode << " t " << t << " component " << i;
        }
      }
    }
  }
}

INSTANTIATE_TEST_SUITE_P(HardParameters, ExactFlowTest,
                         ::testing::ValuesIn(testing::HardParameterSets()),
                         [](const auto& test_info) { return test_info.param.name; });

// ---- event location ----

struct GrazeCase {
  const char* surface;
  testing::GrazingCase (*make)(double);
};

class GrazingEventTest : public ::testing::TestWithParam<GrazeCase> {};

TEST_P(GrazingEventTest, DetectsAGrazeDeeperThanOneTenthOfANanometre) {
  DO model;
  ExactPropagator prop(model);
  for (double depth : {-1e-10, -1e-11, 0.0}) {
    const testing::GrazingCase c = GetParam().make(depth);
    AdvanceRequest req;
    req.mode = c.mode, req.x0 = c.x0, req.t_max = c.t_end;
    const AdvanceResult r = prop.Advance(req, c.params);
    ASSERT_TRUE(r.status.ok());
    ASSERT_EQ(r.end, AdvanceEnd::kEvent) << GetParam().surface << " depth " << depth;
    EXPECT_EQ(r.guard, c.guard);
    // The event lies at the crossing just before the touching point: within sqrt(2 |depth| / h'')
    // of it (the parabola's half-width), which is < 1e-4 for these curvatures.
    EXPECT_NEAR(r.duration, c.t_touch, 1e-4);
    EXPECT_LE(std::abs(model.Guard(c.mode, c.guard, r.x, c.params).h), 1e-12);
  }
}

TEST_P(GrazingEventTest, IgnoresANearMissOfTenNanometres) {
  DO model;
  ExactPropagator prop(model);
  const testing::GrazingCase c = GetParam().make(1e-8);
  AdvanceRequest req;
  req.mode = c.mode, req.x0 = c.x0, req.t_max = c.t_end;
  const AdvanceResult r = prop.Advance(req, c.params);
  ASSERT_TRUE(r.status.ok());
  EXPECT_EQ(r.end, AdvanceEnd::kTimeLimit) << GetParam().surface;
  EXPECT_DOUBLE_EQ(r.duration, c.t_end);
}

INSTANTIATE_TEST_SUITE_P(Surfaces, GrazingEventTest,
                         ::testing::Values(GrazeCase{"Pi", testing::GrazeImpact},
                                           GrazeCase{"l1", testing::GrazeProgression},
                                           GrazeCase{"l2", testing::GrazeSeparation}),
                         [](const auto& test_info) { return test_info.param.surface; });

// A transversal crossing is placed to machine precision: the guard vanishes at the located time
// to rounding (|h| <= 8 eps times the largest terms summed in p(t) = p0 + y0 t + ..., about 60
// each here, which cancel to p = 0.02), so by Newton's estimate the time is within |h / h'| of
// the true root, below 1e-13 relative.
TEST(EventLocation, PlacesAnImpactToMachinePrecision) {
  DO model;
  ExactPropagator prop(model);
  const Params prm = model.DefaultParams();
  AdvanceRequest req;
  req.mode = DO::kNoContact;
  req.x0 = (StateVector(4) << -60.1843757956, 2.7611141956, 0.0, 0.0).finished();
  req.t_max = kTwoPi / prm[DO::kOmega];
  const AdvanceResult r = prop.Advance(req, prm);
  ASSERT_EQ(r.end, AdvanceEnd::kEvent);
  const GuardValue g = model.Guard(DO::kNoContact, DO::kImpact, r.x, prm);
  const double scale = std::abs(req.x0[DO::kP]) + std::abs(req.x0[DO::kY]) * r.duration;
  EXPECT_LE(std::abs(g.h), 8 * 2.2e-16 * scale);
  EXPECT_LE(std::abs(g.h / g.dh), 1e-13 * r.duration);
  // The published impact phase, 5 decimals.
  EXPECT_NEAR(r.x[DO::kS], 1.16088, 1e-5);
}

// A free flight that leaves Pi tangentially (h = h' = 0, h'' = 3e-3, as just after a separation
// next to a grazing) and falls back onto it (h''' = -4.5): it rises to ~9e-10, above the 1e-12
// tolerance band, and its curvature bound (0.9) is 300 times the curvature it has, so that
// stepping on that bound alone takes steps of ~1e-6 at first, growing by ~6% each. With the
// closed form's third-derivative bound the steps span the flight: the same impact, located to the
// polishing's tolerance either way, at a fraction of the evaluations; and none where the window
// ends before the impact.
TEST(EventLocation, ShortFreeFlightAfterATangentialDepartureTakesFewSteps) {
  DO model;
  const Params prm = model.DefaultParams();
  const double xi = prm[DO::kXi], theta = 0.0;
  const double q = 4 * xi * xi * (prm[DO::kA] * std::cos(theta) + prm[DO::kB] + 3e-3);
  StateVector x0(4);
  x0[DO::kQ] = q, x0[DO::kY] = -q / (2 * xi), x0[DO::kP] = q + prm[DO::kG];
  x0[DO::kS] = theta - prm[DO::kPhi0];
  const GuardValue g = model.Guard(DO::kNoContact, DO::kImpact, x0, prm);
  ASSERT_NEAR(g.h, 0.0, 1e-15);
  ASSERT_NEAR(g.dh, 0.0, 1e-15);
  ASSERT_NEAR(g.ddh, 3e-3, 1e-12);
  // h ~ h'' t^2 / 2 + h''' t^3 / 6 returns to 0 at t ~ 3 h'' / |h'''|, h''' = -q / (8 xi^3).
  const double back = 9e-3 / (q / (8 * xi * xi * xi));
  ExactOptions by_expm;
  by_expm.use_closed_form = false;
  ExactPropagator closed(model), expm(model, by_expm);
  AdvanceRequest req;
  req.mode = DO::kNoContact, req.x0 = x0, req.t_max = 2 * back;
  const AdvanceResult fast = closed.Advance(req, prm), slow = expm.Advance(req, prm);
  ASSERT_EQ(fast.end, AdvanceEnd::kEvent);
  ASSERT_EQ(slow.end, AdvanceEnd::kEvent);
  EXPECT_EQ(fast.guard, DO::kImpact);
  // Each is polished to 1e-14, but h = q + g - p is known only to rounding, ~8 eps (q + g) (as in
  // the test above), and there h' ~ -3e-6: the root is known to 8 eps (q + g) / |h'| (~9e-11).
  const double rate = std::abs(model.Guard(DO::kNoContact, DO::kImpact, fast.x, prm).dh);
  EXPECT_NEAR(fast.duration, slow.duration, 8 * 2.2e-16 * (q + prm[DO::kG]) / rate);
  EXPECT_NEAR(fast.duration, back, 0.1 * back);
  EXPECT_LT(4 * fast.evaluations, slow.evaluations)
      << fast.evaluations << " against " << slow.evaluations;
  req.t_max = 0.5 * back;
  const AdvanceResult before = closed.Advance(req, prm);
  EXPECT_EQ(before.end, AdvanceEnd::kTimeLimit);
}

// On l2 (F = 2 xi y + q = 0, y = -q/(2 xi)) the separation guard's rate is
// F' = 2 xi (a cos s + b) - q/(2 xi): at s = 0 it is 0.045 - 10 q, so q = 0.001 departs (F rises)
// and q = 0.1 moves in (F falls).
StateVector OnSeparationSurface(double q, const Params& prm) {
  return ContactState(q, -q / (2 * prm[DO::kXi]), 0.0, prm);
}

TEST(EventLocation, DoesNotRefireAGuardItStartsOnWhileMovingAway) {
  DO model;
  ExactPropagator prop(model);
  const Params prm = model.DefaultParams();
  const StateVector x0 = OnSeparationSurface(0.001, prm);
  const GuardValue g = model.Guard(DO::kContact, DO::kSeparation, x0, prm);
  ASSERT_NEAR(g.h, 0.0, 1e-15);
  ASSERT_GT(g.dh, 0.0);
  AdvanceRequest req;
  req.mode = DO::kContact, req.x0 = x0, req.t_max = 0.5;
  const AdvanceResult r = prop.Advance(req, prm);
  ASSERT_TRUE(r.status.ok());
  EXPECT_EQ(r.end, AdvanceEnd::kTimeLimit);
}

TEST(EventLocation, FiresAtOnceWhenStartingOnASurfaceMovingIn) {
  DO model;
  ExactPropagator prop(model);
  const Params prm = model.DefaultParams();
  const StateVector x0 = OnSeparationSurface(0.1, prm);
  ASSERT_LT(model.Guard(DO::kContact, DO::kSeparation, x0, prm).dh, 0.0);
  AdvanceRequest req;
  req.mode = DO::kContact, req.x0 = x0, req.t_max = 1.0;
  const AdvanceResult r = prop.Advance(req, prm);
  ASSERT_EQ(r.end, AdvanceEnd::kEvent);
  EXPECT_EQ(r.guard, DO::kSeparation);
  EXPECT_EQ(r.duration, 0.0);
}

}  // namespace
}  // namespace drillbif
