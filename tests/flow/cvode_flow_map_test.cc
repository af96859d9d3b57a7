// CvodePropagator::FlowMap against independent references: the closed-form solution of the
// forced linear oscillator (state, Jacobians) and finite differences of its own flow map; and the
// checks of options and inputs, and failures that become statuses, in FlowMap and Advance alike.
// The error model behind the tolerances is in flow/cvode_test_support.h.
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "drillbif/flow/cvode_propagator.h"
#include "flow/cvode_test_support.h"
#include "problems/forced_linear_oscillator.h"

namespace drillbif {
namespace {

using FLO = testing::ForcedLinearOscillator;
using testing::GlobalBound;
using testing::kStart;
using testing::Options;

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
  int ModeAcross(int m, int g) const override { return base_.ModeAcross(m, g); }
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

}  // namespace
}  // namespace drillbif
