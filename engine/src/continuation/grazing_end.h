// A curve's end where its orbit grazes, solved as the codimension-2 point it is. The bisection of
// the admissibility boundary (curve.cc) brackets such an end, but next to it the curve's own
// system degenerates (the vanishing segment's two events merge and a family of zero-length
// solutions meets the curve there, tangent_grazing.h), Newton fails on the last stretch and the
// bracket can stay wide (1e-5 .. 1e-2 in issue 4's box). In tangent form the same point is the
// regular root of a square system in (X, lambda1, lambda2):
//   fold / PD / NS curve:  G = 0, h' = 0 at the one tangent end, sigma(shifted M) = 0
//   grazing curve:         G = 0, h' = 0 at both tangent ends (a double grazing)
// with M the tangent-form orbit's monodromy (that of the orbit without the vanishing segment; it
// is the limit of the curve's own where the segment's events leave the flow continuous, as at
// l1; elsewhere the root lies away from the end and the caller rejects it).
#ifndef DRILLBIF_CONTINUATION_GRAZING_END_H_
#define DRILLBIF_CONTINUATION_GRAZING_END_H_

#include "drillbif/continuation/curve.h"

namespace drillbif::internal {

// Newton from `guess` (in tangent form: one tangent end for a fold, PD or NS curve, two for a
// grazing curve) on the system above, with params[index1] and params[index2] free, to a scaled
// step <= `tolerance`. The solved orbit, in tangent form; INVALID_ARGUMENT for a guess with the
// wrong number of tangent ends, INTERNAL when Newton fails.
StatusOr<PeriodicOrbit> SolveGrazingEnd(const HybridModel& model, Propagator& propagator,
                                        const PeriodicOrbit& guess, CurveKind kind, int index1,
                                        int index2, double tolerance = 1e-12);

// The same point where the vanishing segment lies between segments of different modes, or where
// its two events leave the monodromy discontinuous (no tangent form, or its solution is another
// point): the orbit keeps its signature with segment `segment` held at zero length (its two
// events, of different guards, at one point: a regular condition, unlike a segment between two of
// one mode, whose two guards are one), plus the curve's own condition (sigma, or h' = 0 at the
// tangent end of a grazing curve). Newton from `guess`, params[index1] and params[index2] free.
StatusOr<PeriodicOrbit> SolveZeroLengthEnd(const HybridModel& model, Propagator& propagator,
                                           const PeriodicOrbit& guess, int segment, CurveKind kind,
                                           int index1, int index2, double tolerance = 1e-12);

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_GRAZING_END_H_
