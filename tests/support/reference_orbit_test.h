// A test fixture holding the drifting oscillator, the exact propagator and the reference orbit
// (MODEL.md's parameters) solved from rest: the start of the continuation and curve tests. A
// fixture that adds to it calls ReferenceOrbitTest::SetUp() first.
#ifndef DRILLBIF_TESTS_SUPPORT_REFERENCE_ORBIT_TEST_H_
#define DRILLBIF_TESTS_SUPPORT_REFERENCE_ORBIT_TEST_H_

#include <gtest/gtest.h>

#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif::testing {

class ReferenceOrbitTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const StatusOr<PeriodicOrbit> start = SolvedOrbitFromRest(model_, prop_, ReferenceParams());
    ASSERT_TRUE(start.ok()) << start.status().ToString();
    start_ = *start;
  }

  DriftingOscillator model_;
  ExactPropagator prop_{model_};
  PeriodicOrbit start_;
};

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_REFERENCE_ORBIT_TEST_H_
