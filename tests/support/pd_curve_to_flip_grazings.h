// The period-1 PD curve from the omega-branch's period doubling at omega = 1.6258 (a = 0.3) over
// the reference (omega, a) box, which ends at the flip-grazings (1.3946, 6.7289) and (0.4734,
// 0.1616): where the tests of the period-2 grazing curves leaving flip-grazings start.
#ifndef DRILLBIF_TESTS_SUPPORT_PD_CURVE_TO_FLIP_GRAZINGS_H_
#define DRILLBIF_TESTS_SUPPORT_PD_CURVE_TO_FLIP_GRAZINGS_H_

#include <gtest/gtest.h>

#include <string>

#include "drillbif/continuation/trace.h"
#include "drillbif/model/drifting_oscillator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"
#include "support/special_point_near.h"

namespace drillbif::testing {

// That curve, traced with the box's and curve options of `box`, as a traced curve started from
// the omega-branch (its outline left to the caller: internal::OutlineOf); a failure when the
// reference orbit or the doubling is not found.
inline ::testing::AssertionResult PdCurveToFlipGrazings(const DriftingOscillator& model,
                                                        Propagator& prop, const TraceOptions& box,
                                                        TracedCurve* out) {
  const StatusOr<PeriodicOrbit> start = SolvedOrbitFromRest(model, prop, ReferenceParams());
  if (!start.ok()) return ::testing::AssertionFailure() << start.status().ToString();
  ContinuationOptions branch;
  branch.param = std::string("omega");
  branch.min = box.min1, branch.max = box.max1;
  const ContinuationResult omega = Continue(model, prop, *start, branch);
  const SpecialPoint* pd = SpecialPointNear(omega, SpecialPointKind::kPeriodDoubling, 1.6258, 1e-3);
  if (pd == nullptr) {
    return ::testing::AssertionFailure() << "no period doubling near omega = 1.6258";
  }
  CurveOptions co = box.curve;
  co.box() = box.box();
  out->start = *pd;
  out->start_param = "omega";
  out->curve = ContinueCurve(model, prop, *pd, co);
  return ::testing::AssertionSuccess();
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_PD_CURVE_TO_FLIP_GRAZINGS_H_
