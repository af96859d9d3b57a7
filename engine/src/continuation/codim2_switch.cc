// Switching at codimension-2 points: the curves that leave the codimension-2 points found on the
// traced curves (TraceOptions::switch_at_codim2; continuation/trace_internal.h).
#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <deque>
#include <iterator>
#include <limits>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "common/format.h"
#include "continuation/curve_ends.h"
#include "continuation/curve_tasks.h"
#include "continuation/grazing_end.h"
#include "continuation/runner_tasks.h"
#include "continuation/runs_ahead.h"
#include "continuation/signature_switch.h"
#include "continuation/tangent_grazing.h"
#include "continuation/trace_internal.h"

namespace drillbif::internal {

namespace {
// The segment's lengths at a root's step-off when none of kStepOffLengths gives an admissible
// orbit, each tried in turn until a curve gets away from the point.
constexpr std::array<double, 4> kLastResortStepOffs = {1e-6, 3e-7, 1e-7, 3e-8};
// The most curves a switching round reserves room for so that its tasks can read the curves
// applied meanwhile (SwitchAtCodim2): above it (a max_switched_curves far beyond any box's need),
// the runs are computed when applied, on the calling thread.
constexpr size_t kMaxReservedCurves = 100000;

}  // namespace

SpecialPointKind GrazingKind(const HybridModel& model, const PeriodicOrbit& tangent_orbit) {
  const std::vector<SegmentSpec>& segs = tangent_orbit.signature.segments;
  const int corner = CornerSegment(model, tangent_orbit);
  for (int j = 0; j < static_cast<int>(segs.size()); ++j) {
    // A touch's surface, or a corner's second event's (e.g. l1 where an impact goes straight
    // into progression).
    if (!segs[j].tangent && j != corner) continue;
    const std::string& surface = model.guards(segs[j].mode)[segs[j].guard].surface;
    if (surface == "l1") return SpecialPointKind::kGrazingL1;
    if (surface == "l2") return SpecialPointKind::kGrazingL2;
    return SpecialPointKind::kGrazingPi;
  }
  return SpecialPointKind::kGrazingPi;
}

void TallyNotes(const SwitchTally& t, TraceSummary* sum) {
  if (t.capped) {
    sum->notes.push_back("switching stopped after " + std::to_string(t.added) +
                         " curves (max_switched_curves)");
  }
  if (t.wide + t.no_form > 0) {
    sum->notes.push_back(
        std::to_string(t.wide + t.no_form) +
        " codimension-2 points at curve ends not switched at: " + std::to_string(t.wide) +
        " located only to a bracket > 1e-6, " + std::to_string(t.no_form) +
        " where the end's grazing has no tangent form (a corner, two events at one point such "
        "as an impact straight into progression, whose curve is not traced; or no segment "
        "within 1e-6 of vanishing between two of one mode, no guard within 1e-6 of touching "
        "inside a segment)");
  }
  if (t.unverified_no_form > 0) {
    sum->notes.push_back(std::to_string(t.unverified_no_form) +
                         " unverified curve ends not switched at: no tangent form of a grazing "
                         "there (no segment within 1e-6 of vanishing between two of one mode, no "
                         "guard within 1e-6 of touching inside a segment)");
  }
  if (t.no_step_off + t.no_step_off_grazing > 0) {
    std::string lengths;
    for (const double l : kStepOffLengths) {
      lengths += (lengths.empty() ? "" : ", ") + FormatNumber(l, 1);
    }
    std::string last_resort;
    for (const double l : kLastResortStepOffs) last_resort += ", " + FormatNumber(l, 1);
    sum->notes.push_back(
        "curves not started where no admissible orbit has the inserted segment of any length "
        "tried (or the curve from it does not get away from the point): " +
        std::to_string(t.no_step_off) + " fold / PD curves at roots of grazing curves (" + lengths +
        last_resort + "), " + std::to_string(t.no_step_off_grazing) +
        " grazing curves beyond a double grazing's other boundary (" + lengths +
        "; not told apart from double grazings past which the touch's curve does not go on)");
  }
}

// The curves to try from codimension-2 point `point` of a curve of kind `from_kind` (none where
// no curve leaves it that switching starts).
std::vector<SwitchCandidate> CandidatesAt(const HybridModel& model, Propagator& propagator,
                                          CurveKind from_kind, const Codim2Point& point) {
  const bool fold = point.kind == Codim2Kind::kFoldGrazing;
  // The curves to try from this point.
  std::vector<SwitchCandidate> candidates;
  if (from_kind == CurveKind::kGrazing && point.kind == Codim2Kind::kDoubleGrazing) {
    // A grazing curve's end solved with both touches as tangent ends: the grazing curve of
    // each touch alone (the other tangent end merged away) passes; one of them is usually the
    // curve it came from (known, below), the other the second boundary's (or the first
    // touch's in the signature beyond the second boundary).
    // (An end solved with a zero-length segment for its second grazing has one tangent end:
    // merging it away leaves the corner, whose grazing curve starts there.)
    const std::vector<SegmentSpec>& segs = point.point.orbit.signature.segments;
    if (point.bracket != 0.0) return candidates;
    // And the grazing curve of each touch beyond the other's boundary, where that touch
    // has become a crossing (CrossingForm, stepped off as at a root of a grazing curve): the
    // fourth half-curve through the point. (In the reference box: a grazing curve between two
    // double grazings near (0.065, 0.166), which the a-branch at omega = 0.065 crosses, met
    // neither other way.)
    for (int j = 0; j < static_cast<int>(segs.size()); ++j) {
      if (!segs[j].tangent) continue;
      StatusOr<PeriodicOrbit> single = MergedForm(point.point.orbit, j);
      if (!single.ok()) continue;
      const SpecialPointKind k = GrazingKind(model, *single);
      candidates.push_back({std::move(single), k, CurveKind::kGrazing});
      int inserted = -1;
      StatusOr<PeriodicOrbit> crossed =
          CrossingForm(model, propagator, point.point.orbit, &inserted, j);
      if (crossed.ok()) {
        candidates.push_back({std::move(crossed), k, CurveKind::kGrazing, inserted});
      }
    }
  } else if (!fold && point.kind != Codim2Kind::kFlipGrazing) {
    return candidates;
  } else if (from_kind == CurveKind::kGrazing && point.bracket == 0.0) {
    // A root along a grazing curve: the orbit without the vanishing segment folds / doubles,
    // and so does the orbit with it, whose curve ends here from the side where the touch has
    // become a crossing (started from a point off the root, the segment's length stepped off
    // from zero). Either may be known, traced from its other end; without the second the
    // reference box lacks 174 curves (a PD curve between two flip-grazings, next to a hairpin
    // of another PD curve of its signature, is found only where longer steps jump onto it).
    const SpecialPointKind seed =
        fold ? SpecialPointKind::kFold : SpecialPointKind::kPeriodDoubling;
    const CurveKind kind = fold ? CurveKind::kFold : CurveKind::kPeriodDoubling;
    candidates.push_back({MergedForm(point.point.orbit), seed, kind});
    int inserted = -1;
    StatusOr<PeriodicOrbit> crossing =
        CrossingForm(model, propagator, point.point.orbit, &inserted);
    candidates.push_back({std::move(crossing), seed, kind, inserted});
  } else if (from_kind != CurveKind::kGrazing) {
    // A fold / PD curve's end where its orbit grazes: the grazing curve through it. An end
    // solved in tangent form is its start as it is; else the tangent form at the segment the
    // violation beyond the end says vanishes (between two of one mode), else the form found
    // from the orbit alone.
    const Admissibility& beyond = point.violation;
    const std::vector<SegmentSpec>& segs = point.point.orbit.signature.segments;
    const int i = beyond.segment;
    StatusOr<PeriodicOrbit> tangent = Status(StatusCode::kUnimplemented, "");
    const bool has_tangent =
        std::any_of(segs.begin(), segs.end(), [](const SegmentSpec& s) { return s.tangent; });
    if (has_tangent) {
      tangent = point.point.orbit;
    } else if (point.bracket == 0.0) {
      // Solved with a zero-length segment: the grazing curve of that corner (two events held
      // at one point) starts from it as it is.
      tangent = point.point.orbit;
    } else if (!beyond.admissible && beyond.guard < 0 && i > 0 &&
               i + 1 < static_cast<int>(segs.size()) && segs[i - 1].mode == segs[i + 1].mode) {
      tangent = TangentForm(point.point.orbit, i);
    }
    if (!tangent.ok()) {
      tangent = GrazingTangentForm(model, propagator, point.point.orbit);
    }
    const SpecialPointKind k =
        tangent.ok() ? GrazingKind(model, *tangent) : SpecialPointKind::kGrazingPi;
    candidates.push_back({std::move(tangent), k, CurveKind::kGrazing});
    // An end solved with a zero-length segment between events of two surfaces (a corner: a
    // contact phase between an impact and progression vanishing, the impact going straight
    // into progression) is no end of the fold / PD curve itself: past the corner its orbit
    // goes on without that segment, as a one-parameter branch does through such a
    // SIGNATURE_CHANGE, and so does the curve. (In the reference box: the PD curve through
    // (omega, a) = (0.1, 0.45763) ended at such a corner at omega = 0.0931, and its
    // continuation in the signature NC>Pi CwP>l1 CwoP>l2 NC, which the a-branches at
    // omega = 0.065 .. 0.085 cross, was never traced.)
    const bool fold_or_pd =
        from_kind == CurveKind::kFold || from_kind == CurveKind::kPeriodDoubling;
    if (fold_or_pd && !has_tangent && point.bracket == 0.0 && beyond.guard < 0 && i >= 0 &&
        i < static_cast<int>(segs.size())) {
      const SwitchedOrbit past = SwitchSignature(model, propagator, point.point.orbit, beyond);
      if (past.new_segment < 0 && !past.representation_only &&
          past.orbit.signature != point.point.orbit.signature) {
        candidates.push_back({past.orbit,
                              from_kind == CurveKind::kFold ? SpecialPointKind::kFold
                                                            : SpecialPointKind::kPeriodDoubling,
                              from_kind});
      }
    }
  }  // else a bracketed root on a grazing curve: none

  return candidates;
}

namespace {

// Whether every point of the curve lies within `distance` (box-scaled) of (u, v).
bool StaysAt(const CurveResult& curve, double u, double v, double w1, double w2, double distance) {
  return std::all_of(curve.points.begin(), curve.points.end(), [&](const CurvePoint& p) {
    return std::hypot((p.value1 - u) / w1, (p.value2 - v) / w2) <= distance;
  });
}

}  // namespace

// The orbits to start a candidate's curve from and the curves from them, on a worker's
// propagator: the candidate itself, or stepped off its zero-length segment at the first of
// kStepOffLengths that gives an admissible orbit (the same lengths as a one-parameter branch's
// step off an inserted segment), else, for a fold / PD curve, in the last round (`last_resort`),
// at each kLastResortStepOffs length in turn. Next to a contact phase vanishing between flights the
// fixed-length system can stagnate or leave the flows' domain down to 1e-5 and solve shorter (in
// the reference box: a PD curve of 253 points between two flip-grazings near (0.062, 0.17),
// crossed by the omega-branch at a = 0.17, was not traced without it; with longer steps its start
// needed 1e-7). Last, because a curve started so close to its root is traced coarsely there (its
// first steps long against the square-root scale of the orbit's change) and, traced first, it
// hid the same curve traced from its other end, and that curve's crossing with the a-branch at
// omega = 0.09. A last-resort length is solved along its level set first
// (SolveSegmentLengthAlongLevel), by the fixed-length system where that fails (a secant stalled
// on the condition's noise): that system's Newton borders the fold /
// PD condition at the root, where the zero-length segment's saltation is singular, so its first
// residual is whatever rounding makes of 0 / 0 (1e-6 or 1.1 at one fold-grazing of the
// reference box, whose fold curve was started or not by a 1e-17 difference in the root), and
// from a regular orbit of that length its condition row is noise; where it converges, its start
// lies in the band where the condition sits at its rounding floor (there: the multiplier 6.6e-6
// off 1, the level set's start 3e-9 off, 1.5e-8 away in omega).
CandidateRun RunCandidate(const HybridModel& model, Propagator& propagator,
                          const TraceOptions& options, const CurveOptions& co, int i1, int i2,
                          const Codim2Point& point, const SwitchCandidate& candidate,
                          bool last_resort) {
  CandidateRun run;
  const PeriodicOrbit& orbit = *candidate.orbit;
  const double w1 = options.width1(), w2 = options.width2();
  const double u = orbit.params[i1], v = orbit.params[i2];
  std::vector<PeriodicOrbit> starts;
  if (candidate.step_off < 0) {
    starts.push_back(orbit);
  } else {
    auto step_off = [&](double length) {
      StatusOr<PeriodicOrbit> off = InvalidArgument("");
      if (last_resort) {
        off = SolveSegmentLengthAlongLevel(model, propagator, orbit, candidate.step_off, length,
                                           candidate.kind, i1, i2);
      }
      if (!off.ok()) {
        off = SolveSegmentLength(model, propagator, orbit, candidate.step_off, length,
                                 candidate.kind, i1, i2);
      }
      if (!off.ok() || !CheckAdmissible(model, propagator, *off).admissible) return false;
      if (propagator.stopped()) return false;
      starts.push_back(*std::move(off));
      return true;
    };
    if (!last_resort) {
      for (const double length : kStepOffLengths) {
        if (step_off(length)) break;
      }
      if (starts.empty()) {
        run.deferred = true;
        return run;
      }
    } else if (candidate.kind != CurveKind::kGrazing) {
      for (const double length : kLastResortStepOffs) step_off(length);
    }
    // (A grazing curve's step-off, deferred all the same so that one whose curve is traced by
    // then is not counted as not started, has no last-resort length: the level-set secant is for
    // fold / PD curves only, and its fixed-length system, solved from the root (no consistent
    // orbit first: its tangent end's double root, SolveSegmentLength), is the one whose matrix
    // the vanishing crossing speed makes singular there. It solved less often the shorter the
    // length, in the reference box at 154, 7 and 1 candidates at the three regular lengths (with
    // --period2 889, 79 and 24), and at a last-resort length never: 0 of 108 candidates, 0 of
    // 701 with --period2.)
  }
  SpecialPoint seed;
  seed.kind = candidate.seed_kind;
  seed.point.value = point.point.value1;
  for (PeriodicOrbit& start : starts) {
    seed.point.orbit = std::move(start);
    seed.point.stability = OrbitStability(model, propagator, seed.point.orbit);
    CurveResult curve =
        ContinueCurveFromRoot(model, propagator, seed, orbit, candidate.step_off, co);
    run.stopped = propagator.stopped();
    // Started at a last-resort length but never away from the point: the next length is tried
    // (see ApplyRun).
    const bool next = !run.stopped && last_resort &&
                      curve.summary.termination != Termination::kFailed &&
                      StaysAt(curve, u, v, w1, w2, options.duplicate_distance);
    run.tries.emplace_back(seed, std::move(curve));
    if (!next) break;
  }
  return run;
}

bool SwitchAtCodim2(const HybridModel& model, Propagator& propagator, WorkerPropagators& workers,
                    const std::function<void()>& wait, const TraceOptions& options,
                    const std::function<bool(double)>& report, size_t first_curve,
                    SwitchTally* tally, TraceResult* result, bool last_resort) {
  TraceSummary& sum = result->summary;
  const double w1 = options.width1(), w2 = options.width2();
  const int i1 = model.ParamIndex(options.param1).value();
  const int i2 = model.ParamIndex(options.param2).value();
  const CurveOptions co = SwitchCurveOptions(options);
  int& added = tally->added;
  // Whether a candidate's curve is known: on a traced curve of the same kind and signature, by
  // its polyline or by one of its codimension-2 points (which lie between its vertices, off the
  // chords by up to the chord error). The signature tells curves through one point apart: at a
  // fold-grazing the fold curves of the orbits with and without the vanishing segment both pass,
  // at a double grazing the grazing curves of either touch. (Grazing candidates compared by kind
  // only were hidden by a grazing curve ending at a double grazing 4.5e-7 away.)
  // Reads curves[0, n) only: the workers call it on the curves applied so far (below).
  auto known_in = [&](const TracedCurve* curves, size_t n, const SwitchCandidate& candidate) {
    const PeriodicOrbit& orbit = *candidate.orbit;
    const Signature& curve_signature = orbit.signature;
    const double u = orbit.params[i1], v = orbit.params[i2];
    return std::any_of(curves, curves + n, [&](const TracedCurve& t) {
      // A curve's signature rotates where it crosses the Poincare section: any of its points'
      // signatures counts.
      if (t.curve.kind != candidate.kind) return false;
      const CurveOutline& line = t.outline;
      const auto same = std::find(line.signatures.begin(), line.signatures.end(), curve_signature);
      if (same == line.signatures.end()) return false;
      const int signature = static_cast<int>(same - line.signatures.begin());
      // Nor does it always tell which touch: where one contact phase touches its guard twice
      // (two tangent ends in a row at a double grazing), the curves of either touch alone have
      // the same signature and differ in how long the tangent segment is (5.5 and 24.5 at
      // (0.0628, 0.1813) in the reference box, where the one was taken for the other and the
      // second touch's curve, crossed by the omega-branch at a = 0.18, was not traced). So a
      // curve with points of that signature next to this one (within 1e-2 of the box) is another
      // curve when none of them has its durations, to within a longest step and 10% (a step
      // changes a duration by at most its arclength). Any of them, not the nearest in the
      // parameters: that one may lie on another stretch of the same curve (a hairpin, or the
      // two ends of a short curve, close in the box's scaling), farther from this point along the
      // curve than its neighbour there; with longer steps the neighbour's vertex lies farther
      // off (a PD curve between two flip-grazings 9.3e-5 apart in the box, whose vertex next to
      // one end lies 2.2e-4 from it: the nearest vertex, at the other end, has another segment
      // 2.6 long instead of 0.97, and the curve was traced again from that end).
      bool near = false, agrees = false;
      for (size_t k = 0, from = 0; k < line.size() && !agrees; ++k) {
        const size_t count = line.SignatureAt(k).segments.size();
        if (line.signature[k] == signature &&
            std::hypot((line.values1[k] - u) / w1, (line.values2[k] - v) / w2) <= 1e-2) {
          near = true;
          const float* d0 = line.durations.data() + from;
          const std::vector<double>& d1 = orbit.durations;
          agrees = true;
          for (size_t i = 0; i < count && i < d1.size() && agrees; ++i) {
            agrees = std::abs(d0[i] - d1[i]) <= co.steps.max_step + 0.1 * std::abs(d1[i]);
          }
        }
        from += count;
      }
      if (near && !agrees) return false;
      if (OnTracedCurve(t, u, v, w1, w2, options.duplicate_distance)) return true;
      return std::any_of(t.curve.codim2.begin(), t.curve.codim2.end(), [&](const Codim2Point& z) {
        return std::hypot((z.point.value1 - u) / w1, (z.point.value2 - v) / w2) <=
               options.duplicate_distance;
      });
    });
  };
  auto known = [&](const SwitchCandidate& candidate) {
    return known_in(result->curves.data(), result->curves.size(), candidate);
  };
  // With more than one thread a point's task computes its candidates' runs too, each unless its
  // curve is known among the curves applied so far: `published` of them, at addresses that do
  // not move while the stage runs (the room reserved for every curve it may append: up to the
  // cap, and one cut short by a stop). A candidate known then is known when applied (the curves
  // only grow); one not known then may be known when applied, its run dropped. With one thread
  // the runs are computed when applied, as a plain loop would.
  const size_t room = static_cast<size_t>(std::max(0, options.max_switched_curves - added)) + 1;
  const bool speculate = workers.threads() > 1 && room <= kMaxReservedCurves;
  if (speculate) result->curves.reserve(result->curves.size() + room);
  const TracedCurve* const applied = result->curves.data();
  std::atomic<size_t> published{result->curves.size()};
  // Applies what a candidate from point q of curve c (-1: one of its unverified ends) gave:
  // nothing when its curve is known (`is_known`), else the curve traced from its start (appended
  // to result->curves) or counted among the failures; a step-off no regular length starts is
  // deferred to the last round. `take` gives the task's run. False when max_switched_curves is
  // reached or a stop cut the run.
  auto apply = [&](size_t c, int q, const Codim2Point& point, const SwitchCandidate& candidate,
                   bool is_known, const std::function<CandidateRun()>& take) {
    if (!candidate.orbit.ok()) {
      // An unverified end is no located point: counted apart, whatever its bracket.
      ++(q < 0 ? tally->unverified_no_form : point.bracket > 1e-6 ? tally->wide : tally->no_form);
      return true;
    }
    if (is_known) return true;
    CandidateRun run = take();
    if (run.deferred) {
      tally->deferred.push_back({c, q, point, candidate});
      return true;
    }
    const double u = candidate.orbit->params[i1], v = candidate.orbit->params[i2];
    bool started = false;
    for (size_t t = 0; t < run.tries.size() && !started; ++t) {
      const SpecialPoint& seed = run.tries[t].first;
      CurveResult curve = std::move(run.tries[t].second);
      if (added == options.max_switched_curves) {
        tally->capped = true;
        return false;
      }
      if (run.stopped && t + 1 == run.tries.size()) {
        // Cut short by a stop: kept with what it has (termination kCancelled), if anything.
        if (!curve.points.empty()) {
          AppendCurve(seed, "", std::move(curve), result, static_cast<int>(c), q);
        }
        return false;
      }
      if (curve.summary.termination == Termination::kFailed) {
        // An unverified end is no located point (CurveResult::unverified_ends): named so.
        const std::string what = q < 0 ? std::string("curve end (unverified: no ") +
                                             Codim2KindName(point.kind) + " point claimed)"
                                       : std::string(Codim2KindName(point.kind));
        sum.notes.push_back(PeriodPrefix(point.point.orbit.signature.periods) + what + " at " +
                            options.param1 + " = " + std::to_string(u) + ", " + options.param2 +
                            " = " + std::to_string(v) + ": the " +
                            PeriodPrefix(candidate.orbit->signature.periods) +
                            CurveKindName(candidate.kind) +
                            " curve leaving it not traced: " + curve.summary.message);
        started = true;  // named in the note, not counted as a failed step-off
        break;
      }
      // Started at a last-resort length but never away from the point: from most such starts
      // the curve ends at once both ways, back at the root and where its corrector fails at the
      // first step (in the reference box: nine curves at 1e-6, each within 1e-9 of its root,
      // seven with their second end bracketed only to 5 .. 7 in arclength). Kept, such a curve
      // would also hide the real curve of its signature through the point from a later start
      // (it hid two, of 11 and 80 points). The next length is tried.
      if (last_resort && StaysAt(curve, u, v, w1, w2, options.duplicate_distance)) continue;
      // Stepped off its root, the start may have landed on a traced curve of the candidate's kind
      // and signature elsewhere nearby (a fold curve's end stretch, 1e-3 of the box from the
      // root it left): its curve is that one again (seven fold curves of the reference box were
      // traced twice so, with either step setting).
      if (candidate.step_off >= 0) {
        SwitchCandidate landed = candidate;
        landed.orbit = seed.point.orbit;
        if (known(landed)) {
          started = true;
          break;
        }
      }
      AppendCurve(seed, "", std::move(curve), result, static_cast<int>(c), q);
      published.store(result->curves.size(), std::memory_order_release);
      ++added;
      started = true;
    }
    if (!started) {
      ++(candidate.kind == CurveKind::kGrazing ? tally->no_step_off_grazing : tally->no_step_off);
    }
    return true;
  };

  // The work, in the order one thread does it: per point, its candidates and their runs (one
  // task; see `speculate`), applied in order; in the last round, one task per deferred
  // candidate's run.
  struct Work {
    std::vector<SwitchCandidate> candidates;
    std::vector<std::optional<CandidateRun>> runs;  // per candidate, if computed by the task
  };
  struct Item {
    size_t c;
    int q;  // the point: codim2[q] of curve c, -1 for unverified_ends[e - located]
    Codim2Point point;
    std::optional<SwitchCandidate> candidate;  // the last round's deferred candidate
    size_t order = 0;                          // its place in the queue
    bool task = true;                          // whether a task computes it (else: when applied)
  };
  // The runs of `w`'s candidates (item `order`, on worker `worker`) not known among the curves
  // applied so far nor among those the runs of earlier items traced (`speculate`). A run is also
  // stopped, and left out, once its candidate becomes known so while it runs (mostly the same
  // curve traced from its other end by an earlier item's run, finished meanwhile). (Declared
  // before the stage, as is everything its tasks refer to: the stage's end waits for the tasks
  // still running, e.g. after a stop.)
  RunsAhead ahead;
  auto run_unknown = [&](int worker, const Codim2Point& point, size_t order, Work* w) {
    Propagator& p = workers.at(worker);
    w->runs.resize(w->candidates.size());
    for (size_t i = 0; i < w->candidates.size() && !p.stopped(); ++i) {
      const SwitchCandidate& candidate = w->candidates[i];
      if (!candidate.orbit.ok()) continue;
      // Each look checks only the applied curves it has not seen, and the runs ahead only when
      // one was recorded since the last look.
      size_t seen_applied = 0, seen_ahead = 0;
      auto known_now = [&] {
        const size_t n = published.load(std::memory_order_acquire);
        if (known_in(applied + seen_applied, n - seen_applied, candidate)) return true;
        seen_applied = n;
        const size_t a = ahead.added();
        if (a == seen_ahead) return false;
        seen_ahead = a;
        return ahead.AnyBefore(order,
                               [&](const TracedCurve& t) { return known_in(&t, 1, candidate); });
      };
      if (known_now()) continue;
      std::optional<CandidateRun> run;
      if (!workers.UnlessMoot(worker, known_now, [&] {
            run = RunCandidate(model, p, options, co, i1, i2, point, candidate, last_resort);
          })) {
        continue;
      }
      ahead.Add(order, *run);
      w->runs[i] = std::move(run);
    }
  };
  TaskStage<Work> stage(workers);
  OrderedTasks<Work>& tasks = stage.tasks();
  // With a task runner (TraceOptions::task_runner) the tasks go there instead; a runner's error
  // ends the trace failed with it, its CANCELLED (the trace was stopped) cancelled.
  std::optional<RunnerSwitchQueue> remote;
  if (options.task_runner != nullptr) {
    remote.emplace(
        *options.task_runner,
        [&] {
          wait();
          return !propagator.stopped();
        },
        known, last_resort);
  }
  const size_t window = remote ? remote->window() : stage.window();
  auto fail = [&](const Status& why) {
    if (why.code() != StatusCode::kCancelled) {
      sum.Fail(why);
    } else if (!sum.cancelled()) {
      sum.Cancel(kCancelledMessage);
    }
    return false;
  };
  // How the round ended: false when cancelled or failed.
  auto ended = [&] { return !propagator.stopped() && !sum.failed() && !sum.cancelled(); };
  std::deque<Item> items;
  size_t queued_items = 0;
  size_t queued_tasks = 0;  // items queued with a task and not applied: the window's
  auto queue = [&](Item item, CurveKind from_kind) {
    item.order = queued_items++;
    if (remote) {
      const Status queued = remote->Queue(from_kind, item.point, item.candidate);
      items.push_back(std::move(item));
      ++queued_tasks;
      return queued.ok() || fail(queued);
    }
    // The last round's grazing candidates have no last-resort length (RunCandidate): nothing to
    // run ahead, so no task, and no room taken in the window. (In the reference box 167 of the
    // 194 deferred candidates. Counted in the window, they kept the other worker idle while
    // a long run, up to ~130 ms, held the front: the fold / PD runs after it were too far back.)
    item.task = !(last_resort && item.candidate && item.candidate->kind == CurveKind::kGrazing);
    if (!item.task) {
      items.push_back(std::move(item));
      return true;
    }
    ++queued_tasks;
    tasks.Push(
        [&, order = item.order, from_kind, point = item.point, fixed = item.candidate](int worker) {
          Propagator& p = workers.at(worker);
          Work w;
          if (fixed.has_value()) {
            w.candidates = {*fixed};
          } else {
            w.candidates = CandidatesAt(model, p, from_kind, point);
          }
          if (speculate) run_unknown(worker, point, order, &w);
          return w;
        });
    items.push_back(std::move(item));
    return true;
  };
  // The runner's front item as the threads' Work (its runs taken when applied).
  auto take_remote = [&](Work* w) {
    if (Status s = remote->Promote(); !s.ok()) return fail(s);
    StatusOr<std::vector<SwitchCandidate>> candidates = remote->FrontCandidates();
    if (!candidates.ok()) return fail(candidates.status());
    w->candidates = *std::move(candidates);
    return true;
  };
  // Applies the first item: its candidates in order, each from its run (computed by the task,
  // else now on the calling thread's propagator). False when the round ends (cap, stop).
  auto apply_front = [&]() {
    const Item item = std::move(items.front());
    items.pop_front();
    Work w;
    if (!item.task) {
      w.candidates = {*item.candidate};
    } else {
      --queued_tasks;
      if (!remote) {
        w = *tasks.TakeFront(wait);
      } else if (!take_remote(&w)) {
        return false;
      }
    }
    if (propagator.stopped()) return false;  // the candidates are not to be trusted
    w.runs.resize(w.candidates.size());
    bool taken = true;  // false once a runner could not give a run
    for (size_t i = 0; i < w.candidates.size() && taken; ++i) {
      const SwitchCandidate& candidate = w.candidates[i];
      const bool is_known = candidate.orbit.ok() && known(candidate);
      if (is_known && remote) remote->DropRun(i);
      auto take = [&]() -> CandidateRun {
        if (w.runs[i].has_value()) return *std::move(w.runs[i]);
        if (remote) {
          StatusOr<CandidateRun> run = remote->TakeRun(i);
          if (run.ok()) return *std::move(run);
          // The trace ends failed or cancelled below: what apply() makes of this empty run (a
          // failed step-off in the tally) is never reported.
          taken = fail(run.status());
          return CandidateRun{};
        }
        return RunCandidate(model, propagator, options, co, i1, i2, item.point, candidate,
                            last_resort);
      };
      if (!apply(item.c, item.q, item.point, candidate, is_known, take)) return false;
    }
    if (remote) remote->PopFront();
    ahead.Applied(item.order);
    return taken;
  };

  if (last_resort) {
    std::vector<DeferredStepOff> deferred;
    deferred.swap(tally->deferred);
    size_t next = 0;
    for (size_t k = 0; k < deferred.size(); ++k) {
      for (; next < deferred.size() && queued_tasks < window; ++next) {
        const DeferredStepOff& d = deferred[next];
        if (!queue({d.curve, d.codim2, d.point, d.candidate}, d.candidate.kind)) return false;
      }
      if (!report(0.99)) return false;
      if (!apply_front()) return ended();
    }
    return ended();
  }
  // result->curves grows while it is walked: index, not iterator. After its codimension-2 points
  // a curve's unverified ends (CurveResult::unverified_ends): not located, but the curves that
  // may leave there are tried as from a located end (in the reference box with max_period 2 that
  // adds 413 curves and 11 period-2 codimension-2 points, located to 1e-8, that no other curve
  // reaches).
  size_t c = first_curve, e = 0;
  auto queue_points = [&] {
    while (c < result->curves.size() && queued_tasks < window) {
      const CurveResult& curve = result->curves[c].curve;
      const size_t located = curve.codim2.size();
      if (e >= located + curve.unverified_ends.size()) {
        ++c, e = 0;
        continue;
      }
      const size_t at = e++;
      if (!queue(
              {c, at < located ? static_cast<int>(at) : -1,
               at < located ? curve.codim2[at] : curve.unverified_ends[at - located], std::nullopt},
              curve.kind)) {
        return false;
      }
    }
    return true;
  };
  for (bool queued = queue_points(); !items.empty(); queued = queue_points()) {
    if (!queued) return false;
    if (!report(0.99)) return false;
    if (!apply_front()) return ended();
  }
  return ended();
}

}  // namespace drillbif::internal
