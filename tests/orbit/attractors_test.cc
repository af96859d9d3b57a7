// SampleAttractors (orbit/attractors.h): coexisting periodic attractors found by simulation from
// DriftingOscillator::SpreadStates.
#include "drillbif/orbit/attractors.h"

#include <gtest/gtest.h>

#include <string>

#include "drillbif/continuation/continuation.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/orbit/signature.h"
#include "problems/drifting_reference.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

class Attractors : public ::testing::Test {
 protected:
  DO model_;
  ExactPropagator prop_{model_};
};

// The first special point of `kind` on the branch, or nullptr.
const SpecialPoint* First(const ContinuationResult& branch, SpecialPointKind kind) {
  for (const SpecialPoint& s : branch.special_points) {
    if (s.kind == kind) return &s;
  }
  return nullptr;
}

// At the reference point one attractor, the published orbit (ROP to MODEL.md's 10 decimals),
// reached from every spread state.
TEST_F(Attractors, ReferencePointHasOneAttractor) {
  const Params p = testing::ReferenceParams();
  const StatusOr<AttractorSample> s = SampleAttractors(model_, prop_, p, DO::SpreadStates(p));
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  ASSERT_EQ(s->attractors.size(), 1u);
  EXPECT_TRUE(s->not_periodic.empty());
  const Attractor& a = s->attractors.front();
  EXPECT_EQ(a.reached_from.size(), 8u);
  EXPECT_TRUE(a.stable);
  EXPECT_NEAR(a.rop, testing::kRefRop, testing::kRefMeasurePrecision);
}

// At (omega, a) = (0.9, 0.02) two stable orbits coexist: the pure-contact orbit ("CwoP|", ROP 0)
// and one with a free flight. Independently of the sample, by one-parameter continuation in
// omega from each: the flight orbit's branch folds below 0.9 (at 0.8681) and the pure-contact
// orbit's grazes above it (at 0.9517), so both exist over (0.8681, 0.9517), a bistable interval.
TEST_F(Attractors, FindsTheTwoCoexistingOrbitsOfABistableInterval) {
  Params p = testing::ReferenceParams();
  p[DO::kOmega] = 0.9;
  p[DO::kA] = 0.02;
  const StatusOr<AttractorSample> s = SampleAttractors(model_, prop_, p, DO::SpreadStates(p));
  ASSERT_TRUE(s.ok()) << s.status().ToString();
  ASSERT_EQ(s->attractors.size(), 2u);
  size_t reached = s->not_periodic.size();
  const Attractor* contact = nullptr;
  const Attractor* flight = nullptr;
  for (const Attractor& a : s->attractors) {
    reached += a.reached_from.size();
    EXPECT_TRUE(a.stable);
    const std::string sig = SignatureString(model_, a.orbit.signature);
    (sig == "CwoP|" ? contact : flight) = &a;
  }
  EXPECT_EQ(reached, 8u);
  ASSERT_NE(contact, nullptr);
  ASSERT_NE(flight, nullptr);
  EXPECT_EQ(contact->rop, 0.0);
  bool has_flight = false;
  for (const SegmentSpec& seg : flight->orbit.signature.segments) {
    has_flight = has_flight || seg.mode == DO::kNoContact;
  }
  EXPECT_TRUE(has_flight) << SignatureString(model_, flight->orbit.signature);

  ContinuationOptions down;
  down.param = "omega";
  down.min = 0.8, down.max = 0.9;
  const ContinuationResult flight_branch = Continue(model_, prop_, flight->orbit, down);
  const SpecialPoint* fold = First(flight_branch, SpecialPointKind::kFold);
  ASSERT_NE(fold, nullptr) << flight_branch.summary.message;
  EXPECT_NEAR(fold->point.value, 0.8681, 1e-4);
  ContinuationOptions up;
  up.param = "omega";
  up.min = 0.9, up.max = 1.0;
  const ContinuationResult contact_branch = Continue(model_, prop_, contact->orbit, up);
  ASSERT_FALSE(contact_branch.special_points.empty()) << contact_branch.summary.message;
  const SpecialPoint& graze = contact_branch.special_points.front();
  EXPECT_NEAR(graze.point.value, 0.9517, 1e-4) << SpecialPointKindName(graze.kind);
}

TEST_F(Attractors, InvalidInputIsNamed) {
  Params p = testing::ReferenceParams();
  std::vector<StateVector> states = DO::SpreadStates(p);
  states[3][DO::kQ] = 2.0;
  const StatusOr<AttractorSample> bad_state = SampleAttractors(model_, prop_, p, states);
  ASSERT_FALSE(bad_state.ok());
  EXPECT_EQ(bad_state.status().code(), StatusCode::kInvalidArgument);
  EXPECT_NE(bad_state.status().message().find("initial state 3"), std::string::npos)
      << bad_state.status().message();
  p[DO::kOmega] = -1.0;
  const StatusOr<AttractorSample> bad_params =
      SampleAttractors(model_, prop_, p, DO::SpreadStates(p));
  ASSERT_FALSE(bad_params.ok());
  EXPECT_NE(bad_params.status().message().find("omega"), std::string::npos)
      << bad_params.status().message();
}

}  // namespace
}  // namespace drillbif
