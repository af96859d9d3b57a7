// CvodePropagator::Advance on the forced linear oscillator against its closed form: event times,
// grazes and near misses, starts on the wall, the masking of a departing guard, a sequence of
// impacts, measures and trajectory samples. Where the exact propagator is the reference, it is
// compared event by event. The error model behind the tolerances is in flow/cvode_test_support.h.
#include <gtest/gtest.h>

#include <cmath>
#include <cstddef>

#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "flow/cvode_test_support.h"
#include "problems/forced_linear_oscillator.h"

namespace drillbif {
namespace {

using FLO = testing::ForcedLinearOscillator;
using testing::GlobalBound;
using testing::kStart;
using testing::Options;

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
    const MeasureVector exact = model.MeasureIncrements(FLO::kFree, kStart, 12.0, p, kAllMeasures);
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
  const MeasureVector exact = model.MeasureIncrements(FLO::kFree, x0, r.duration, p, kAllMeasures);
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

}  // namespace
}  // namespace drillbif
