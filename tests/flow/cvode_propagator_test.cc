// CvodePropagator against independent references: the closed-form solution of the forced linear
// oscillator (state, Jacobians, measures, event times), finite differences of its own flow map,
// and, as a sanity check on the first real model, the drifting oscillator's exact propagator.
//
// Error model used by the tolerances below. Per internal step CVODE keeps the local error of every
// component below rtol |x| + atol (WRMS norm <= 1, applied to states, quadratures and
// sensitivities alike). The oscillator's homogeneous flow is non-expansive (the transient energy
// x^2 + v^2 does not grow: its derivative is -4 zeta v^2), so local errors are not amplified and
// the global error after N steps is at most N (rtol max|x| + atol). At the tolerances used here
// CVODE takes fewer than 50 steps per unit time with either method (the step is also capped at
// max_step_fraction * TimeScale = 0.5), hence the bound
//     GlobalBound(t) = 50 (1 + t) (rtol max|x| + atol).
// It is loose (Adams is ~1000 times better: ~0.1 rtol |x| per unit time) but derived, not tuned.
#include "drillbif/flow/cvode_propagator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <ostream>
#include <stdexcept>
#include <string>

#include "drillbif/flow/exact_propagator.h"
#include "drillbif/model/drifting_oscillator.h"
#include "problems/forced_linear_oscillator.h"

namespace drillbif {
namespace {

using FLO = testing::ForcedLinearOscillator;

const StateVector kStart = FLO::MakeState(0.3, -0.2, 0.4);

CvodeOptions Options(double rtol, bool bdf = false) {
  CvodeOptions o;
  o.rtol = rtol;
  o.atol = 1e-2 * rtol;
  o.bdf = bdf;
  return o;
}

// See the error model at the top; xmax bounds |x| and |v| along the trajectories used (R + the
// transient, below 3.5 for kStart and the default parameters) or the sensitivities (below 3).
double GlobalBound(const CvodeOptions& o, double t, double xmax = 3.5) {
  return 50.0 * (1.0 + t) * (o.rtol * xmax + o.atol);
}

// ---------------------------------------------------------------------------------------------
// Options and inputs.

TEST(CvodeOptionsTest, DefaultsAreValid) { EXPECT_TRUE(CvodeOptions{}.Validate().ok()); }

TEST(CvodeOptionsTest, InvalidOptionsAreRejectedNamingTheField) {
  struct Case {
    CvodeOptions options;
    const char* field;
  };
  std::vector<Case> cases;
  CvodeOptions o;
  o.rtol = 0.0;
  cases.push_back({o, "rtol"});
  o = {};
  o.rtol = 0.1;
  cases.push_back({o, "rtol"});
  o = {};
  o.rtol = NAN;
  cases.push_back({o, "rtol"});
  o = {};
  o.atol = 0.0;
  cases.push_back({o, "atol"});
  o = {};
  o.atol = -1e-12;
  cases.push_back({o, "atol"});
  o = {};
  o.max_steps = 0;
  cases.push_back({o, "max_steps"});
  o = {};
  o.events.tolerance = -1.0;
  cases.push_back({o, "tolerance"});
  for (const Case& c : cases) {
    const Status s = c.options.Validate();
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << c.field;
    EXPECT_NE(s.message().find(c.field), std::string::npos) << s.message();
  }
}

TEST(CvodeOptionsTest, APropagatorWithInvalidOptionsReturnsTheErrorFromEveryCall) {
  const FLO model;
  CvodeOptions o;
  o.rtol = 1.0;
  CvodePropagator prop(model, o);
  const FlowResult f = prop.FlowMap(FLO::kFree, kStart, 1.0, model.DefaultParams(), {});
  EXPECT_EQ(f.status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(f.status.message().find("rtol"), std::string::npos);
  AdvanceRequest req;
  req.x0 = kStart;
  req.t_max = 1.0;
  const AdvanceResult a = prop.Advance(req, model.DefaultParams());
  EXPECT_EQ(a.status.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(a.end, AdvanceEnd::kFailed);
}

TEST(CvodeInputTest, InvalidInputsAreRejectedWithoutIntegrating) {
  const FLO model;
  CvodePropagator prop(model);
  const Params p = model.DefaultParams();
  EXPECT_EQ(prop.FlowMap(FLO::kFree, kStart, -1.0, p, {}).status.code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(prop.FlowMap(FLO::kFree, kStart, INFINITY, p, {}).status.code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(prop.FlowMap(1, kStart, 1.0, p, {}).status.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(prop.FlowMap(FLO::kFree, FLO::MakeState(NAN, 0, 0), 1.0, p, {}).status.code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(prop.FlowMap(FLO::kFree, StateVector::Zero(2), 1.0, p, {}).status.code(),
            StatusCode::kInvalidArgument);
  const Status bad_params = prop.FlowMap(FLO::kFree, kStart, 1.0, FLO::MakeParams(2.0), {}).status;
  EXPECT_EQ(bad_params.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad_params.message().find("zeta"), std::string::npos);
  AdvanceRequest req;
  req.x0 = kStart;
  req.t_max = -1.0;
  EXPECT_EQ(prop.Advance(req, p).status.code(), StatusCode::kInvalidArgument);
  req.t_max = 1.0;
  req.sample_dt = -0.1;
  EXPECT_EQ(prop.Advance(req, p).status.code(), StatusCode::kInvalidArgument);
}

// ---------------------------------------------------------------------------------------------
// FlowMap.

TEST(CvodeFlowMapTest, ZeroTimeReturnsTheInitialStateAndIdentity) {
  const FLO model;
  CvodePropagator prop(model);
  const FlowResult r = prop.FlowMap(FLO::kFree, kStart, 0.0, model.DefaultParams(), {true, true});
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  EXPECT_EQ(r.x, kStart);
  EXPECT_EQ(r.state_jacobian, StateMatrix::Identity(3, 3));
  EXPECT_EQ(r.param_jacobian, ParamMatrix::Zero(3, 5));
}

TEST(CvodeFlowMapTest, MatchesTheClosedFormWithinTheRequestedAccuracy) {
  const FLO model;
  const Params p = model.DefaultParams();
  for (bool bdf : {false, true}) {
    for (double rtol : {1e-8, 1e-10, 1e-12}) {
      CvodeOptions o = Options(rtol, bdf);
      o.max_step_fraction = (rtol == 1e-10) ? 0.0 : 0.5;  // also without a step bound
      CvodePropagator prop(model, o);
      for (double t : {0.5, 10.0, 50.0}) {
        const FlowResult r = prop.FlowMap(FLO::kFree, kStart, t, p, {});
        ASSERT_TRUE(r.status.ok()) << r.status.ToString();
        const StateVector exact = FLO::ExactState(kStart, t, p);
        EXPECT_LE((r.x - exact).cwiseAbs().maxCoeff(), GlobalBound(o, t))
            << "bdf " << bdf << " rtol " << rtol << " t " << t;
        // The phase is integrated, not wrapped: s0 + omega t even past 2 pi.
        EXPECT_NEAR(r.x[FLO::kS], kStart[FLO::kS] + p[FLO::kOmega] * t, 1e-9 * (1 + t));
      }
    }
  }
}

TEST(CvodeFlowMapTest, StateJacobianMatchesTheClosedForm) {
  const FLO model;
  const Params p = model.DefaultParams();
  for (bool bdf : {false, true}) {
    const CvodeOptions o = Options(1e-10, bdf);
    CvodePropagator prop(model, o);
    for (double t : {0.5, 10.0, 50.0}) {
      const FlowResult r = prop.FlowMap(FLO::kFree, kStart, t, p, {true, false});
      ASSERT_TRUE(r.status.ok()) << r.status.ToString();
      StateVector x;
      StateMatrix j;
      model.Flow(FLO::kFree, kStart, t, p, &x, &j);
      // The sensitivities are integrated under the same error control as the state.
      EXPECT_LE((r.state_jacobian - j).cwiseAbs().maxCoeff(), GlobalBound(o, t))
          << "bdf " << bdf << " t " << t;
      EXPECT_LE((r.x - x).cwiseAbs().maxCoeff(), GlobalBound(o, t));
    }
  }
}

// d x(t) / d params against central differences of the closed form (step 1e-6: truncation
// ~ 1e-12 |x'''|, rounding ~ eps |x| / 1e-6 ~ 1e-10), within the integration bound.
TEST(CvodeFlowMapTest, ParamJacobianMatchesFiniteDifferencesOfTheClosedForm) {
  const FLO model;
  const Params p = model.DefaultParams();
  const CvodeOptions o = Options(1e-10);
  CvodePropagator prop(model, o);
  for (double t : {0.5, 10.0}) {
    const FlowResult r = prop.FlowMap(FLO::kFree, kStart, t, p, {false, true});
    ASSERT_TRUE(r.status.ok()) << r.status.ToString();
    for (int k = 0; k < model.num_params(); ++k) {
      const double d = 1e-6;
      Params pp = p, pm = p;
      pp[k] += d, pm[k] -= d;
      const StateVector fd =
          (FLO::ExactState(kStart, t, pp) - FLO::ExactState(kStart, t, pm)) / (2 * d);
      // Parameter sensitivities reach |ds/domega| = t and |dx/dA| ~ R/A ~ 2.5.
      EXPECT_LE((r.param_jacobian.col(k) - fd).cwiseAbs().maxCoeff(),
                GlobalBound(o, t, 3.5 + t) + 1e-9)
          << model.param_names()[k] << " t " << t;
    }
  }
}

// Both Jacobians against central differences of FlowMap itself at rtol 1e-12, step d = 1e-5. The
// perturbation changes CVODE's step sequence (its initial step and order changes depend on the
// data), so the two runs' global errors (~5e-13 at rtol 1e-12 over t = 3 on this problem) do not
// cancel: the quotient carries up to 2 * 5e-13 / (2 d) = 5e-8, plus truncation d^2 |x'''| / 6
// < 1e-10 (the flow is affine in x0 and v0, smooth in s0 and the parameters) and the
// sensitivities' own error (same size as the state's): 1e-6 leaves a margin of 20.
TEST(CvodeFlowMapTest, JacobiansMatchFiniteDifferencesOfTheFlowMap) {
  const FLO model;
  const Params p = model.DefaultParams();
  CvodePropagator prop(model, Options(1e-12));
  const double t = 3.0;
  const FlowResult r = prop.FlowMap(FLO::kFree, kStart, t, p, {true, true});
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  const double d = 1e-5;
  for (int c = 0; c < 3; ++c) {
    StateVector xp = kStart, xm = kStart;
    xp[c] += d, xm[c] -= d;
    const StateVector fd =
        (prop.FlowMap(FLO::kFree, xp, t, p, {}).x - prop.FlowMap(FLO::kFree, xm, t, p, {}).x) /
        (2 * d);
    EXPECT_LE((r.state_jacobian.col(c) - fd).cwiseAbs().maxCoeff(), 1e-6) << "x0[" << c << "]";
  }
  for (int k = 0; k < model.num_params(); ++k) {
    Params pp = p, pm = p;
    pp[k] += d, pm[k] -= d;
    const StateVector fd = (prop.FlowMap(FLO::kFree, kStart, t, pp, {}).x -
                            prop.FlowMap(FLO::kFree, kStart, t, pm, {}).x) /
                           (2 * d);
    EXPECT_LE((r.param_jacobian.col(k) - fd).cwiseAbs().maxCoeff(), 1e-6) << model.param_names()[k];
  }
}

// The integrator is reused across calls (re-initialised, sensitivities toggled or re-allocated):
// any sequence of requests gives the same results as a fresh propagator for each.
TEST(CvodeFlowMapTest, ReusingTheIntegratorAcrossRequestsGivesFreshResults) {
  const FLO model;
  const Params p = model.DefaultParams();
  CvodePropagator reused(model);
  const FlowRequest requests[] = {{false, false}, {true, false}, {true, true}, {false, true},
                                  {false, false}, {true, true},  {true, false}};
  for (int round = 0; round < 2; ++round) {
    for (const FlowRequest& rq : requests) {
      CvodePropagator fresh(model);
      const FlowResult a = reused.FlowMap(FLO::kFree, kStart, 4.0, p, rq);
      const FlowResult b = fresh.FlowMap(FLO::kFree, kStart, 4.0, p, rq);
      ASSERT_TRUE(a.status.ok() && b.status.ok()) << a.status.ToString() << b.status.ToString();
      EXPECT_EQ(a.x, b.x);
      if (rq.state_jacobian) {
        EXPECT_EQ(a.state_jacobian, b.state_jacobian);
      }
      if (rq.param_jacobian) {
        EXPECT_EQ(a.param_jacobian, b.param_jacobian);
      }
      // An Advance in between must not disturb the next FlowMap either.
      AdvanceRequest adv;
      adv.x0 = kStart;
      adv.t_max = 2.0;
      adv.measures = round == 0;
      EXPECT_TRUE(reused.Advance(adv, p).status.ok());
    }
  }
}

// ---------------------------------------------------------------------------------------------
// Advance: events.

// The wall is crossed with velocity v ~ 1, so the event time is as accurate as the state:
// |dt| <= |dx| / |v| <= GlobalBound / |v|.
TEST(CvodeAdvanceTest, FindsTheWallAtTheClosedFormTime) {
  const FLO model;
  Params p = model.DefaultParams();
  p[FLO::kWall] = 0.2;
  const StateVector x0 = FLO::MakeState(-1.0, 0.5, 0.0);
  const double t_cross = FLO::FirstUpCrossing(x0, 0.2, 20.0, p);
  ASSERT_GT(t_cross, 0.0);
  const double v_cross = FLO::ExactState(x0, t_cross, p)[FLO::kV];
  ASSERT_GT(v_cross, 0.5);
  for (bool bdf : {false, true}) {
    const CvodeOptions o = Options(1e-10, bdf);
    CvodePropagator prop(model, o);
    AdvanceRequest req;
    req.x0 = x0;
    req.t_max = 20.0;
    const AdvanceResult r = prop.Advance(req, p);
    ASSERT_TRUE(r.status.ok()) << r.status.ToString();
    ASSERT_EQ(r.end, AdvanceEnd::kEvent);
    EXPECT_EQ(r.guard, FLO::kWallGuard);
    EXPECT_FALSE(r.tangential);
    EXPECT_NEAR(r.duration, t_cross, GlobalBound(o, t_cross) / v_cross) << "bdf " << bdf;
    // CVODE's root finder stops within 100 uround (|t| + |h|) of the root: |h| <= that times |v|.
    EXPECT_LE(std::abs(p[FLO::kWall] - r.x[FLO::kX]), 1e-12);
    EXPECT_GT(r.evaluations, 0);
  }
}

TEST(CvodeAdvanceTest, StopsAtTheTimeLimitWhenNoGuardFires) {
  const FLO model;
  Params p = model.DefaultParams();
  p[FLO::kWall] = 10.0;  // beyond the reach of the motion
  const CvodeOptions o = Options(1e-10);
  CvodePropagator prop(model, o);
  AdvanceRequest req;
  req.x0 = kStart;
  req.t_max = 7.5;
  const AdvanceResult r = prop.Advance(req, p);
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  EXPECT_EQ(r.end, AdvanceEnd::kTimeLimit);
  EXPECT_EQ(r.guard, -1);
  EXPECT_DOUBLE_EQ(r.duration, 7.5);
  EXPECT_LE((r.x - FLO::ExactState(kStart, 7.5, p)).cwiseAbs().maxCoeff(), GlobalBound(o, 7.5));
}

TEST(CvodeAdvanceTest, ZeroTimeLimitReturnsTheStartState) {
  const FLO model;
  CvodePropagator prop(model);
  AdvanceRequest req;
  req.x0 = kStart;
  req.t_max = 0.0;
  req.measures = true;
  req.sample_dt = 0.1;
  const AdvanceResult r = prop.Advance(req, model.DefaultParams());
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  EXPECT_EQ(r.end, AdvanceEnd::kTimeLimit);
  EXPECT_EQ(r.duration, 0.0);
  EXPECT_EQ(r.x, kStart);
  EXPECT_EQ(r.measures, MeasureVector::Zero(2));
  ASSERT_EQ(r.samples.size(), 1u);
}

// Grazing: the wall is placed at the closed-form maximum of x (~0.42, at t ~ 1.6) plus a signed
// gap. At rtol 1e-11 the computed maximum is within ~6e-12 of the closed form's (measured; Adams'
// early-time error is 5-15 local tolerances rtol |x|), well below the 1e-10 penetration and the
// 1e-8 miss. (At the default rtol 1e-10 the error, ~2e-10, would hide a 1e-10 penetration.)
class CvodeGrazeTest : public ::testing::Test {
 protected:
  void SetUp() override {
    p_ = model_.DefaultParams();
    ASSERT_TRUE(FLO::FirstMaximum(kStart, 20.0, p_, &t_max_, &x_max_));
  }
  AdvanceResult Run(double gap, CvodeOptions o = Options(1e-11)) {
    CvodePropagator prop(model_, o);
    Params p = p_;
    p[FLO::kWall] = x_max_ + gap;
    AdvanceRequest req;
    req.x0 = kStart;
    req.t_max = t_max_ + 1.0;
    return prop.Advance(req, p);
  }
  FLO model_;
  Params p_;
  double t_max_ = 0.0, x_max_ = 0.0;
};

// A penetration of 1e-10 crosses the wall for ~2e-5 time units: narrower than any internal step,
// yet found, because the minimum of h = w - x is itself a located root. The crossing is reported
// (as by the exact propagator) and flagged tangential: its dip is below d_graze = 100 (rtol |x| +
// atol) ~ 4e-10, the depth the integrator cannot tell from a touch.
TEST_F(CvodeGrazeTest, DetectsAPenetrationOfOneTenthOfANanometreAsTangential) {
  const AdvanceResult r = Run(-1e-10);
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  ASSERT_EQ(r.end, AdvanceEnd::kEvent);
  EXPECT_EQ(r.guard, FLO::kWallGuard);
  EXPECT_TRUE(r.tangential);
  // At the crossing, within the parabola's half-width sqrt(2 1e-10 / |x''|) ~ 2e-5 of the maximum.
  const double half_width =
      std::sqrt(2e-10 / std::abs(model_.Guard(0, 0, FLO::ExactState(kStart, t_max_, p_), p_).ddh));
  EXPECT_LE(r.duration, t_max_ + 1e-6);
  EXPECT_GE(r.duration, t_max_ - 2.0 * half_width);
  EXPECT_LE(std::abs(x_max_ - 1e-10 - r.x[FLO::kX]), 1e-12);
}

TEST_F(CvodeGrazeTest, IgnoresANearMissOfTenNanometres) {
  const AdvanceResult r = Run(1e-8);
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  EXPECT_EQ(r.end, AdvanceEnd::kTimeLimit);
  EXPECT_DOUBLE_EQ(r.duration, t_max_ + 1.0);
}

// A deep crossing is transversal.
TEST_F(CvodeGrazeTest, FlagsADeepCrossingAsTransversal) {
  const AdvanceResult r = Run(-1e-3);
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  ASSERT_EQ(r.end, AdvanceEnd::kEvent);
  EXPECT_FALSE(r.tangential);
}

// With a tolerance band of 1e-9, a miss by 5e-10 touches the band: a tangential event at the
// minimum of h, where x' = 0. The minimum is the root of h' = -v, located to |dv| <= ~1e-11, so its
// time is within |dv| / |v'| ~ 1e-10 of the closed form's (|v'| ~ 0.4).
TEST_F(CvodeGrazeTest, TouchingTheToleranceBandIsATangentialEventAtTheMinimum) {
  CvodeOptions o = Options(1e-11);
  o.events.tolerance = 1e-9;
  const AdvanceResult r = Run(5e-10, o);
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  ASSERT_EQ(r.end, AdvanceEnd::kEvent);
  EXPECT_TRUE(r.tangential);
  EXPECT_NEAR(r.duration, t_max_, 1e-8);
  EXPECT_NEAR(r.x[FLO::kV], 0.0, 1e-10);
}

// After an impact the simulator restarts on the wall with the reflected velocity: the guard it
// starts on must not fire again at once, and the next impact comes at the closed-form time.
TEST(CvodeAdvanceTest, StartingOnTheWallAndLeavingItDoesNotRefire) {
  const FLO model;
  Params p = model.DefaultParams();
  p[FLO::kWall] = 1.0;
  const StateVector x0 = FLO::MakeState(1.0, -0.9, 0.3);  // on the wall, moving away
  const double t_next = FLO::FirstUpCrossing(FLO::MakeState(1.0 - 1e-9, -0.9, 0.3), 1.0, 30.0, p);
  ASSERT_GT(t_next, 1.0);
  const CvodeOptions o = Options(1e-10);
  CvodePropagator prop(model, o);
  AdvanceRequest req;
  req.x0 = x0;
  req.t_max = 30.0;
  const AdvanceResult r = prop.Advance(req, p);
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  ASSERT_EQ(r.end, AdvanceEnd::kEvent);
  // Starting 1e-9 below the wall changes the crossing time by ~1e-9 / |v|; allow 1e-6.
  EXPECT_NEAR(r.duration, t_next, 1e-6);
}

TEST(CvodeAdvanceTest, StartingOnTheWallMovingIntoItFiresAtOnce) {
  const FLO model;
  Params p = model.DefaultParams();
  p[FLO::kWall] = 1.0;
  CvodePropagator prop(model);
  AdvanceRequest req;
  req.x0 = FLO::MakeState(1.0, 0.5, 0.3);
  req.t_max = 30.0;
  req.sample_dt = 0.1;
  const AdvanceResult r = prop.Advance(req, p);
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  ASSERT_EQ(r.end, AdvanceEnd::kEvent);
  EXPECT_EQ(r.guard, FLO::kWallGuard);
  EXPECT_FALSE(r.tangential);
  EXPECT_EQ(r.duration, 0.0);
  EXPECT_EQ(r.x, req.x0);
  ASSERT_EQ(r.samples.size(), 1u);  // the end point only
}

// A bouncing sequence driven like the simulator (Advance, Jump, Advance, ...) against the chain of
// closed-form flights. Each impact time is ill-conditioned only through the error carried in the
// state, which stays below the global bound over the whole run.
TEST(CvodeAdvanceTest, ASequenceOfImpactsFollowsTheClosedForm) {
  const FLO model;
  Params p = model.DefaultParams();
  p[FLO::kWall] = 1.0;
  const CvodeOptions o = Options(1e-11);
  CvodePropagator prop(model, o);
  StateVector x = FLO::MakeState(0.0, 0.0, 0.0), xe = x;
  double t_total = 0.0;
  int impacts = 0;
  while (impacts < 6 && t_total < 100.0) {
    AdvanceRequest req;
    req.x0 = x;
    req.t_max = 100.0 - t_total;
    const AdvanceResult r = prop.Advance(req, p);
    ASSERT_TRUE(r.status.ok()) << r.status.ToString();
    if (r.end != AdvanceEnd::kEvent) break;
    // Reference flight: from the reference state, nudged off the wall so that the closed-form
    // search does not find the start itself.
    StateVector ref0 = xe;
    if (impacts > 0) ref0[FLO::kX] -= 1e-12;
    const double t_ref = FLO::FirstUpCrossing(ref0, 1.0, req.t_max, p);
    ASSERT_GT(t_ref, 0.0);
    t_total += r.duration;
    EXPECT_NEAR(r.duration, t_ref, 1e-6) << "impact " << impacts;
    xe = FLO::ExactState(ref0, t_ref, p);
    EXPECT_LE((r.x - xe).cwiseAbs().maxCoeff(), 1e-6) << "impact " << impacts;
    x = model.Jump(FLO::kFree, r.guard, r.x, p).x;
    xe = model.Jump(FLO::kFree, 0, xe, p).x;
    ++impacts;
  }
  EXPECT_GE(impacts, 3);
}

// ---------------------------------------------------------------------------------------------
// Advance: measures and samples.

TEST(CvodeAdvanceTest, MeasuresMatchTheirClosedForms) {
  const FLO model;
  Params p = model.DefaultParams();
  p[FLO::kWall] = 10.0;
  for (bool bdf : {false, true}) {
    const CvodeOptions o = Options(1e-10, bdf);
    CvodePropagator prop(model, o);
    AdvanceRequest req;
    req.x0 = kStart;
    req.t_max = 12.0;
    req.measures = true;
    const AdvanceResult r = prop.Advance(req, p);
    ASSERT_TRUE(r.status.ok()) << r.status.ToString();
    ASSERT_EQ(r.measures.size(), 2);
    const MeasureVector exact = model.MeasureIncrements(FLO::kFree, kStart, 12.0, p);
    // The quadratures are under the same error control; their values reach ~ R t ~ 30.
    EXPECT_LE((r.measures - exact).cwiseAbs().maxCoeff(), GlobalBound(o, 12.0, 30.0))
        << "bdf " << bdf;
  }
}

TEST(CvodeAdvanceTest, MeasuresStopAtTheEvent) {
  const FLO model;
  Params p = model.DefaultParams();
  p[FLO::kWall] = 0.2;
  const StateVector x0 = FLO::MakeState(-1.0, 0.5, 0.0);
  const CvodeOptions o = Options(1e-10);
  CvodePropagator prop(model, o);
  AdvanceRequest req;
  req.x0 = x0;
  req.t_max = 20.0;
  req.measures = true;
  const AdvanceResult r = prop.Advance(req, p);
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  ASSERT_EQ(r.end, AdvanceEnd::kEvent);
  // The displacement is x(t_event) - x0 = w - x0, exactly known.
  EXPECT_NEAR(r.measures[FLO::kDisplacement], 0.2 - x0[FLO::kX], GlobalBound(o, r.duration, 30.0));
  const MeasureVector exact = model.MeasureIncrements(FLO::kFree, x0, r.duration, p);
  EXPECT_NEAR(r.measures[FLO::kPositionIntegral], exact[FLO::kPositionIntegral],
              GlobalBound(o, r.duration, 30.0));
}

TEST(CvodeAdvanceTest, SamplesLieOnTheTrajectoryAtMultiplesOfTheStep) {
  const FLO model;
  Params p = model.DefaultParams();
  p[FLO::kWall] = 0.2;
  const StateVector x0 = FLO::MakeState(-1.0, 0.5, 0.0);
  const CvodeOptions o = Options(1e-10);
  CvodePropagator prop(model, o);
  AdvanceRequest req;
  req.x0 = x0;
  req.t_max = 20.0;
  req.sample_dt = 0.05;
  const AdvanceResult r = prop.Advance(req, p);
  ASSERT_TRUE(r.status.ok()) << r.status.ToString();
  ASSERT_EQ(r.end, AdvanceEnd::kEvent);
  // t = 0, dt, 2 dt, ... < duration, then the end point.
  const size_t expected = static_cast<size_t>(std::ceil(r.duration / req.sample_dt)) + 1;
  ASSERT_EQ(r.samples.size(), expected);
  for (size_t k = 0; k + 1 < r.samples.size(); ++k) {
    EXPECT_DOUBLE_EQ(r.samples[k].t, k * req.sample_dt);
    // Dense output is accurate to the order of the method, like the steps' end points.
    EXPECT_LE((r.samples[k].x - FLO::ExactState(x0, r.samples[k].t, p)).cwiseAbs().maxCoeff(),
              GlobalBound(o, r.samples[k].t))
        << "sample " << k;
  }
  EXPECT_EQ(r.samples.back().t, r.duration);
  EXPECT_EQ(r.samples.back().x, r.x);
}

// ---------------------------------------------------------------------------------------------
// Failures become statuses, never NaN or exceptions.

// The oscillator with a vector field that is poisoned beyond x = 1 (NaN or an exception).
class PoisonedOscillator final : public HybridModel {
 public:
  explicit PoisonedOscillator(bool throws) : throws_(throws) {}
  std::string_view name() const override { return "poisoned"; }
  int state_dim() const override { return base_.state_dim(); }
  int phase_index() const override { return base_.phase_index(); }
  const std::vector<std::string>& state_names() const override { return base_.state_names(); }
  int num_modes() const override { return 1; }
  std::string_view mode_name(int m) const override { return base_.mode_name(m); }
  const std::vector<std::string>& param_names() const override { return base_.param_names(); }
  Params DefaultParams() const override { return base_.DefaultParams(); }
  double ForcingFrequency(const Params& p) const override { return base_.ForcingFrequency(p); }
  Status ValidateParams(const Params& p) const override { return base_.ValidateParams(p); }
  Status ValidateState(const StateVector& x, const Params& p, double tol) const override {
    return base_.ValidateState(x, p, tol);
  }
  int ModeAt(const StateVector& x, const Params& p) const override { return base_.ModeAt(x, p); }
  void VectorField(int m, const StateVector& x, const Params& p, StateVector* dx) const override {
    base_.VectorField(m, x, p, dx);
    if (x[FLO::kX] > 1.0) {
      if (throws_) throw std::runtime_error("poisoned region");
      (*dx)[FLO::kV] = NAN;
    }
  }
  void StateJacobian(int m, const StateVector& x, const Params& p, StateMatrix* j) const override {
    base_.StateJacobian(m, x, p, j);
  }
  void ParamJacobian(int m, const StateVector& x, const Params& p, ParamMatrix* j) const override {
    base_.ParamJacobian(m, x, p, j);
  }
  const std::vector<GuardSpec>& guards(int m) const override { return base_.guards(m); }
  GuardValue Guard(int m, int g, const StateVector& x, const Params& p) const override {
    return base_.Guard(m, g, x, p);
  }
  StateRow GuardGradient(int m, int g, const StateVector& x, const Params& p) const override {
    return base_.GuardGradient(m, g, x, p);
  }
  ParamVector GuardParamGradient(int m, int g, const StateVector& x,
                                 const Params& p) const override {
    return base_.GuardParamGradient(m, g, x, p);
  }
  double GuardCurvatureBound(int m, int g, const StateVector& x, const Params& p) const override {
    return base_.GuardCurvatureBound(m, g, x, p);
  }
  Transition Jump(int m, int g, const StateVector& x, const Params& p) const override {
    return base_.Jump(m, g, x, p);
  }
  const std::vector<std::string>& measure_names() const override { return base_.measure_names(); }
  MeasureVector MeasureRates(int m, const StateVector& x, const Params& p) const override {
    return base_.MeasureRates(m, x, p);
  }
  double TimeScale(int m, const Params& p) const override { return base_.TimeScale(m, p); }

 private:
  FLO base_;
  bool throws_;
};

TEST(CvodeFailureTest, ANonFiniteVectorFieldIsAnInternalErrorNamingTheCvodeFlag) {
  for (bool throws : {false, true}) {
    const PoisonedOscillator model(throws);
    Params p = model.DefaultParams();
    p[FLO::kWall] = 10.0;
    CvodePropagator prop(model);
    const StateVector x0 = FLO::MakeState(0.0, 2.0, 0.0);  // reaches x > 1 quickly
    const FlowResult f = prop.FlowMap(0, x0, 5.0, p, {true, true});
    EXPECT_EQ(f.status.code(), StatusCode::kInternal) << "throws " << throws;
    EXPECT_NE(f.status.message().find("CV_"), std::string::npos) << f.status.message();
    EXPECT_TRUE(f.x.allFinite());
    AdvanceRequest req;
    req.x0 = x0;
    req.t_max = 5.0;
    req.measures = true;
    req.sample_dt = 0.1;
    const AdvanceResult a = prop.Advance(req, p);
    EXPECT_EQ(a.end, AdvanceEnd::kFailed);
    EXPECT_EQ(a.status.code(), StatusCode::kInternal);
    EXPECT_NE(a.status.message().find("CV_"), std::string::npos) << a.status.message();
    if (throws) {
      EXPECT_NE(a.status.message().find("poisoned region"), std::string::npos)
          << a.status.message();
    }
    EXPECT_TRUE(a.x.allFinite());
    // The propagator is still usable afterwards.
    const FlowResult ok = prop.FlowMap(0, FLO::MakeState(0.0, 0.1, 0.0), 0.5, p, {});
    EXPECT_TRUE(ok.status.ok()) << ok.status.ToString();
  }
}

TEST(CvodeFailureTest, ExceedingMaxStepsIsAnInternalError) {
  const FLO model;
  Params p = model.DefaultParams();
  p[FLO::kWall] = 10.0;
  CvodeOptions o;
  o.max_steps = 5;
  CvodePropagator prop(model, o);
  const FlowResult f = prop.FlowMap(FLO::kFree, kStart, 50.0, p, {});
  EXPECT_EQ(f.status.code(), StatusCode::kInternal);
  EXPECT_NE(f.status.message().find("CV_TOO_MUCH_WORK"), std::string::npos) << f.status.message();
  AdvanceRequest req;
  req.x0 = kStart;
  req.t_max = 50.0;
  const AdvanceResult a = prop.Advance(req, p);
  EXPECT_EQ(a.end, AdvanceEnd::kFailed);
  EXPECT_NE(a.status.message().find("max_steps"), std::string::npos) << a.status.message();
}

// ---------------------------------------------------------------------------------------------
// Sanity check on the drifting oscillator (the cross-checks against the exact propagator proper
// live with the simulator's tests): from rest in free flight at the reference parameters the bit
// accelerates onto the slider, and both propagators see the same impact.
TEST(CvodeDriftingOscillatorTest, FindsTheImpactFromRestLikeTheExactPropagator) {
  const DriftingOscillator model;
  const Params p = model.DefaultParams();
  const StateVector x0 = StateVector::Zero(4);
  AdvanceRequest req;
  req.mode = DriftingOscillator::kNoContact;
  req.x0 = x0;
  req.t_max = kTwoPi / p[DriftingOscillator::kOmega];
  req.measures = true;
  CvodePropagator cvode(model);
  ExactPropagator exact(model);
  const AdvanceResult c = cvode.Advance(req, p);
  const AdvanceResult e = exact.Advance(req, p);
  ASSERT_TRUE(c.status.ok()) << c.status.ToString();
  ASSERT_TRUE(e.status.ok()) << e.status.ToString();
  ASSERT_EQ(c.end, AdvanceEnd::kEvent);
  ASSERT_EQ(e.end, AdvanceEnd::kEvent);
  EXPECT_EQ(c.guard, DriftingOscillator::kImpact);
  EXPECT_EQ(c.guard, e.guard);
  // A transversal impact after a short flight: the times agree to the integration accuracy.
  EXPECT_NEAR(c.duration, e.duration, 1e-7 * (1.0 + e.duration));
  EXPECT_LE((c.x - e.x).cwiseAbs().maxCoeff(), 1e-7 * (1.0 + e.x.cwiseAbs().maxCoeff()));
  EXPECT_LE(std::abs(model.Guard(req.mode, c.guard, c.x, p).h), 1e-10);
  ASSERT_EQ(c.measures.size(), e.measures.size());
  EXPECT_LE((c.measures - e.measures).cwiseAbs().maxCoeff(), 1e-7);
}

// Free flights that start on Pi, from states long simulations reached (hex literals: the failures
// depended on the last bits). At a separation F = 0, so the next flight starts with the impact
// guard h = q + g - p and its rate h' = -F / (2 xi) both at rounding level. CVODE cannot give a
// direction to a root function that is zero to rounding at a root it has just returned (cvRcheck2:
// CV_ILL_INPUT "Root found at and very near t"); each of these used to fail that way within 1e-10
// time units. Both propagators must instead fly to the section with no event, to the same state.
struct SurfaceStartCase {
  const char* name;
  double xi;
  StateVector x0;
  bool measures;  // the quadrature changes CVODE's steps, and which start failed
};

void PrintTo(const SurfaceStartCase& c, std::ostream* os) { *os << c.name; }

class CvodeSurfaceStartTest : public ::testing::TestWithParam<SurfaceStartCase> {};

TEST_P(CvodeSurfaceStartTest, FliesToTheSectionLikeTheExactPropagator) {
  const DriftingOscillator model;
  Params p = model.DefaultParams();
  p[DriftingOscillator::kXi] = GetParam().xi;
  AdvanceRequest req;
  req.mode = DriftingOscillator::kNoContact;
  req.x0 = GetParam().x0;
  req.t_max = (kTwoPi - req.x0[DriftingOscillator::kS]) / p[DriftingOscillator::kOmega];
  req.measures = GetParam().measures;
  const CvodeOptions o;  // the defaults, as the simulator uses them
  CvodePropagator cvode(model, o);
  ExactPropagator exact(model);
  const AdvanceResult c = cvode.Advance(req, p);
  const AdvanceResult e = exact.Advance(req, p);
  ASSERT_TRUE(c.status.ok()) << c.status.ToString();
  ASSERT_TRUE(e.status.ok()) << e.status.ToString();
  ASSERT_EQ(e.end, AdvanceEnd::kTimeLimit);
  ASSERT_EQ(c.end, AdvanceEnd::kTimeLimit);
  EXPECT_EQ(c.duration, req.t_max);
  // One flight of ~41 time units: CVODE's global error stays within K = 100 local tolerances
  // rtol |x| + atol (the error model of tests/simulate/propagator_agreement_test.cc).
  const double xmax = 1.0 + e.x.cwiseAbs().maxCoeff();
  EXPECT_LE((c.x - e.x).cwiseAbs().maxCoeff(), 100.0 * (o.rtol * xmax + o.atol));
  if (req.measures) {
    ASSERT_EQ(c.measures.size(), e.measures.size());
    EXPECT_LE((c.measures - e.measures).cwiseAbs().maxCoeff(),
              100.0 * (o.rtol * (1.0 + e.measures.cwiseAbs().maxCoeff()) + o.atol));
  }
}

StateVector NoContactState(double p, double y, double q, double s) {
  StateVector x(4);
  x << p, y, q, s;
  return x;
}

INSTANTIATE_TEST_SUITE_P(
    AfterSeparation, CvodeSurfaceStartTest,
    ::testing::Values(
        // Reference parameters, period 445 from rest: h = 7e-16 (inside the band, departing) and
        // h' = -1.1e-16, so that h has a minimum at t = 1.2e-17, where h' is exactly zero and stays
        // so for longer than CVODE's root separation ttol ~ 1e-20.
        SurfaceStartCase{"DepartingWithARoundingLevelMinimum", 0.05,
                         NoContactState(0x1.cee53848d997cp-4, -0x1.dc381ff4a99b3p-1,
                                        0x1.7cf9b32a2149p-4, 0x1.14edfad51d842p+1),
                         false},
        // The same 2e-12 lower: h = 2e-12 is above the band, so the guard takes part from the
        // start, and the same minimum at t = 1.2e-17 is a near miss (h > tolerance) to step past.
        SurfaceStartCase{"NearMissJustAboveTheBand", 0.05,
                         NoContactState(0x1.cee53848b6689p-4, -0x1.dc381ff4a99b3p-1,
                                        0x1.7cf9b32a2149p-4, 0x1.14edfad51d842p+1),
                         false},
        // xi = 0.5, period 518 from rest: h = 0 exactly and h' = 3.3e-15: h stays zero to
        // rounding for ~1e-10 time units.
        SurfaceStartCase{"ExactlyOnTheSurfaceAtXiOneHalf", 0.5,
                         NoContactState(0x1.12c45f331abc1p-4, -0x1.81b1b428c4f2p-5,
                                        0x1.81b1b428c4d45p-5, 0x1.1637e16e7ef0cp+1),
                         true}),
    [](const auto& test_info) { return std::string(test_info.param.name); });

// A guard that starts on its surface, leaves the band for a moment (peak 5e-11 from the wall,
// above the tolerance 1e-12, at t = |v| / |x''| = 1e-5) and comes back is a crossing at the
// return, 2 |v| / |x''| = 2e-5, as in the exact propagator: masking its root functions while it is
// inside the band must neither hide the return nor fire at the start.
TEST(CvodeAdvanceTest, LeavingTheBandBrieflyAndComingBackIsACrossing) {
  const FLO model;
  const Params p = FLO::MakeParams(0.1, 2.0, 0.8, 1.0, 0.8);  // x'' = 2 cos s - x - 0.2 v = 1 here
  const double v = 1e-5;
  AdvanceRequest req;
  req.x0 = FLO::MakeState(1.0, -v, 0.0);  // on the wall, moving away
  req.t_max = 5.0;
  const CvodeOptions o = Options(1e-12);
  CvodePropagator cvode(model, o);
  ExactPropagator exact(model);
  const AdvanceResult c = cvode.Advance(req, p);
  const AdvanceResult e = exact.Advance(req, p);
  ASSERT_TRUE(c.status.ok()) << c.status.ToString();
  ASSERT_TRUE(e.status.ok()) << e.status.ToString();
  ASSERT_EQ(e.end, AdvanceEnd::kEvent);
  ASSERT_EQ(c.end, AdvanceEnd::kEvent);
  EXPECT_EQ(c.guard, FLO::kWallGuard);
  EXPECT_NEAR(e.duration, 2.0 * v, 1e-3 * v);  // x'' = 1 to within 1e-5 over the excursion
  // The return crosses the wall at speed v: the error bound on x at that time moves the crossing
  // by at most GlobalBound / v (5e-6 here, a quarter of the return time, and past the peak).
  EXPECT_NEAR(c.duration, e.duration, GlobalBound(o, e.duration, 1.0) / v);
  EXPECT_GT(c.duration, v);
}

}  // namespace
}  // namespace drillbif
