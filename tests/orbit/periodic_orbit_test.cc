// Periodic orbits: the reference orbit of MODEL.md solved as a boundary-value problem, its Floquet
// multipliers, the monodromy matrix against finite differences of the simulated Poincare map, and
// bad input.
#include "drillbif/orbit/periodic_orbit.h"

#include <gtest/gtest.h>

#include <cmath>

#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

PeriodicOrbit SolvedOrbit(const DO& model, Propagator& prop, const Params& params) {
  StatusOr<PeriodicOrbit> orbit = testing::SolvedOrbitFromRest(model, prop, params);
  EXPECT_TRUE(orbit.ok()) << orbit.status().ToString();
  return orbit.ok() ? *orbit : PeriodicOrbit{};
}

TEST(PeriodicOrbit, SolvesThePublishedReferenceOrbit) {
  DO model;
  ExactPropagator prop(model);
  PeriodicOrbit orbit = SolvedOrbit(model, prop, testing::ReferenceParams());
  EXPECT_EQ(SignatureString(model, orbit.signature), "NC>Pi CwoP>l1 CwP>l1 CwoP>l2 NC|");
  const OrbitSolveSummary s = SolveOrbit(model, prop, {}, &orbit);
  // Residual: rounding of the closed-form flows over positions of ~60 (about 100 eps * 60).
  EXPECT_LE(s.residual, 1e-11);
  EXPECT_NEAR(orbit.starts[0][DO::kP], testing::kRefFixedP, testing::kRefFixedPrecision);
  EXPECT_NEAR(orbit.starts[0][DO::kY], testing::kRefFixedY, testing::kRefFixedPrecision);
  EXPECT_NEAR(orbit.starts[0][DO::kQ], testing::kRefFixedQ, testing::kRefFixedPrecision);
  const double phases[4] = {testing::kRefImpactS, testing::kRefProgressionS, testing::kRefStickS,
                            testing::kRefSeparationS};
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(orbit.starts[i + 1][DO::kS], phases[i], testing::kRefPhasePrecision);
  }
  const std::vector<double> m = OrbitMeasures(model, prop, orbit);
  EXPECT_NEAR(m[DO::kDrift], testing::kRefRop, testing::kRefMeasurePrecision);
  EXPECT_NEAR(m[DO::kPower], testing::kRefPc, testing::kRefMeasurePrecision);
  EXPECT_TRUE(CheckAdmissible(model, prop, orbit).admissible);
}

// MODEL.md: multipliers -0.0873672, 0, 0 (7 decimals); the zeros are structural.
TEST(PeriodicOrbit, FloquetMultipliersMatchThePublishedOnes) {
  DO model;
  ExactPropagator prop(model);
  const PeriodicOrbit orbit = SolvedOrbit(model, prop, testing::ReferenceParams());
  const Stability st = OrbitStability(model, prop, orbit);
  ASSERT_EQ(st.multipliers.size(), 1u);
  EXPECT_EQ(st.structural_zeros, 2);
  EXPECT_NEAR(st.multipliers[0].real(), -0.0873672, 1e-7);
  EXPECT_EQ(st.multipliers[0].imag(), 0.0);
  EXPECT_TRUE(st.stable);
}

// The monodromy matrix (flow Jacobians and saltation matrices) is the derivative of the
// stroboscopic map: compare with differences of simulated one-period maps. Central differences
// with step 1e-6 (one-sided forward in q, which must stay >= 0 at q = 0): truncation
// ~1e-6 |P''| for the one-sided column, ~1e-12 |P'''| for the others, rounding ~1e-16 * 60 / 1e-6.
// Tolerance 1e-4 (1 + |M_ij|) relative covers the one-sided column's curvature term.
TEST(PeriodicOrbit, MonodromyMatchesFiniteDifferencesOfThePoincareMap) {
  DO model;
  ExactPropagator prop(model);
  for (double b : {0.15, 0.12}) {
    Params prm = testing::ReferenceParams();
    prm[DO::kB] = b;
    const PeriodicOrbit orbit = SolvedOrbit(model, prop, prm);
    const Stability st = OrbitStability(model, prop, orbit);
    SimulationOptions one;
    one.transient_periods = 0;
    one.sample_periods = 1;
    one.outputs = SimulationOutputs{false, true, false, false, 0.0};
    auto map = [&](const StateVector& x) {
      const SimulationResult r = Simulate(model, prop, prm, x, one);
      EXPECT_EQ(r.termination, Termination::kCompleted) << r.status.ToString();
      return r.poincare.at(0).x;
    };
    const StateVector x0 = orbit.starts[0];
    const double h = 1e-6;
    for (int j = 0; j < 3; ++j) {
      StateVector xp = x0, xm = x0;
      xp[j] += h;
      const bool one_sided = j == DO::kQ;
      if (!one_sided) xm[j] -= h;
      const StateVector fp = map(xp), fm = map(xm);
      for (int i = 0; i < 3; ++i) {
        const double fd = (fp[i] - fm[i]) / (one_sided ? h : 2 * h);
        EXPECT_NEAR(st.monodromy(i, j), fd, 1e-4 * (1 + std::abs(fd)))
            << "b = " << b << " M(" << i << "," << j << ")";
      }
    }
  }
}

TEST(PeriodicOrbit, StartNotNearAPeriodicOrbitIsAClearError) {
  DO model;
  ExactPropagator prop(model);
  Params prm = testing::ReferenceParams();
  prm[DO::kB] = 0.05;  // chaotic (MODEL.md's brute-force picture: chaotic bands as b -> 0)
  GuessOptions opt;
  opt.max_period = 4;
  const StatusOr<PeriodicOrbit> guess =
      OrbitFromSimulation(model, prop, prm, DefaultInitialState(model), opt);
  ASSERT_FALSE(guess.ok());
  EXPECT_EQ(guess.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_NE(guess.status().message().find("no periodic orbit"), std::string::npos);
}

TEST(PeriodicOrbit, InvalidSignatureOrParametersFailTheSolve) {
  DO model;
  ExactPropagator prop(model);
  PeriodicOrbit orbit = SolvedOrbit(model, prop, testing::ReferenceParams());
  PeriodicOrbit bad = orbit;
  bad.signature.segments.back().guard = 0;  // the last segment must end at the section
  EXPECT_EQ(SolveOrbit(model, prop, {}, &bad).status, SolveStatus::kFailed);
  bad = orbit;
  bad.params[DO::kXi] = -1.0;
  const OrbitSolveSummary s = SolveOrbit(model, prop, {}, &bad);
  EXPECT_EQ(s.status, SolveStatus::kFailed);
  EXPECT_NE(s.message.find("xi"), std::string::npos);
}

// A model without closed-form flows would solve its orbits with CVODES sensitivities: the same
// boundary-value problem through the CVODE propagator finds the same orbit. CVODE's global error
// over the orbit's segments is ~100 (rtol |x| + atol) (tests/simulate/propagator_agreement_test),
// at rtol 1e-11 about 1e-7 on |p| ~ 60.
TEST(PeriodicOrbit, SolvesWithCvodesSensitivitiesToo) {
  DO model;
  ExactPropagator exact(model);
  CvodeOptions copt;
  copt.rtol = 1e-11;
  copt.atol = 1e-13;
  CvodePropagator cvode(model, copt);
  const PeriodicOrbit reference = SolvedOrbit(model, exact, testing::ReferenceParams());
  PeriodicOrbit orbit = reference;
  orbit.starts[0][DO::kY] += 1e-3;  // start Newton off the solution
  const OrbitSolveSummary s = SolveOrbit(model, cvode, {}, &orbit);
  ASSERT_EQ(s.status, SolveStatus::kConverged) << s.message;
  for (size_t i = 0; i < orbit.starts.size(); ++i) {
    for (int j = 0; j < 4; ++j) {
      EXPECT_NEAR(orbit.starts[i][j], reference.starts[i][j],
                  1e-7 * (1 + std::abs(reference.starts[i][j])));
    }
    EXPECT_NEAR(orbit.durations[i], reference.durations[i], 1e-7 * (1 + reference.durations[i]));
  }
  const Stability st = OrbitStability(model, cvode, orbit);
  ASSERT_EQ(st.multipliers.size(), 1u);
  EXPECT_NEAR(st.multipliers[0].real(), -0.0873672, 1e-6);
}

}  // namespace
}  // namespace drillbif
