// Pieces of TraceCurves (continuation/trace.h) shared by its steps: curve geometry in the box's
// scaled coordinates, and the steps that add curves leaving codimension-2 points.
#ifndef DRILLBIF_CONTINUATION_TRACE_INTERNAL_H_
#define DRILLBIF_CONTINUATION_TRACE_INTERNAL_H_

#include <functional>
#include <string>
#include <vector>

#include "continuation/period_doubling.h"
#include "drillbif/continuation/trace.h"
#include "drillbif/continuation/trace_tasks.h"

namespace drillbif::internal {

class WorkerPropagators;  // continuation/curve_tasks.h

// The message of a trace that was stopped.
inline constexpr char kCancelledMessage[] = "cancelled: the curves traced until then";

// The outline of a curve's vertices (TracedCurve::outline).
CurveOutline OutlineOf(const CurveResult& c);

// Appends the curve traced from `start` to the result, with its outline (TracedCurve's fields).
void AppendCurve(const SpecialPoint& start, std::string start_param, CurveResult curve,
                 TraceResult* result, int from_curve = -1, int from_codim2 = -1);

// Distance from (u, v) to the polyline of the curve, coordinates scaled by the box's widths.
double DistanceToCurve(const CurveOutline& c, double u, double v, double w1, double w2);

// Whether (u, v) lies on the curve: within `tol` of its polyline plus, at each chord, an estimate
// of how far the curve bows away from it between the vertices (chord length times the turning
// angle at its ends over 4, twice the circular arc's L theta / 8; the angle capped at 0.5 rad,
// beyond which the estimate means nothing). Coordinates scaled by the box's widths. For points
// solved on a curve of the same kind and signature: a polyline's chord error (~1e-4 of the box
// with COARSE steps) can exceed any fixed tolerance small enough to keep curves 1e-3 apart apart.
bool OnCurve(const CurveOutline& c, double u, double v, double w1, double w2, double tol);

// Whether (u, v) lies on the traced curve: on its polyline (OnCurve), or on one of its end
// stretches, from its first or last vertex to a codimension-2 end located beyond it. A curve's last
// vertex is its last admissible point, within the end's bracket of it: ~1e-8 where the
// bisection converged, but up to ~6e-3 where Newton failed next to the end (and, before that
// vertex was kept, up to a step, 1e-3 of the box with target_iterations 4: a start located on
// that stretch, the a-branch's fold at omega = 0.1, a = 0.15688, 3.3e-5 off the polyline of the
// fold curve through it, was taken for another curve). Each end is joined to the end vertex whose
// durations are nearer its own (the curve's two ends can be nearer each other in the box than
// either is to its own last vertex). Same tolerance and chord allowance as OnCurve. Reads the
// outline and the codimension-2 points only: switching's workers call it while the trace releases
// the vertices of curves handed over.
bool OnTracedCurve(const TracedCurve& t, double u, double v, double w1, double w2, double tol);

// The curve with (value1, value2) swapped, for a curve traced with the parameters in the other
// order.
void SwapValues(CurveResult* c);

// Whether a located special point of this kind starts a grazing curve.
bool IsGrazing(SpecialPointKind kind);

// "" for period 1, else "period-n " (for notes).
std::string PeriodPrefix(int periods);

// The candidates at codimension-2 point `point` of a curve of kind `from_kind` (CandidatesTask).
std::vector<SwitchCandidate> CandidatesAt(const HybridModel& model, Propagator& propagator,
                                          CurveKind from_kind, const Codim2Point& point);

// The run of a candidate at `point` (CandidateTask): its step-off, if any, and its curve, with
// the curve options `co` of the trace's box and its parameters' indices i1, i2.
CandidateRun RunCandidate(const HybridModel& model, Propagator& propagator,
                          const TraceOptions& options, const CurveOptions& co, int i1, int i2,
                          const Codim2Point& point, const SwitchCandidate& candidate,
                          bool last_resort);

// The curve through a located start (CurveTask), its values in the start axis' order (axis 1:
// (param2, param1)).
CurveResult CurveThroughStart(const HybridModel& model, Propagator& propagator,
                              const TraceOptions& options, const SpecialPoint& start, int axis);

// Whether the trace may read a curve's vertices whole after it is appended: the period-n PD
// curves with 2n <= max_period, from whose vertices the period-2n grazing curves start.
bool KeptWhole(int max_period, const CurveResult& c);

// Drops the section states (PeriodicOrbit::starts) and monodromy of a curve's interior vertices
// (TraceOptions::vertex_states false), unless KeptWhole. The trace reads no more of them: its
// tests for known curves read the outline; edge branches start from a curve's first and last
// vertices; switching from codimension-2 points and unverified ends.
void DropVertexStates(int max_period, CurveResult* c);

// The curve options of the trace's switching: its curve options over its box.
CurveOptions SwitchCurveOptions(const TraceOptions& options);

// A candidate whose step-off needs a last-resort length (SwitchAtCodim2), kept for the end.
struct DeferredStepOff {
  size_t curve = 0;  // the point it leaves: the curve's codim2[codim2], or (-1) an unverified end
  int codim2 = 0;
  Codim2Point point;
  SwitchCandidate candidate;
};

// What switching at codimension-2 points added and could not do, over all its rounds.
struct SwitchTally {
  int added = 0;                // curves
  int wide = 0;                 // ends located only to a bracket > 1e-6
  int no_form = 0;              // ends whose grazing has no tangent form
  int unverified_no_form = 0;   // unverified ends (CurveResult) likewise, of any bracket
  int no_step_off = 0;          // roots where no inserted segment length gave an admissible orbit
  int no_step_off_grazing = 0;  // likewise at double grazings
  bool capped = false;          // max_switched_curves reached
  std::vector<DeferredStepOff> deferred;  // for the last round
};

// The notes for what switching could not do.
void TallyNotes(const SwitchTally& t, TraceSummary* sum);

// A grazing start kind named after the surface of the tangent segment's guard (or of a corner's
// second event).
SpecialPointKind GrazingKind(const HybridModel& model, const PeriodicOrbit& tangent_orbit);

// The curves that leave the codimension-2 points of the traced curves from first_curve on
// (TraceOptions::switch_at_codim2), appended to result->curves until none is new or the cap is
// reached; *tally accumulates over calls. The candidates at each point and the curves from them
// are tasks on `workers` (continuation/curve_tasks.h), applied in the order one thread computes
// them; `wait` is called while the calling thread waits for one. Step-offs that no regular length
// starts are kept in tally->deferred; with `last_resort` only those are tried (shorter lengths),
// and the curves they start appended. False when cancelled.
bool SwitchAtCodim2(const HybridModel& model, Propagator& propagator, WorkerPropagators& workers,
                    const std::function<void()>& wait, const TraceOptions& options,
                    const std::function<bool(double)>& report, size_t first_curve,
                    SwitchTally* tally, TraceResult* result, bool last_resort = false);

// The period-2n grazing curves that leave the period-n curves' FLIP_GRAZING points, for
// 2n <= TraceOptions::max_period (with switch_at_codim2), appended to result->curves; the
// flip-grazings of the curves it adds are visited too; those of the curves before first_curve
// are not (visited in an earlier round). False when cancelled (`report` returned false).
bool GrazingCurvesAtFlipGrazings(const HybridModel& model, Propagator& propagator,
                                 const TraceOptions& options,
                                 const std::function<bool(double)>& report, size_t first_curve,
                                 TraceResult* result);

// The trace's last pass over the codimension-2 entries. First, entries of period 2n that are the
// period-n flip-grazing their orbit merges into. A period-2n curve leaving a period-n
// flip-grazing (above), or a period-2n fold curve ending at one, meets there the period-n orbit
// traversed twice: the period-2n system is singular at that end (its multiplier -1 squared is a
// second +1), Newton fails next to it and the end keeps a wide bracket (1e-5 .. 10 in arclength
// in the reference box) although its parameters lie within ~1e-5 of the period-n point. Each such
// end (bracket above 1e-8, within 1e-4 (box-scaled) of a located period-n FLIP_GRAZING, its
// section state that point's to the O(sqrt(distance)) by which the passes of a period-2n orbit
// next to its birth at a PD differ) is reported as that point: kind FLIP_GRAZING, its orbit,
// parameters and bracket, `detail` naming the merge and the violation beyond, and the curve's
// message saying so. Likewise, within 3e-7 of such a point (and with the same passes' test), an
// end bisected but not solved as the point it is, and a root of det(M - I) (FOLD_GRAZING on a
// grazing curve, FOLD_FLIP on a PD curve), or such a root within the bracket of an end merged so
// on its curve: the +1 it found is that -1 squared. Then the ends (bisected, not solved) of a
// switched period-2n curve that made no step either way are reported as the point it leaves.
// Last, each point once: an entry of the same kind and period as an entry before it (curve order,
// then list order), within 1e-9 of the box, gets that entry's same_as_curve / same_as_index.
// Returns how many curve ends were reported as a flip-grazing (notes count the roots so reported,
// the ends of curves without steps and the copies).
int EndsAtFlipGrazings(const HybridModel& model, const TraceOptions& options, TraceResult* result);

// Whether EndsAtFlipGrazings may change the curve's message or its entries other than their
// same_as fields: a curve of even period with an end bracketed above 1e-8, an end bisected but not
// solved or a root of det(M - I), or a switched one that made no step.
bool MayMergeAtFlipGrazing(const TracedCurve& curve);

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_TRACE_INTERNAL_H_
