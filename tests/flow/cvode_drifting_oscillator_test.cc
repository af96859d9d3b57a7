// CvodePropagator::Advance on the drifting oscillator against the exact propagator: the first
// impact from rest, and free flights that start on the impact surface at rounding level, as after a
// separation.
#include <gtest/gtest.h>

#include <cmath>
#include <ostream>
#include <string>

#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/model/drifting_oscillator.h"

namespace drillbif {
namespace {

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

}  // namespace
}  // namespace drillbif
