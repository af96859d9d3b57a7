// The fold curve with the reference box's best-known cusp: through the a-branch's fold at
// a = 0.156617 (omega = 0.1, orbit CwoP>l2 NC>Pi CwoP), continued in (a, omega) over the reference
// box; it reverses its direction near (omega, a) = (0.10435, 0.15436)
// (tests/continuation/cusp_test.cc checks that it is a cusp).
#ifndef DRILLBIF_TESTS_SUPPORT_CUSP_FOLD_CURVE_H_
#define DRILLBIF_TESTS_SUPPORT_CUSP_FOLD_CURVE_H_

#include <optional>
#include <string>

#include "drillbif/continuation/continuation.h"
#include "drillbif/continuation/curve.h"
#include "problems/drifting_reference.h"
#include "problems/reference_box.h"
#include "problems/reference_orbit.h"
#include "support/special_point_near.h"

namespace drillbif::testing {

// The a-branch's fold at a = 0.156617 from the reference orbit; nullopt when the orbit or the
// fold is not found.
inline std::optional<SpecialPoint> CuspCurveFold(const DriftingOscillator& model,
                                                 Propagator& propagator) {
  const StatusOr<PeriodicOrbit> start = SolvedOrbitFromRest(model, propagator, ReferenceParams());
  if (!start.ok()) return std::nullopt;
  ContinuationOptions opt;
  opt.param = "a";
  opt.min = 0.01, opt.max = 8.0;
  const ContinuationResult branch = Continue(model, propagator, *start, opt);
  const SpecialPoint* fold = SpecialPointNear(branch, SpecialPointKind::kFold, 0.156617, 1e-5);
  if (fold == nullptr) return std::nullopt;
  return *fold;
}

// The fold curve's options: a first, omega second, over the reference box.
inline CurveOptions CuspCurveOptions() {
  const TraceOptions box = ReferenceBox();
  CurveOptions co;
  co.param1 = std::string("a");
  co.param2 = std::string("omega");
  co.min1 = box.min2, co.max1 = box.max2;
  co.min2 = box.min1, co.max2 = box.max1;
  return co;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_CUSP_FOLD_CURVE_H_
