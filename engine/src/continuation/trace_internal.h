// Pieces of TraceCurves (continuation/trace.h) shared by its steps: curve geometry in the box's
// scaled coordinates, and the steps that add curves leaving codimension-2 points.
#ifndef DRILLBIF_CONTINUATION_TRACE_INTERNAL_H_
#define DRILLBIF_CONTINUATION_TRACE_INTERNAL_H_

#include <functional>

#include "drillbif/continuation/trace.h"

namespace drillbif::internal {

// Distance from (u, v) to the polyline of the curve, coordinates scaled by the box's widths.
double DistanceToCurve(const CurveResult& c, double u, double v, double w1, double w2);

// The curve with (value1, value2) swapped, for a curve traced with the parameters in the other
// order.
void SwapValues(CurveResult* c);

// Whether a located special point of this kind starts a grazing curve.
bool IsGrazing(SpecialPointKind kind);

// The period-2 grazing curves that leave the period-1 curves' FLIP_GRAZING points
// (TraceOptions::period2 with switch_at_codim2), appended to result->curves. False when
// cancelled (`report` returned false).
bool Period2AtFlipGrazings(const HybridModel& model, Propagator& propagator,
                           const TraceOptions& options, const std::function<bool(double)>& report,
                           TraceResult* result);

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_TRACE_INTERNAL_H_
