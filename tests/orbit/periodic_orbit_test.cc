// Periodic orbits: the reference orbit of MODEL.md solved as a boundary-value problem, its Floquet
// multipliers, the monodromy matrix against finite differences of the simulated Poincare map, and
// bad input.
#include "drillbif/orbit/periodic_orbit.h"

#include <gtest/gtest.h>

#include <cmath>
#include <complex>

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
      EXPECT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.BriefReport();
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

// A pure-contact orbit ("CwoP|": the bit on the slider all period, no progression): the contact
// constraint c = p - q - g keeps its value along the contact flow (p' = q' = y), so the monodromy
// has the multiplier 1 with left eigenvector grad c = (1, 0, -1), a direction off the surface the
// motion never takes. It is set apart (structural_ones); the others are those of the damped
// oscillator the contact motion is, q'' + 2 xi q' + q = a cos s + b: exp(T (-xi +- i
// sqrt(1 - xi^2))), T = 2 pi / omega (closed form). Before, the 1 came out at 1 +- 1e-15 and
// decided `stable` by rounding. An orbit that leaves contact has no such multiplier.
TEST(PeriodicOrbit, PureContactOrbitSetsTheConstraintsUnitMultiplierApart) {
  DO model;
  ExactPropagator prop(model);
  Params params = testing::ReferenceParams();
  params[DO::kOmega] = 0.42, params[DO::kA] = 0.02;
  const PeriodicOrbit orbit = SolvedOrbit(model, prop, params);
  ASSERT_EQ(SignatureString(model, orbit.signature), "CwoP|");
  const Stability st = OrbitStability(model, prop, orbit);
  EXPECT_EQ(st.structural_ones, 1);
  ASSERT_EQ(st.monodromy.rows(), 3);  // p, y, q (the phase left out)
  const Eigen::RowVector3d grad(1.0, 0.0, -1.0);
  // Entries of M are O(1) here; rounding of the closed-form flow leaves ~1e-15.
  EXPECT_LE((grad * st.monodromy - grad).norm(), 1e-12);
  const double xi = params[DO::kXi], period = 2.0 * M_PI / params[DO::kOmega];
  const std::complex<double> expected =
      std::exp(period * std::complex<double>(-xi, std::sqrt(1.0 - xi * xi)));
  ASSERT_EQ(st.multipliers.size(), 2u);
  for (const std::complex<double>& mu : st.multipliers) {
    EXPECT_NEAR(std::abs(mu - (mu.imag() > 0.0 ? expected : std::conj(expected))), 0.0, 1e-12);
  }
  EXPECT_TRUE(st.stable);
  EXPECT_EQ(OrbitStability(model, prop, SolvedOrbit(model, prop, testing::ReferenceParams()))
                .structural_ones,
            0);
}

// Signatures that differ only in where the section cuts the orbit (an event crossing s = 0):
// the same cyclic sequence of segments.
TEST(Signature, SameUpToSectionComparesTheCycleOfSegments) {
  DO model;
  ExactPropagator prop(model);
  Params params = testing::ReferenceParams();
  params[DO::kOmega] = 1.0, params[DO::kA] = 0.1;
  const Signature nc = SolvedOrbit(model, prop, params).signature;
  ASSERT_EQ(SignatureString(model, nc), "NC>Pi CwoP>l2 NC|");
  Signature rotated = nc;  // CwoP>l2 NC>Pi CwoP|
  rotated.segments = {nc.segments[1], nc.segments[0], {nc.segments[1].mode, -1}};
  EXPECT_TRUE(SameUpToSection(nc, rotated));
  EXPECT_TRUE(SameUpToSection(rotated, nc));
  EXPECT_FALSE(nc == rotated);
  Signature doubled = rotated;
  doubled.periods = 2;
  EXPECT_FALSE(SameUpToSection(nc, doubled));
  const Signature reference = SolvedOrbit(model, prop, testing::ReferenceParams()).signature;
  EXPECT_FALSE(SameUpToSection(nc, reference));
  Signature open = nc;  // last and first modes differ: no cut segment
  open.segments.back().mode = nc.segments[1].mode;
  EXPECT_FALSE(SameUpToSection(open, rotated));
  EXPECT_TRUE(SameUpToSection(open, open));
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
  EXPECT_EQ(SolveOrbit(model, prop, {}, &bad).termination, Termination::kFailed);
  bad = orbit;
  bad.params[DO::kXi] = -1.0;
  const OrbitSolveSummary s = SolveOrbit(model, prop, {}, &bad);
  EXPECT_EQ(s.termination, Termination::kFailed);
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
  ASSERT_EQ(s.termination, Termination::kCompleted) << s.message;
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
