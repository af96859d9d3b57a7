#include "continuation/grazing_end.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <vector>

#include "continuation/bordered_sigma.h"
#include "continuation/tangent_grazing.h"

namespace drillbif::internal {

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
  BorderedSigma sigma;
  if (kind != CurveKind::kGrazing) {
    sigma =
        BorderedSigma(ShiftedMonodromy(kind, OrbitStability(model, propagator, guess).monodromy));
  }
  return SolveWithConditions(
      model, propagator, guess, {index1, index2},
      [&](const PeriodicOrbit& o) {
        const std::vector<double> rates = TangentEndRates(model, propagator, o);
        if (kind == CurveKind::kGrazing) return Eigen::Vector2d(rates[0], rates[1]).eval();
        const double s =
            sigma(ShiftedMonodromy(kind, OrbitStability(model, propagator, o).monodromy));
        return Eigen::Vector2d(rates[0], s).eval();
      },
      tolerance, "codimension-2 system");
}

StatusOr<PeriodicOrbit> SolveZeroLengthEnd(const HybridModel& model, Propagator& propagator,
                                           const PeriodicOrbit& guess, int segment, CurveKind kind,
                                           int index1, int index2, double tolerance) {
  if (segment < 0 || segment >= static_cast<int>(guess.durations.size())) {
    return InvalidArgument("no segment " + std::to_string(segment));
  }
  const bool grazing = kind == CurveKind::kGrazing;
  if (grazing && TangentEndRates(model, propagator, guess).size() != 1) {
    return InvalidArgument("the end of a GRAZING curve needs its one tangent end");
  }
  BorderedSigma sigma;
  if (!grazing) {
    sigma =
        BorderedSigma(ShiftedMonodromy(kind, OrbitStability(model, propagator, guess).monodromy));
  }
  return SolveWithConditions(
      model, propagator, guess, {index1, index2},
      [&](const PeriodicOrbit& o) {
        const double own =
            grazing ? TangentEndRate(model, propagator, o)
                    : sigma(ShiftedMonodromy(kind, OrbitStability(model, propagator, o).monodromy));
        return Eigen::Vector2d(o.durations[segment], own).eval();
      },
      tolerance, "zero-length segment system");
}

}  // namespace drillbif::internal
