// Signature switching at grazing points: what an admissibility violation means, the test function
// that locates it, and the orbit with the new signature at the located point.
#ifndef DRILLBIF_CONTINUATION_SIGNATURE_SWITCH_H_
#define DRILLBIF_CONTINUATION_SIGNATURE_SWITCH_H_

#include <array>
#include <limits>
#include <string>

#include "drillbif/continuation/continuation.h"

namespace drillbif::internal {

// The lowest interior local minimum over (0, tau) of guard `guard` along segment `segment`:
// dense samples, each sampled local minimum refined by Newton on h' to the stationary point
// (a smooth function of the orbit near a touch). Endpoint values do not count: the segment
// starts or ends on some guards by construction. Without an interior local minimum, the smallest
// interior sample stands in (positive while admissible, so it still brackets a later touch).
// `near`: where a crossing of that guard was seen (Admissibility::time), if known; a dip there
// that no sample shows is searched for more finely.
struct GuardMinimum {
  double t = 0.0;
  double h = std::numeric_limits<double>::infinity();
};
GuardMinimum SegmentGuardMinimum(const HybridModel& model, Propagator& propagator,
                                 const PeriodicOrbit& orbit, int segment, int guard,
                                 double near = -1.0);

// For a violation whose guard fires at its segment's start (Admissibility::at_start): the guard
// at the start (t = 0), or its interior minimum where that is a stationary point below the start
// value. Where h falls after the start, that touch inside the segment comes first as the
// parameter moves, and it is crossed as a touch (SwitchSignature splits the segment there): the
// contact phase that the section splits on the a-branch of the period-2 attractor at
// omega = 0.6, a = 0.2 touches l1 0.058 after the section, 2.3e-4 in a before the guard fires at
// the section; switched at the section instead, the inserted CwP phase ended at once ("could not
// locate or cross: segment 0 (CwP) crosses l1 at t = 0").
GuardMinimum AtStartMinimum(const HybridModel& model, Propagator& propagator,
                            const PeriodicOrbit& orbit, const Admissibility& violation);

// The test function of a violation found by CheckAdmissible: positive while admissible, zero at
// the grazing point. (-1 guard: the segment's duration; at the start, AtStartMinimum's value;
// else the guard's interior minimum.)
double ViolationTestFunction(const HybridModel& model, Propagator& propagator,
                             const PeriodicOrbit& orbit, const Admissibility& violation);

struct SwitchedOrbit {
  PeriodicOrbit orbit;    // same state, new signature
  SpecialPointKind kind;  // GRAZING_L1 / L2 / PI, or SIGNATURE_CHANGE
  int new_segment = -1;   // index of the inserted zero-length segment (-1: one was removed)
  // An event crossed the Poincare section: the signature is rotated, the orbit is the same kind
  // (no special point to report).
  bool representation_only = false;
  std::string detail;  // "NC>Pi CwoP>l1 ... -> NC>Pi CwoP>l2 NC|"
};

// Lengths a zero-length segment inserted by a switch is stepped off to, tried in this order: the
// shortest at which Newton solves an admissible orbit is not known in advance (a one-parameter
// branch past a grazing, branch_tracer.cc; a fold / PD curve of the crossing form started off a
// grazing curve's codimension-2 root, trace.cc).
inline constexpr std::array<double, 3> kStepOffLengths = {1e-3, 1e-4, 1e-5};

// The orbit at a located grazing point, re-expressed in the signature that continues past it:
// a vanished segment removed (equal neighbours merged), or a segment split around a new
// zero-length segment of the mode across the touching guard.
SwitchedOrbit SwitchSignature(const HybridModel& model, Propagator& propagator,
                              const PeriodicOrbit& orbit, const Admissibility& violation);

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_SIGNATURE_SWITCH_H_
