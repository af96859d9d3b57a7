// The drifting oscillator's hand-written derivatives against finite differences, its guards and
// curvature bounds, and its input validation.
#include "drillbif/model/drifting_oscillator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "problems/parameter_sets.h"
#include "support/same_bits.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

// Central differences with step h: truncation error h^2 |f'''| / 6 and rounding error
// eps |f| / h. With h = 1e-5 and O(1) derivatives of these linear-trigonometric functions both are
// below 1e-10; the tolerance 1e-8 (1 + |value|) leaves two orders of margin and still fails on any
// wrong term (a wrong entry is off by O(1)).
constexpr double kFdStep = 1e-5;
double FdTol(double v) { return 1e-8 * (1.0 + std::abs(v)); }

// Admissible random states of a mode (contact modes have p = q + g).
StateVector RandomState(int mode, const Params& prm, std::mt19937& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  StateVector x(4);
  x[DO::kQ] = u(rng);
  x[DO::kY] = 2.0 * u(rng) - 1.0;
  x[DO::kS] = kTwoPi * u(rng);
  x[DO::kP] =
      mode == DO::kNoContact ? x[DO::kQ] + prm[DO::kG] - 2.0 * u(rng) : x[DO::kQ] + prm[DO::kG];
  return x;
}

class ParameterSetTest : public ::testing::TestWithParam<testing::NamedParams> {};

TEST_P(ParameterSetTest, StateJacobianMatchesFiniteDifferences) {
  DO model;
  const Params& prm = GetParam().params;
  std::mt19937 rng(1);
  for (int mode = 0; mode < 3; ++mode) {
    for (int trial = 0; trial < 5; ++trial) {
      const StateVector x = RandomState(mode, prm, rng);
      StateMatrix jac;
      model.StateJacobian(mode, x, prm, &jac);
      for (int j = 0; j < 4; ++j) {
        StateVector xp = x, xm = x, fp, fm;
        xp[j] += kFdStep, xm[j] -= kFdStep;
        model.VectorField(mode, xp, prm, &fp);
        model.VectorField(mode, xm, prm, &fm);
        for (int i = 0; i < 4; ++i) {
          const double fd = (fp[i] - fm[i]) / (2 * kFdStep);
          EXPECT_NEAR(jac(i, j), fd, FdTol(fd)) << "mode " << mode << " d f" << i << "/dx" << j;
        }
      }
    }
  }
}

TEST_P(ParameterSetTest, ParamJacobianMatchesFiniteDifferences) {
  DO model;
  const Params& prm = GetParam().params;
  std::mt19937 rng(2);
  for (int mode = 0; mode < 3; ++mode) {
    const StateVector x = RandomState(mode, prm, rng);
    ParamMatrix jac;
    model.ParamJacobian(mode, x, prm, &jac);
    for (int k = 0; k < 6; ++k) {
      // Relative step: d/dxi of 1/(2 xi) has truncation error ~ (h/xi)^2, so h must scale with xi.
      const double h = kFdStep * (prm[k] != 0.0 ? std::abs(prm[k]) : 1.0);
      Params pp = prm, pm = prm;
      pp[k] += h, pm[k] -= h;
      StateVector fp, fm;
      model.VectorField(mode, x, pp, &fp);
      model.VectorField(mode, x, pm, &fm);
      for (int i = 0; i < 4; ++i) {
        const double fd = (fp[i] - fm[i]) / (2 * h);
        EXPECT_NEAR(jac(i, k), fd, FdTol(fd)) << "mode " << mode << " d f" << i << "/dp" << k;
      }
    }
  }
}

TEST_P(ParameterSetTest, GuardGradientsMatchFiniteDifferences) {
  DO model;
  const Params& prm = GetParam().params;
  std::mt19937 rng(3);
  for (int mode = 0; mode < 3; ++mode) {
    for (int guard = 0; guard < static_cast<int>(model.guards(mode).size()); ++guard) {
      const StateVector x = RandomState(mode, prm, rng);
      const StateRow grad = model.GuardGradient(mode, guard, x, prm);
      for (int j = 0; j < 4; ++j) {
        StateVector xp = x, xm = x;
        xp[j] += kFdStep, xm[j] -= kFdStep;
        const double fd =
            (model.Guard(mode, guard, xp, prm).h - model.Guard(mode, guard, xm, prm).h) /
            (2 * kFdStep);
        EXPECT_NEAR(grad[j], fd, FdTol(fd)) << "mode " << mode << " guard " << guard;
      }
      const ParamVector pgrad = model.GuardParamGradient(mode, guard, x, prm);
      for (int k = 0; k < 6; ++k) {
        const double h = kFdStep * (prm[k] != 0.0 ? std::abs(prm[k]) : 1.0);
        Params pp = prm, pm = prm;
        pp[k] += h, pm[k] -= h;
        const double fd =
            (model.Guard(mode, guard, x, pp).h - model.Guard(mode, guard, x, pm).h) / (2 * h);
        EXPECT_NEAR(pgrad[k], fd, FdTol(fd)) << "mode " << mode << " guard " << guard;
      }
    }
  }
}

// dh/dt and d2h/dt2 along the flow against differences of h along the closed-form flow. The
// second difference has rounding error eps |h| / dt^2: with dt = 1e-4 that is 1e-8, so the
// tolerance for ddh is 1e-6 (1 + |ddh|) (times a stiffness factor for fast modes, xi = 0.005).
TEST_P(ParameterSetTest, GuardTimeDerivativesMatchTheFlow) {
  DO model;
  const Params& prm = GetParam().params;
  const double rate = std::max({1.0, 1.0 / (2.0 * prm[DO::kXi]), prm[DO::kOmega]});
  const double dt = 1e-4 / rate;
  std::mt19937 rng(4);
  for (int mode = 0; mode < 3; ++mode) {
    for (int guard = 0; guard < static_cast<int>(model.guards(mode).size()); ++guard) {
      const StateVector x = RandomState(mode, prm, rng);
      StateVector xp, xm;
      model.Flow(mode, x, dt, prm, &xp, nullptr);
      model.Flow(mode, x, -dt, prm, &xm, nullptr);
      const GuardValue g = model.Guard(mode, guard, x, prm);
      const double hp = model.Guard(mode, guard, xp, prm).h;
      const double hm = model.Guard(mode, guard, xm, prm).h;
      const double d1 = (hp - hm) / (2 * dt), d2 = (hp - 2 * g.h + hm) / (dt * dt);
      EXPECT_NEAR(g.dh, d1, 1e-7 * rate * (1 + std::abs(d1))) << "mode " << mode;
      EXPECT_NEAR(g.ddh, d2, 1e-6 * rate * rate * (1 + std::abs(d2))) << "mode " << mode;
    }
  }
}

// The curvature bound must hold along the whole future flow in the mode: sample d2h/dt2 densely
// over several forcing periods and decay times from random states.
TEST_P(ParameterSetTest, GuardCurvatureBoundHoldsAlongTheFlow) {
  DO model;
  const Params& prm = GetParam().params;
  const double horizon = std::min(3 * kTwoPi / prm[DO::kOmega], 200.0);
  std::mt19937 rng(5);
  for (int mode = 0; mode < 3; ++mode) {
    for (int guard = 0; guard < static_cast<int>(model.guards(mode).size()); ++guard) {
      for (int trial = 0; trial < 4; ++trial) {
        const StateVector x0 = RandomState(mode, prm, rng);
        const double bound = model.GuardCurvatureBound(mode, guard, x0, prm);
        ASSERT_TRUE(std::isfinite(bound) && bound > 0.0);
        StateVector x;
        for (int k = 0; k <= 4000; ++k) {
          model.Flow(mode, x0, horizon * k / 4000.0, prm, &x, nullptr);
          const double ddh = model.Guard(mode, guard, x, prm).ddh;
          ASSERT_LE(std::abs(ddh), bound)
              << "mode " << mode << " guard " << guard << " t " << horizon * k / 4000.0;
        }
      }
    }
  }
}

// Free flight's bound on |d3h/dt3| (PreparedSegment's jerk_bounds) must hold along the whole future
// flight, as the curvature bound: d3h/dt3 by central differences of d2h/dt2 along the closed-form
// flow, dt = 1e-4 / rate. Their truncation error, dt^2 / 6 |h^(5)| with |h^(5)| <= rate^2 times
// the bound, is below 2e-9 of the bound; their rounding, eps |h''| / dt, below 1e-11 rate times
// the curvature bound. The margin, 1e-8 of the bound plus 1e-10 rate times the curvature bound,
// covers both.
TEST_P(ParameterSetTest, FreeFlightJerkBoundHoldsAlongTheFlow) {
  DO model;
  const Params& prm = GetParam().params;
  const double rate = std::max({1.0, 1.0 / (2.0 * prm[DO::kXi]), prm[DO::kOmega]});
  const double dt = 1e-4 / rate;
  const double horizon = std::min(3 * kTwoPi / prm[DO::kOmega], 200.0);
  std::mt19937 rng(9);
  double largest = 0.0;  // the largest |d3h/dt3| over its bound seen
  for (int trial = 0; trial < 8; ++trial) {
    const StateVector x0 = RandomState(DO::kNoContact, prm, rng);
    PreparedSegment seg;
    model.PrepareSegment(DO::kNoContact, x0, prm, &seg);
    SegmentPoint start, at, before, after;
    model.EvaluateSegment(seg, 0.0, prm, true, &start);
    const double bound = start.jerk_bounds[DO::kImpact];
    ASSERT_TRUE(std::isfinite(bound) && bound > 0.0);
    for (int k = 0; k <= 2000; ++k) {
      const double t = dt + horizon * k / 2000.0;
      model.EvaluateSegment(seg, t - dt, prm, true, &before);
      model.EvaluateSegment(seg, t, prm, true, &at);
      model.EvaluateSegment(seg, t + dt, prm, true, &after);
      const double d3 = (after.guards[DO::kImpact].ddh - before.guards[DO::kImpact].ddh) / (2 * dt);
      ASSERT_LE(std::abs(d3), bound * (1 + 1e-8) + 1e-10 * rate * start.bounds[DO::kImpact])
          << "t " << t;
      // A bound from a later state holds from there on: it can only be smaller.
      ASSERT_LE(at.jerk_bounds[DO::kImpact], bound);
      largest = std::max(largest, std::abs(d3) / bound);
    }
  }
  // Tight where the flight starts with q of order 1: there -q/(8 xi^3) dominates h''' (a bound
  // twice too large fails this).
  EXPECT_GT(largest, 0.9);
}

// The impact jump places the state on Pi (p = q + g); its Jacobian against finite differences of
// the jump map, at states on and off the surface (differences are exact here: the map is affine).
TEST_P(ParameterSetTest, JumpJacobianMatchesFiniteDifferences) {
  DO model;
  const Params& prm = GetParam().params;
  std::mt19937 rng(6);
  for (int mode = 0; mode < 3; ++mode) {
    for (int guard = 0; guard < static_cast<int>(model.guards(mode).size()); ++guard) {
      const StateVector x = RandomState(DO::kContact, prm, rng);
      const Transition t = model.Jump(mode, guard, x, prm);
      for (int j = 0; j < 4; ++j) {
        StateVector xp = x, xm = x;
        xp[j] += kFdStep, xm[j] -= kFdStep;
        const StateVector fp = model.Jump(mode, guard, xp, prm).x;
        const StateVector fm = model.Jump(mode, guard, xm, prm).x;
        for (int i = 0; i < 4; ++i) {
          EXPECT_NEAR(t.jacobian(i, j), (fp[i] - fm[i]) / (2 * kFdStep), 1e-9)
              << "mode " << mode << " guard " << guard << " d x" << i << "/d x" << j;
        }
      }
    }
  }
}

// The shooting system takes a segment's flow and its parameter columns from one call that shares
// the segment's preparation; the continuation's results must not depend on that, so the values
// are compared bit for bit (no tolerance) with the separate calls, in every mode, for every
// parameter (also the one left to the matrix exponential, where both answer false), with and
// without the state Jacobian.
TEST_P(ParameterSetTest, FlowAndParamDerivativesEqualTheSeparateCallsBitForBit) {
  DO model;
  const Params& prm = GetParam().params;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  const int ks[] = {DO::kA, DO::kB, DO::kOmega, DO::kXi, DO::kG, DO::kPhi0};
  constexpr int kCount = 6;
  for (int mode = 0; mode < 3; ++mode) {
    for (int trial = 0; trial < 4; ++trial) {
      const StateVector x0 = RandomState(mode, prm, rng);
      const double t = 3.0 * u(rng);
      StateVector x_ref;
      StateMatrix jac_ref;
      model.Flow(mode, x0, t, prm, &x_ref, &jac_ref);
      for (const bool with_jac : {true, false}) {
        StateVector x, dx[kCount];
        StateMatrix jac;
        bool ok[kCount];
        model.FlowAndParamDerivatives(mode, x0, t, prm, &x, with_jac ? &jac : nullptr, ks, dx, ok);
        EXPECT_TRUE(testing::SameBits(x, x_ref)) << "mode " << mode;
        if (with_jac) {
          EXPECT_TRUE(jac.rows() == jac_ref.rows() && jac.cols() == jac_ref.cols() &&
                      std::memcmp(jac.data(), jac_ref.data(), sizeof(double) * jac.size()) == 0)
              << "mode " << mode;
        }
        for (int i = 0; i < kCount; ++i) {
          StateVector dx_ref;
          const bool ok_ref = model.FlowParamDerivative(mode, x0, t, prm, ks[i], &dx_ref);
          EXPECT_EQ(ok[i], ok_ref) << "mode " << mode << " param " << ks[i];
          EXPECT_TRUE(testing::SameBits(dx[i], dx_ref)) << "mode " << mode << " param " << ks[i];
        }
      }
    }
  }
}

// The model's saltation shares the two fields' cosine and skips the jump's parameter Jacobian;
// the monodromy factors must not depend on that, so it is compared bit for bit (no tolerance)
// with the generic formula of HybridModel, for every guard of every mode, every mode the flow may
// go on in (a grazing impact stays in free flight), at random states on and off the impact
// surface (off it the impact jump moves p, so DR f- and f+ are not f-'s own entries).
TEST_P(ParameterSetTest, SaltationEqualsTheGenericFormulaBitForBit) {
  DO model;
  const Params& prm = GetParam().params;
  std::mt19937 rng(8);
  int compared = 0;
  for (int mode = 0; mode < 3; ++mode) {
    for (int guard = 0; guard < static_cast<int>(model.guards(mode).size()); ++guard) {
      for (int next = 0; next < 3; ++next) {
        for (int trial = 0; trial < 50; ++trial) {
          const StateVector x = RandomState(trial % 2 ? DO::kContact : DO::kNoContact, prm, rng);
          const StateMatrix fast = model.Saltation(mode, guard, next, x, prm);
          const StateMatrix generic = model.HybridModel::Saltation(mode, guard, next, x, prm);
          ASSERT_EQ(fast.rows(), 4);
          ASSERT_EQ(fast.cols(), 4);
          EXPECT_EQ(std::memcmp(fast.data(), generic.data(), sizeof(double) * 16), 0)
              << "mode " << mode << " guard " << guard << " next " << next << "\n"
              << fast << "\n"
              << generic;
          ++compared;
        }
      }
    }
  }
  EXPECT_EQ(compared, 4 * 3 * 50);
}

INSTANTIATE_TEST_SUITE_P(DriftingOscillator, ParameterSetTest,
                         ::testing::ValuesIn(testing::HardParameterSets()),
                         [](const auto& test_info) { return test_info.param.name; });

TEST(DriftingOscillatorValidation, NamesEachInvalidParameter) {
  DO model;
  struct Case {
    int index;
    double value;
    const char* name;
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  for (const Case& c :
       {Case{DO::kXi, 0.0, "xi"}, Case{DO::kXi, -0.1, "xi"}, Case{DO::kOmega, 0.0, "omega"},
        Case{DO::kOmega, -1.0, "omega"}, Case{DO::kA, -0.01, "a"}, Case{DO::kB, -0.01, "b"},
        Case{DO::kG, 0.0, "g"}, Case{DO::kG, -1.0, "g"}, Case{DO::kA, nan, "a"},
        Case{DO::kB, inf, "b"}, Case{DO::kPhi0, nan, "phi0"}, Case{DO::kOmega, -inf, "omega"}}) {
    Params p = model.DefaultParams();
    p[c.index] = c.value;
    const Status s = model.ValidateParams(p);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << c.name << " = " << c.value;
    EXPECT_NE(s.message().find(std::string("parameter ") + c.name + " "), std::string::npos)
        << s.message();
  }
  EXPECT_TRUE(model.ValidateParams(model.DefaultParams()).ok());
  Params edge = model.DefaultParams();
  edge[DO::kA] = 0.0, edge[DO::kB] = 0.0;  // a = 0 and b = 0 are in the domain
  EXPECT_TRUE(model.ValidateParams(edge).ok());
}

TEST(DriftingOscillatorValidation, RejectsStatesOutsideTheInvariantSet) {
  DO model;
  const Params prm = model.DefaultParams();
  StateVector x = StateVector::Zero(4);
  EXPECT_TRUE(model.ValidateState(x, prm, 1e-12).ok());
  struct Case {
    int index;
    double value;
    const char* needle;
  };
  for (const Case& c :
       {Case{DO::kQ, -0.1, "q"}, Case{DO::kQ, 1.5, "q"}, Case{DO::kP, 0.5, "p <= q + g"},
        Case{DO::kY, std::numeric_limits<double>::quiet_NaN(), "y"},
        Case{DO::kS, std::numeric_limits<double>::infinity(), "s"}}) {
    StateVector bad = x;
    bad[c.index] = c.value;
    const Status s = model.ValidateState(bad, prm, 1e-12);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
    EXPECT_NE(s.message().find(c.needle), std::string::npos) << s.message();
  }
}

TEST(DriftingOscillatorModes, ModeAtFollowsTheContactForce) {
  DO model;
  const Params prm = model.DefaultParams();
  StateVector x(4);
  x << -1.0, 0.0, 0.0, 0.0;
  EXPECT_EQ(model.ModeAt(x, prm), DO::kNoContact);
  x << 0.5 + 0.02, 0.0, 0.5, 0.0;  // in contact, F = 0.5
  EXPECT_EQ(model.ModeAt(x, prm), DO::kContact);
  x << 0.5 + 0.02, 6.0, 0.5, 0.0;  // F = 0.6 + 0.5 > 1
  EXPECT_EQ(model.ModeAt(x, prm), DO::kProgression);
  x << 0.5 + 0.02, -6.0, 0.5, 0.0;  // F < 0: the bit leaves
  EXPECT_EQ(model.ModeAt(x, prm), DO::kNoContact);
}

}  // namespace
}  // namespace drillbif
