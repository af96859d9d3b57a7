// The forced linear oscillator test problem checks itself before other tests rely on it: the closed
// form solves the equation of motion, the hand-written derivatives match finite differences, the
// augmented linear form reproduces the closed form, and the measure increments match quadrature.
#include "problems/forced_linear_oscillator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <unsupported/Eigen/MatrixFunctions>

namespace drillbif::testing {
namespace {

using FLO = ForcedLinearOscillator;

const StateVector kStart = FLO::MakeState(0.3, -0.2, 0.4);

// Central differences with step 1e-5 on O(1) smooth functions: truncation ~ f''' h^2 / 6 ~ 1e-11,
// rounding ~ eps / h ~ 1e-11; 1e-8 leaves a wide margin.
constexpr double kStep = 1e-5;
constexpr double kFdTol = 1e-8;

TEST(ForcedLinearOscillatorTest, ClosedFormSolvesTheEquationOfMotion) {
  const FLO model;
  const Params p = model.DefaultParams();
  for (double t : {0.0, 0.7, 3.0, 25.0}) {
    const StateVector x = FLO::ExactState(kStart, t, p);
    const StateVector dx_fd =
        (FLO::ExactState(kStart, t + kStep, p) - FLO::ExactState(kStart, t - kStep, p)) /
        (2 * kStep);
    StateVector f;
    model.VectorField(FLO::kFree, x, p, &f);
    EXPECT_LE((dx_fd - f).cwiseAbs().maxCoeff(), kFdTol) << "t " << t;
  }
  EXPECT_LE((FLO::ExactState(kStart, 0.0, p) - kStart).norm(), 1e-15);
}

TEST(ForcedLinearOscillatorTest, VectorFieldJacobiansMatchFiniteDifferences) {
  const FLO model;
  const Params p = model.DefaultParams();
  StateMatrix j;
  ParamMatrix jp;
  model.StateJacobian(FLO::kFree, kStart, p, &j);
  model.ParamJacobian(FLO::kFree, kStart, p, &jp);
  StateVector fp, fm;
  for (int c = 0; c < 3; ++c) {
    StateVector xp = kStart, xm = kStart;
    xp[c] += kStep, xm[c] -= kStep;
    model.VectorField(FLO::kFree, xp, p, &fp);
    model.VectorField(FLO::kFree, xm, p, &fm);
    EXPECT_LE(((fp - fm) / (2 * kStep) - j.col(c)).cwiseAbs().maxCoeff(), kFdTol) << "x" << c;
  }
  for (int k = 0; k < model.num_params(); ++k) {
    Params pp = p, pm = p;
    pp[k] += kStep, pm[k] -= kStep;
    model.VectorField(FLO::kFree, kStart, pp, &fp);
    model.VectorField(FLO::kFree, kStart, pm, &fm);
    EXPECT_LE(((fp - fm) / (2 * kStep) - jp.col(k)).cwiseAbs().maxCoeff(), kFdTol)
        << model.param_names()[k];
  }
}

TEST(ForcedLinearOscillatorTest, FlowJacobianMatchesFiniteDifferences) {
  const FLO model;
  const Params p = model.DefaultParams();
  for (double t : {0.5, 4.0, 30.0}) {
    StateVector x, xp, xm;
    StateMatrix j;
    model.Flow(FLO::kFree, kStart, t, p, &x, &j);
    for (int c = 0; c < 3; ++c) {
      StateVector sp = kStart, sm = kStart;
      sp[c] += kStep, sm[c] -= kStep;
      model.Flow(FLO::kFree, sp, t, p, &xp, nullptr);
      model.Flow(FLO::kFree, sm, t, p, &xm, nullptr);
      EXPECT_LE(((xp - xm) / (2 * kStep) - j.col(c)).cwiseAbs().maxCoeff(), kFdTol)
          << "t " << t << " column " << c;
    }
  }
}

TEST(ForcedLinearOscillatorTest, GuardDerivativesMatchTheFlow) {
  const FLO model;
  const Params p = model.DefaultParams();
  for (double t : {0.3, 2.0, 9.0}) {
    auto h = [&](double tt) {
      return model.Guard(FLO::kFree, 0, FLO::ExactState(kStart, tt, p), p).h;
    };
    const GuardValue g = model.Guard(FLO::kFree, 0, FLO::ExactState(kStart, t, p), p);
    EXPECT_NEAR(g.dh, (h(t + kStep) - h(t - kStep)) / (2 * kStep), kFdTol);
    // Second difference: truncation ~ h'''' h^2 / 12, rounding ~ 4 eps / h^2 with h = 1e-4.
    const double s = 1e-4;
    EXPECT_NEAR(g.ddh, (h(t + s) - 2 * h(t) + h(t - s)) / (s * s), 1e-6);
  }
  const StateRow grad = model.GuardGradient(FLO::kFree, 0, kStart, p);
  for (int c = 0; c < 3; ++c) {
    StateVector xp = kStart, xm = kStart;
    xp[c] += kStep, xm[c] -= kStep;
    EXPECT_NEAR(
        grad[c],
        (model.Guard(FLO::kFree, 0, xp, p).h - model.Guard(FLO::kFree, 0, xm, p).h) / (2 * kStep),
        kFdTol);
  }
  const ParamVector gp = model.GuardParamGradient(FLO::kFree, 0, kStart, p);
  for (int k = 0; k < model.num_params(); ++k) {
    Params pp = p, pm = p;
    pp[k] += kStep, pm[k] -= kStep;
    EXPECT_NEAR(
        gp[k],
        (model.Guard(FLO::kFree, 0, kStart, pp).h - model.Guard(FLO::kFree, 0, kStart, pm).h) /
            (2 * kStep),
        kFdTol);
  }
}

TEST(ForcedLinearOscillatorTest, CurvatureBoundHoldsAlongTheFlow) {
  const FLO model;
  const Params p = model.DefaultParams();
  const StateVector x0 = FLO::MakeState(-3.0, 2.0, 1.0);  // a large transient
  const double bound = model.GuardCurvatureBound(FLO::kFree, 0, x0, p);
  double worst = 0.0;
  for (double t = 0.0; t < 60.0; t += 0.01) {
    worst = std::max(worst, std::abs(model.Guard(FLO::kFree, 0, FLO::ExactState(x0, t, p), p).ddh));
  }
  EXPECT_LE(worst, bound);
  EXPECT_GT(worst, 0.2 * bound);  // and it is not uselessly loose
}

TEST(ForcedLinearOscillatorTest, AugmentedLinearFormReproducesTheClosedForm) {
  const FLO model;
  const Params p = model.DefaultParams();
  Eigen::MatrixXd a;
  Eigen::VectorXd z0;
  model.AugmentedMatrix(FLO::kFree, p, &a);
  model.ToAugmented(kStart, p, &z0);
  for (double t : {0.5, 7.0}) {
    const Eigen::VectorXd z = (a * t).exp() * z0;
    const StateVector x = FLO::ExactState(kStart, t, p);
    EXPECT_NEAR(z[0], x[FLO::kX], 1e-12);
    EXPECT_NEAR(z[1], x[FLO::kV], 1e-12);
    EXPECT_NEAR(z[2], std::cos(x[FLO::kS]), 1e-12);
    EXPECT_NEAR(z[3], std::sin(x[FLO::kS]), 1e-12);
  }
  // dA/dk against finite differences of A.
  for (int k = 0; k < model.num_params(); ++k) {
    Params pp = p, pm = p;
    pp[k] += kStep, pm[k] -= kStep;
    Eigen::MatrixXd ap, am, da;
    model.AugmentedMatrix(FLO::kFree, pp, &ap);
    model.AugmentedMatrix(FLO::kFree, pm, &am);
    model.AugmentedMatrixDerivative(FLO::kFree, p, k, &da);
    EXPECT_LE(((ap - am) / (2 * kStep) - da).cwiseAbs().maxCoeff(), kFdTol)
        << model.param_names()[k];
  }
}

TEST(ForcedLinearOscillatorTest, MeasureIncrementsMatchQuadratureOfTheRates) {
  const FLO model;
  const Params p = model.DefaultParams();
  const double t = 5.0;
  // Composite Simpson with 2000 panels: error ~ t h^4 max|f''''| / 180 ~ 1e-13.
  const int n = 2000;
  MeasureVector sum = MeasureVector::Zero(2);
  for (int i = 0; i <= n; ++i) {
    const double w = (i == 0 || i == n) ? 1.0 : (i % 2 ? 4.0 : 2.0);
    sum += w * model.MeasureRates(FLO::kFree, FLO::ExactState(kStart, t * i / n, p), p);
  }
  sum *= t / (3.0 * n);
  const MeasureVector closed = model.MeasureIncrements(FLO::kFree, kStart, t, p, kAllMeasures);
  EXPECT_NEAR(closed[FLO::kDisplacement], sum[FLO::kDisplacement], 1e-10);
  EXPECT_NEAR(closed[FLO::kPositionIntegral], sum[FLO::kPositionIntegral], 1e-10);
}

TEST(ForcedLinearOscillatorTest, PreparedSegmentsAgreeWithFlowAndGuards) {
  const FLO model;
  const Params p = model.DefaultParams();
  PreparedSegment seg;
  model.PrepareSegment(FLO::kFree, kStart, p, &seg);
  for (double t : {0.0, 1.3, 8.0}) {
    SegmentPoint pt;
    model.EvaluateSegment(seg, t, p, true, &pt);
    StateVector x;
    model.Flow(FLO::kFree, kStart, t, p, &x, nullptr);
    EXPECT_EQ(pt.x, x);
    const GuardValue g = model.Guard(FLO::kFree, 0, x, p);
    EXPECT_EQ(pt.guards[0].h, g.h);
    EXPECT_EQ(pt.guards[0].dh, g.dh);
    EXPECT_EQ(pt.guards[0].ddh, g.ddh);
    EXPECT_EQ(pt.bounds[0], model.GuardCurvatureBound(FLO::kFree, 0, x, p));
  }
}

TEST(ForcedLinearOscillatorTest, JumpReversesTheVelocityWithRestitution) {
  const FLO model;
  const Params p = model.DefaultParams();
  const StateVector x = FLO::MakeState(p[FLO::kWall], 1.5, 2.0);
  const Transition tr = model.Jump(FLO::kFree, 0, x, p);
  EXPECT_EQ(tr.next_mode, FLO::kFree);
  EXPECT_DOUBLE_EQ(tr.x[FLO::kV], -p[FLO::kRestitution] * 1.5);
  EXPECT_DOUBLE_EQ(tr.x[FLO::kX], x[FLO::kX]);
  EXPECT_DOUBLE_EQ(tr.jacobian(FLO::kV, FLO::kV), -p[FLO::kRestitution]);
}

TEST(ForcedLinearOscillatorTest, RejectsParametersOutsideItsDomain) {
  const FLO model;
  EXPECT_TRUE(model.ValidateParams(model.DefaultParams()).ok());
  const Status zeta = model.ValidateParams(FLO::MakeParams(1.0));
  EXPECT_EQ(zeta.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(zeta.message().find("zeta"), std::string::npos) << zeta.message();
  EXPECT_FALSE(model.ValidateParams(FLO::MakeParams(0.1, 1.0, 0.0)).ok());
  EXPECT_FALSE(model.ValidateParams(FLO::MakeParams(0.0, 1.0, 1.0)).ok());  // resonance
  EXPECT_FALSE(model.ValidateParams(FLO::MakeParams(0.1, NAN)).ok());
  EXPECT_FALSE(model.ValidateParams(FLO::MakeParams(0.1, 1.0, 0.8, 2.0, 1.5)).ok());
}

}  // namespace
}  // namespace drillbif::testing
