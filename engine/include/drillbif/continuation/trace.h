// Every bifurcation curve through a start orbit's branches in a box of two parameters: the branch
// through the start orbit is continued in each of the two parameters over the box, and from every
// fold, period doubling and grazing located on those branches the curve of such points is traced
// (continuation/curve.h), with its codimension-2 points. A point that lies on a curve already
// traced from another start of the same kind (within `duplicate_distance` of its polyline in the
// box's scaled coordinates) is not traced again; the skipped starts are named in the notes.
//
// With max_period 2 (4, ...), the same for the period-2 branches born at the period-1 branches'
// period doublings (and the period-4 branches born at theirs, ...).
//
// Then, with switch_at_codim2, the curves that leave the codimension-2 points found on them; with
// max_period > 1 also the period-2n grazing curves leaving the period-n flip-grazings.
//
// Not yet: switching at DOUBLE_GRAZING points (the second grazing curve through them), at
// codimension-2 ends certified only to a wide bracket; period 4 and beyond.
#ifndef DRILLBIF_CONTINUATION_TRACE_H_
#define DRILLBIF_CONTINUATION_TRACE_H_

#include <functional>
#include <string>
#include <vector>

#include "drillbif/common/parameter_box.h"
#include "drillbif/continuation/curve.h"

namespace drillbif {

class TraceTaskRunner;  // continuation/trace_tasks.h

// The most threads a trace may ask for: more than any machine it runs on has cores.
constexpr int kMaxTraceThreads = 256;

// The box (ParameterBox): finite, min < max, the start orbit inside.
struct TraceOptions : ParameterBox {
  // A located point within this distance of the polyline of an already traced curve started from
  // a point of the same kind (coordinates scaled by the box's widths) is taken as on it. Small on
  // purpose: near omega = 0.1, a = 0.16 distinct curves lie 1e-3 of the box apart, and a curve
  // traced twice costs time while a curve skipped is lost. The polyline's chord error (~ step^2
  // times the curvature) can exceed it; a located point would then start its curve twice (not
  // seen in the reference (omega, a) box, omega in [0.05, 2], a in [0.01, 8] at b = 0.15: curves of
  // one kind come within 1e-5 of each other at one vertex at most). Curves switched onto at
  // codimension-2 points, compared with curves of the same signature, allow for that error too (a
  // grazing curve with COARSE steps was traced twice).
  double duplicate_distance = 1e-5;
  // The longest period traced: 1 (default), 2, 4, 8 or 16. With 2, also the period-2 curves: at
  // every period doubling of the period-1 branches the period-2 branch born there
  // (SwitchAtPeriodDoublingAlgebraic, else SwitchAtPeriodDoubling) is continued over the box in
  // the same parameter, away from the doubling, and the curves of its folds, period doublings and
  // grazings are traced; with switch_at_codim2, also the period-2 grazing curve leaving each
  // period-1 FLIP_GRAZING (found from the PD curve next to it). With 4, the same once more from
  // the period-2 branches' doublings and flip-grazings, and so on. Asked for, not implied: each
  // level multiplies the work.
  int max_period = 1;
  // More starts: at each of these values of param1 (inside the box), the attractor at that value
  // and the start's other parameters (simulated from seed_state, solved as a periodic orbit) and
  // its branches in both parameters over the box, like the start's; their points start curves
  // unless already on a traced one. Curves that no branch through the start meets and no
  // switching reaches are found so: in the reference box a seed at omega = 0.07 added ~240 curves
  // of the network below omega = 0.09 before the edge branches (below), and none once they were in.
  // An attractor not found, or of a period above max_period, is named in a note.
  std::vector<double> seeds1;
  StateVector seed_state;  // empty: the model's default initial state
  // Then, repeatedly until no end is new: at each end of a fold, PD or NS curve on the box's edge,
  // the branch along that edge (in the other parameter, over the box) through the end's orbit,
  // unless a branch run along that edge located that end's point already; the curves of its
  // points (unless on a traced one) and the curves leaving their codimension-2 points. Curves
  // that neither cross a branch through the start nor meet a curve that does, but cross the
  // box's edge on a branch a traced curve ends on, are found so: in the reference box two branches
  // along omega = 0.05 (the decreasing a-branch snakes there through many more turns than at
  // omega = 0.1) add 8 curves to the 756 traced without them (306 to 436 before switching at
  // double grazings reached most of that network too), ~1 s. Grazing curves' ends start no edge
  // branch; the period-2n branches born at an edge branch's doublings are not continued
  // (max_period > 1). An edge branch that stops early is a note, not a failure.
  bool edge_branches = true;
  // Also the curves that leave the codimension-2 points found (switching), repeatedly until no new
  // curve appears: from a FOLD_GRAZING / FLIP_GRAZING located as a root along a grazing curve,
  // the fold / PD curve of the orbit without the vanishing segment (the grazing orbit with its
  // tangent end merged away has the multiplier +1 / -1 there); from a fold or PD curve ending at
  // a FOLD_GRAZING / FLIP_GRAZING, the grazing curve through that end; from a grazing curve
  // ending at a DOUBLE_GRAZING solved with both touches as tangent ends, the grazing curve of
  // each touch alone (one is the curve it came from). A candidate on a curve already traced with
  // the same kind and signature is skipped.
  bool switch_at_codim2 = true;
  // Whether every curve vertex stays in the result whole. False, for callers that read a curve's
  // vertices from TraceCurves' on_curve only (the trace job): a curve's interior vertices drop
  // their section states (PeriodicOrbit::starts) and monodromy (Stability::monodromy) when it is
  // appended, and are released from `points` once it is handed over to on_curve, its outline
  // (TracedCurve::outline) keeping what the trace reads of them. The first and last vertices,
  // codimension-2 points, unverified ends, and the period-n PD curves with 2n <= max_period stay
  // whole (the trace starts branches and curves from them). A period-2 vertex holds ~2.4 KB whole,
  // ~0.75 KB without its states, ~0.1 KB in the outline.
  bool vertex_states = true;
  // Cap on the curves added by switching (a note says when hit): a guard against runaway, above
  // what the reference box needs (436 curves in all; 2884 with max_period 2, which 2000 cut short).
  int max_switched_curves = 5000;
  // The threads on which the curves are traced (each curve a task; see TraceCurves): 0 means
  // every core. The result is the same whatever the number (the tasks' results are applied in
  // the order one thread computes them).
  int threads = 1;
  // Where the tasks run instead of those threads (continuation/trace_tasks.h), e.g. as child jobs
  // of the service's store; null: the threads. Not owned; must outlive the trace.
  TraceTaskRunner* task_runner = nullptr;
  // For the one-parameter runs (param, min, max are set here; BranchOptions). The steps aim at 4
  // corrector iterations, as the curves' do: on the reference box's period-1 branches about half
  // the steps of 3, and every special point that 3 locates.
  ContinuationOptions branch = [] {
    ContinuationOptions o;
    o.steps.target_iterations = 4;
    return o;
  }();
  // The steps of the branches of period-2n orbits (born at doublings and flip-grazings, or run
  // along the box's edges from period-2n curves) aim at this many iterations instead. Their
  // events crowd (each copy of a nearly twice-traversed orbit reaches a surface at nearly the
  // same parameter), and with max_period 2 over the reference box steps aiming at 4 left three
  // period-2 branches FAILED and two edge branches stopped early, where 3 completes every one
  // (the failures examined: a step over two events, a new signature's first point already past
  // a second one).
  int doubled_branch_target_iterations = 3;
  // `branch` for the branch of an orbit of `periods` periods.
  ContinuationOptions BranchOptions(int periods) const;
  // For the curves (params and box are set here). Its crossings1 / crossings2 are values of
  // param1 / param2 of these options, whichever order a curve is traced in.
  CurveOptions curve;

  Status Validate() const;
};

// What the trace reads of a curve's vertices once they may be released (TraceOptions::
// vertex_states): its polyline, and each vertex's signature and durations (the tests for known
// curves tell curves through one point apart by them, to a longest step and 10%: single precision,
// 6e-8 relative, is ample). A period-2 vertex (~20 segments) takes ~100 bytes here against ~750
// as a CurvePoint.
struct CurveOutline {
  std::vector<double> values1, values2;  // each vertex's (lambda1, lambda2)
  std::vector<Signature> signatures;     // the distinct signatures, in the order first met
  std::vector<int> signature;            // each vertex's, an index into `signatures`
  // Every vertex's durations, one vertex after another (vertex k's as many as its signature has
  // segments).
  std::vector<float> durations;

  size_t size() const { return values1.size(); }
  const Signature& SignatureAt(size_t k) const { return signatures[signature[k]]; }
};

// Where a traced curve came from.
struct TracedCurve {
  SpecialPoint start;       // the located point it was traced from
  std::string start_param;  // the parameter of the branch that located it ("" after switching)
  CurveResult curve;        // points as (value1, value2) = (param1, param2) of TraceOptions
  int from_curve = -1;      // after switching: the curve whose codimension-2 point it leaves
  int from_codim2 = -1;     // and that point's index in its codim2, -1 for one of its
                            // unverified_ends (`start` is the point the curve was continued
                            // from: that point, or one stepped off it)
  CurveOutline outline;     // of curve.points, set when the trace appends the curve
};

// How a trace ended (common/termination.h): kFailed only when it could not start (status
// says why); kCancelled when progress or on_curve stopped it (the curves are those traced until
// then); else kCompleted, a curve or branch that failed being named in the notes.
struct TraceSummary : RunSummary {
  // Starts skipped (duplicates, unsupported), with why; switching tallies; and, per period, how
  // many codimension-2 points are known only to a bracket above 1e-8 (none of period 1 in the
  // reference (omega, a) box).
  std::vector<std::string> notes;
  int64_t branch_points = 0;  // points of the one-parameter runs
  int64_t curves = 0;         // curves traced (TraceResult::curves)
  // "completed: 436 curves, 5200 branch points, 12 notes" (RunSummary::BriefReport).
  std::string BriefReport() const;
};

struct TraceResult {
  std::vector<TracedCurve> curves;
  TraceSummary summary;
};

// Called with the fraction done in [0, 1] (ProgressCallback, common/progress.h), through a
// ProgressThrottle: about every 5 ms of computation (every flow of every branch, curve and switch
// polls it) and whenever the fraction passes a percent (before each curve). Returning false
// cancels within milliseconds: the result then holds the curves traced until then (a curve cut
// short kept with what it has, its termination kCancelled), summary.termination kCancelled.
using TraceProgress = std::function<bool(double fraction)>;

// Receives a traced curve when it is final, with its index in TraceResult::curves (the curve is
// valid during the call only); returning false stops the trace as the progress callback does.
// Called once per curve, on the calling thread, in index order but for the curves held back: a
// curve is final when it is appended, except a period-2n curve with a codimension-2 end bracketed
// only above 1e-8, whose end the trace's last pass may report as the period-n FLIP_GRAZING its
// orbit merges into (internal::EndsAtFlipGrazings); those are handed over at the end, in index
// order, and the curves after them do not wait. With max_period 1 every curve is handed over as
// soon as it is traced. The curves are kept in the result as well (the trace needs them to skip
// duplicates and switch; see TraceOptions::vertex_states for their size). Exception: the
// same_as_curve / same_as_index fields of codimension-2 entries (a point met from several curves,
// Codim2Point) are set by that last pass, after the hand-over; read them in the result.
using TracedCurveCallback = std::function<bool(int index, const TracedCurve& curve)>;

TraceResult TraceCurves(const HybridModel& model, Propagator& propagator,
                        const PeriodicOrbit& start, const TraceOptions& options,
                        const TraceProgress& progress = {},
                        const TracedCurveCallback& on_curve = {});

}  // namespace drillbif

#endif  // DRILLBIF_CONTINUATION_TRACE_H_
