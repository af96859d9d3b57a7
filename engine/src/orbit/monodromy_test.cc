// The monodromy factor from a given flow (FactorFromFlow): for a model with a LinearForm, moving
// a segment's start in its non-phase part by dx moves the end by Phi dx and leaves Phi as it is,
// so the factor at the moved start is FactorFromFlow at the moved end with the same Phi. The
// curve tracer's sigma row relies on it (continuation/curve.cc).
#include "monodromy.h"

#include <gtest/gtest.h>

#include <algorithm>

#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

// At every segment of the reference orbit (impact, contact, progression, flight: each mode and
// guard) and for each non-phase state component, a start moved by 1e-2 (far beyond any
// difference step, so that a flow Jacobian depending on the start would show at O(1e-2)): the
// factor recomputed from the moved start and FactorFromFlow at the moved end agree to rounding,
// 1e-11 (1 + |F|) (both are sums of O(|F|) terms computed to ~1e-15 relative, the moved end
// from Phi dx as well). Unmoved, FactorFromFlow is SegmentFactor.
TEST(Monodromy, FactorFromAnAffineFlowIsTheFactorAtTheMovedStart) {
  DO model;
  ExactPropagator prop(model);
  const StatusOr<PeriodicOrbit> orbit =
      testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  ASSERT_TRUE(orbit.ok()) << orbit.status().ToString();
  ASSERT_NE(dynamic_cast<const LinearForm*>(&model), nullptr);
  const int n = model.state_dim();
  double largest_change = 0.0;
  for (int i = 0; i < static_cast<int>(orbit->durations.size()); ++i) {
    FlowRequest req;
    req.state_jacobian = true;
    const FlowResult fr = prop.FlowMap(orbit->signature.segments[i].mode, orbit->starts[i],
                                       orbit->durations[i], orbit->params, req);
    const StateMatrix base = internal::SegmentFactor(model, prop, *orbit, i);
    EXPECT_LE((internal::FactorFromFlow(model, *orbit, i, fr.x, fr.state_jacobian) - base)
                  .lpNorm<Eigen::Infinity>(),
              1e-14 * (1.0 + base.lpNorm<Eigen::Infinity>()))
        << "segment " << i;
    for (int j = 0; j < n; ++j) {
      if (j == model.phase_index()) continue;
      PeriodicOrbit moved = *orbit;
      moved.starts[i][j] += 1e-2;
      const StateMatrix full = internal::SegmentFactor(model, prop, moved, i);
      const StateVector x_end = fr.x + 1e-2 * fr.state_jacobian.col(j);
      const StateMatrix shortcut =
          internal::FactorFromFlow(model, *orbit, i, x_end, fr.state_jacobian);
      EXPECT_LE((full - shortcut).lpNorm<Eigen::Infinity>(),
                1e-11 * (1.0 + full.lpNorm<Eigen::Infinity>()))
          << "segment " << i << ", component " << j;
      largest_change = std::max(largest_change, (full - base).lpNorm<Eigen::Infinity>());
    }
  }
  // Not vacuous: the moves do change factors (the saltation depends on the end state), by far
  // more than the agreement asserted above.
  EXPECT_GT(largest_change, 1e-6);
}

}  // namespace
}  // namespace drillbif
