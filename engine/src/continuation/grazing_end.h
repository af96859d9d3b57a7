// A curve's end where its orbit grazes, solved as the codimension-2 point it is. The bisection of
// the admissibility boundary (curve.cc) brackets such an end, but next to it the curve's own
// system degenerates (the vanishing segment's two events merge and a family of zero-length
// solutions meets the curve there, tangent_grazing.h), Newton fails on the last stretch and the
// bracket can stay wide (1e-5 .. 1e-2 in the reference (omega, a) box, omega in [0.05, 2], a in
// [0.01, 8] at b = 0.15). In tangent form the same point is the regular root of a square system
// in (X, lambda1, lambda2):
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

// A point of the fold / PD / NS curve that ends at such a point, just off it: the same system with
// segment `segment` held at `length` > 0 instead of zero. From a zero-length segment inserted at a
// grazing curve's codimension-2 root (CrossingForm) it steps onto the curve that ends there from
// the side of the crossing: that curve's own system is singular at its end (the segment's length
// goes like the square root of the distance), so it is started from a point off it. From a
// zero-length `segment` in `guess` the orbit with the segment `length` long is solved first with
// one parameter free (no monodromy), then the whole system from it (each parameter in turn; not
// from `guess` itself, where the system is singular: a fold / PD / NS curve's step-off fails
// where neither gives it).
StatusOr<PeriodicOrbit> SolveSegmentLength(const HybridModel& model, Propagator& propagator,
                                           const PeriodicOrbit& guess, int segment, double length,
                                           CurveKind kind, int index1, int index2,
                                           double tolerance = 1e-12);

// SolveSegmentLength's point found without the curve's condition in Newton's matrix: along the
// level set of orbits with the zero-length `segment` of `guess` `length` long (one parameter
// solved for, the other stepped), a secant on the curve's own condition (fold / PD / NS; not a
// grazing curve). Next to a fold-grazing the condition varies along that level set on the
// parameters' scale length^2, far below the differences' steps of ConditionRow (1e-6), and the
// whole system's Newton stagnates on a row of noise.
StatusOr<PeriodicOrbit> SolveSegmentLengthAlongLevel(const HybridModel& model,
                                                     Propagator& propagator,
                                                     const PeriodicOrbit& guess, int segment,
                                                     double length, CurveKind kind, int index1,
                                                     int index2, double tolerance = 1e-12);

// The same point as the limit of the curve's own points: where the zero-length system is singular
// (both events of the vanishing segment degenerate at once, as a contact phase vanishing between
// two flights: impact at zero speed and lift-off at zero force rate; Newton stagnates) and the
// tangent form's root is another point. Along the curve the segment's length tau is a regular
// coordinate near the end (the parameters move linearly in it, measured in the reference box), and
// the fixed-length system (SolveSegmentLength) is regular for tau > 0. So the curve's points at
// tau = L, 2L, 4L are solved (each from the last) and the orbit's unknowns and parameters
// extrapolated to tau = 0 by the quadratic through them (weights 8/3, -2, 1/3; error O(L^3)); the
// error of its parameters is estimated by the difference to the linear extrapolation from (L, 2L)
// (whose error, -2 c L^2 for x(tau) = a + b tau + c tau^2, dominates: a bound). L = 1e-5: the
// estimate is 3e-13 .. 2.5e-9 in the reference box, while the fold / PD condition at L stays well
// conditioned (the saltations at the segment's events grow like 1/tau; at tau = 1e-7 the
// multiplier +1 came out 1e-8 off and Newton can stagnate). A linear extrapolation left the
// orbit's flight 4e-8 off the impact surface; the quadratic one, 1e-12.
struct ExtrapolatedEnd {
  PeriodicOrbit orbit;  // segment `segment` of zero length
  // The curve's stability at tau = L with its multipliers extrapolated linearly to tau = 0 from
  // (L, 2L), paired by proximity (the orbit's own monodromy at zero length is finite but
  // ill-conditioned: its multiplier +1 came out 1e-8 .. 1e-6 off); `monodromy` is the one at L.
  Stability stability;
  double error = 0.0;  // estimated error of (params[index1], params[index2]), Euclidean
};
StatusOr<ExtrapolatedEnd> ExtrapolateZeroLength(const HybridModel& model, Propagator& propagator,
                                                const PeriodicOrbit& guess, int segment,
                                                CurveKind kind, int index1, int index2,
                                                double length = 1e-5);

// A grazing curve's end where its touch merges with the event next to it (the segment `segment`
// between them vanishes; no tangent or zero-length form applies, as the touch and the event are
// of one guard, or the touched guard and its rate vanish at the event by construction). Near such
// an end the touch time goes like the square root of the distance and the curve's system
// degenerates, so bisection stalls far from it. With the touch merged into the event (MergedForm)
// the point is a regular root of two conditions on the merged orbit:
//   touch of guard E, then the crossing of E that ends the same mode (a contact phase whose force
//   touches zero just before lift-off): h' = h'' = 0 at the crossing (a cubic tangency);
//   event, then a touch of guard G right at the next mode's start: h = h' = 0 there, or, where
//   these two vanish at every such event (a free flight leaving contact starts on the impact
//   surface at zero relative speed), h'' = h''' = 0 (the flight's h ~ -c t^4).
// params[index1] and params[index2] free; the solved orbit is in merged form. INVALID_ARGUMENT
// where the orbit has neither pattern at `segment`, INTERNAL when Newton fails.
StatusOr<PeriodicOrbit> SolveMergedTouchEnd(const HybridModel& model, Propagator& propagator,
                                            const PeriodicOrbit& guess, int segment, int index1,
                                            int index2, double tolerance = 1e-12);

// Whether guard `guard` of segment `segment`'s mode touches zero at that segment's start to third
// order (h, h', h'' all within 1e-9 (1 + |x|) of zero: far above the merged end's residual,
// ~1e-12, and far below the h'' of any transversal touch): at a merged touch end the next mode
// starts so (h ~ -c t^4), and rounding decides whether the locator sees it fire at once.
bool TouchesAtStart(const HybridModel& model, const PeriodicOrbit& orbit, int segment, int guard);

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_GRAZING_END_H_
