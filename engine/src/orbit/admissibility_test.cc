// Admissibility of periodic orbits: CheckAdmissible reports the first violation of the full list
// and checks no segment after it.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "drillbif/flow/exact_propagator.h"
#include "drillbif/orbit/periodic_orbit.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

// Passes everything to another propagator and counts the advances (one per segment checked).
class AdvanceCounter final : public Propagator {
 public:
  explicit AdvanceCounter(Propagator& inner) : inner_(inner) {}
  std::string_view name() const override { return "advance-counter"; }
  FlowResult FlowMap(int mode, const StateVector& x0, double t, const Params& params,
                     const FlowRequest& request) override {
    return inner_.FlowMap(mode, x0, t, params, request);
  }
  AdvanceResult Advance(const AdvanceRequest& request, const Params& params) override {
    ++advances;
    return inner_.Advance(request, params);
  }
  int advances = 0;

 private:
  Propagator& inner_;
};

// The reference orbit with its first segment 1% too long: its guard fires inside it, a violation
// in segment 0. The full list checks every segment; CheckAdmissible gives the list's first entry
// and stops there.
TEST(Admissibility, CheckAdmissibleStopsAtTheFirstViolation) {
  DriftingOscillator model;
  ExactPropagator exact(model);
  const StatusOr<PeriodicOrbit> solved =
      testing::SolvedOrbitFromRest(model, exact, testing::ReferenceParams());
  ASSERT_TRUE(solved.ok()) << solved.status().ToString();
  ASSERT_GE(solved->durations.size(), 3u);
  PeriodicOrbit o = *solved;
  o.durations[0] *= 1.01;

  AdvanceCounter all(exact);
  const std::vector<Admissibility> list = AdmissibilityViolations(model, all, o);
  ASSERT_FALSE(list.empty());
  EXPECT_EQ(list.front().segment, 0);
  EXPECT_EQ(all.advances, static_cast<int>(o.durations.size()));

  AdvanceCounter first(exact);
  const Admissibility a = CheckAdmissible(model, first, o);
  EXPECT_EQ(first.advances, 1);
  EXPECT_FALSE(a.admissible);
  EXPECT_EQ(a.segment, list.front().segment);
  EXPECT_EQ(a.guard, list.front().guard);
  EXPECT_EQ(a.at_start, list.front().at_start);
  EXPECT_EQ(a.message, list.front().message);
}

// An admissible orbit is checked in full by both.
TEST(Admissibility, AdmissibleOrbitIsCheckedInFull) {
  DriftingOscillator model;
  ExactPropagator exact(model);
  const StatusOr<PeriodicOrbit> solved =
      testing::SolvedOrbitFromRest(model, exact, testing::ReferenceParams());
  ASSERT_TRUE(solved.ok()) << solved.status().ToString();
  AdvanceCounter counter(exact);
  EXPECT_TRUE(CheckAdmissible(model, counter, *solved).admissible);
  EXPECT_EQ(counter.advances, static_cast<int>(solved->durations.size()));
}

}  // namespace
}  // namespace drillbif
