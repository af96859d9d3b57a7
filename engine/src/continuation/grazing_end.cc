#include "continuation/grazing_end.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <functional>
#include <vector>

#include "continuation/bordered_sigma.h"
#include "continuation/tangent_grazing.h"

namespace drillbif::internal {

namespace {

// The curve's own defining condition as a function of an orbit near `guess`: sigma of the
// shifted monodromy (bordered at `guess`) on a fold / PD / NS curve, h' at the (first) tangent end
// on a grazing curve.
std::function<double(const PeriodicOrbit&)> OwnCondition(const HybridModel& model,
                                                         Propagator& propagator,
                                                         const PeriodicOrbit& guess,
                                                         CurveKind kind) {
  if (kind == CurveKind::kGrazing) {
    return [&model, &propagator](const PeriodicOrbit& o) {
      return TangentEndRate(model, propagator, o);
    };
  }
  const BorderedSigma sigma(
      ShiftedMonodromy(kind, OrbitStability(model, propagator, guess).monodromy));
  return [&model, &propagator, kind, sigma](const PeriodicOrbit& o) {
    return sigma(ShiftedMonodromy(kind, OrbitStability(model, propagator, o).monodromy));
  };
}

}  // namespace

StatusOr<PeriodicOrbit> SolveGrazingEnd(const HybridModel& model, Propagator& propagator,
                                        const PeriodicOrbit& guess, CurveKind kind, int index1,
                                        int index2, double tolerance) {
  const int tangents = static_cast<int>(TangentEndRates(model, propagator, guess).size());
  const int wanted = kind == CurveKind::kGrazing ? 2 : 1;
  if (tangents != wanted) {
    return InvalidArgument("the end of a " + std::string(CurveKindName(kind)) + " curve needs " +
                           std::to_string(wanted) + " tangent ends, the guess has " +
                           std::to_string(tangents));
  }
  // h' at the last tangent end, and the curve's own condition: on a grazing curve h' at the
  // first, so that both touches count, whichever of them is the new one.
  const auto own = OwnCondition(model, propagator, guess, kind);
  return SolveWithConditions(
      model, propagator, guess, {index1, index2},
      [&](const PeriodicOrbit& o) {
        return Eigen::Vector2d(TangentEndRates(model, propagator, o).back(), own(o)).eval();
      },
      tolerance, "codimension-2 system");
}

StatusOr<PeriodicOrbit> SolveZeroLengthEnd(const HybridModel& model, Propagator& propagator,
                                           const PeriodicOrbit& guess, int segment, CurveKind kind,
                                           int index1, int index2, double tolerance) {
  if (segment < 0 || segment >= static_cast<int>(guess.durations.size())) {
    return InvalidArgument("no segment " + std::to_string(segment));
  }
  if (kind == CurveKind::kGrazing && TangentEndRates(model, propagator, guess).size() != 1) {
    return InvalidArgument("the end of a GRAZING curve needs its one tangent end");
  }
  const auto own = OwnCondition(model, propagator, guess, kind);
  return SolveWithConditions(
      model, propagator, guess, {index1, index2},
      [&](const PeriodicOrbit& o) { return Eigen::Vector2d(o.durations[segment], own(o)).eval(); },
      tolerance, "zero-length segment system");
}

}  // namespace drillbif::internal
