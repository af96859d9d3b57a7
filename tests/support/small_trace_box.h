// The fixture of the trace tests that compare whole networks: the reference orbit solved from
// rest as the start, and a small box around it (omega in [0.05, 0.2], a in [0.27, 0.32]: ~1 s,
// with a flip-grazing to switch at).
#ifndef DRILLBIF_TESTS_SUPPORT_SMALL_TRACE_BOX_H_
#define DRILLBIF_TESTS_SUPPORT_SMALL_TRACE_BOX_H_

#include <gtest/gtest.h>

#include "drillbif/continuation/trace.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_box.h"
#include "problems/reference_orbit.h"

namespace drillbif::testing {

class SmallTraceBox : public ::testing::Test {
 protected:
  void SetUp() override {
    const StatusOr<PeriodicOrbit> orbit = SolvedOrbitFromRest(model_, prop_, ReferenceParams());
    ASSERT_TRUE(orbit.ok()) << orbit.status().ToString();
    start_ = *orbit;
  }
  static TraceOptions SmallBox() {
    TraceOptions o = ReferenceBox();
    o.max1 = 0.2;
    o.min2 = 0.27, o.max2 = 0.32;
    return o;
  }
  DriftingOscillator model_;
  ExactPropagator prop_{model_};
  PeriodicOrbit start_;
};

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_SMALL_TRACE_BOX_H_
