#include "continuation/curve_ends.h"

#include <algorithm>
#include <cmath>
#include <complex>
#include <functional>
#include <utility>

#include "continuation/grazing_end.h"
#include "continuation/tangent_grazing.h"

namespace drillbif::internal {

namespace {

bool SameViolation(const Admissibility& a, const Admissibility& b) {
  return a.segment == b.segment && a.guard == b.guard && a.at_start == b.at_start;
}

}  // namespace

using Vec = CurveEnds::Vec;
using Mat = CurveEnds::Mat;

std::string UnverifiedEndText(const CurveOptions& options, const Codim2Point& end,
                              const std::string& why) {
  return "next to (" + options.param1 + ", " + options.param2 + ") = (" +
         std::to_string(end.point.value1) + ", " + std::to_string(end.point.value2) +
         "), where only a prediction beyond, not a corrected orbit, is inadmissible (" + why +
         "): no " + Codim2KindName(end.kind) + " point claimed";
}

// The admissibility boundary between curve points ya (admissible) and yb (not): bisection in
// the arclength along t, each midpoint of the chord corrected onto the curve in the hyperplane
// normal to t, until the bracket is below tol (1 + |y|). Beyond the boundary the extended
// system need not be smooth (a segment of negative duration may cross a guard) and Newton can
// stall there: a midpoint that does not correct counts as beyond, but then the boundary is
// only known to lie between ya and the nearest corrected inadmissible point `beyond`. ya is
// always a corrected admissible point; `why` / `violation` name the violation at `beyond`.
// `beyond_corrected`: whether `beyond` is a corrected point (not where the end came from a
// prediction, CurveTracer::EndAhead's, and no midpoint beyond the boundary corrected since).
// From a prediction, a midpoint beyond counts so only where it lands within kMaxDrift of its
// distance from ya (as a step's): period-2 curves next to slow lift-offs brought
// predictions ~65 ahead (where the tangent said a flight vanishes), whose first midpoints
// corrected ~50 away onto orbits with that flight -24 long, and the end was reported with a
// bracket of ~100 though the curve had stopped for its corrector failing at the last point (8
// of the 12 entries above 1e-8 in omega [0.09, 0.11], a [0.25, 0.75]). The bisection's course
// is the same either way (refusing such midpoints moved a period-1 curve's end of the
// reference box, whose bisection had jumped 7e-4 along it, to a FOLD_GRAZING 4e-5 before the
// jump, and left a 3-point piece of it at the box's edge untraced).
struct CurveEnds::Boundary {
  Vec ya, yb, beyond;
  std::string why;
  Admissibility violation;
  bool beyond_corrected = true;
  bool from_prediction = false;
  double Width(const Vec& t) const { return t.dot(beyond - ya); }
};

// Whether a violation is an event reaching the Poincare section rather than a grazing: the
// first or the last segment vanishes, or the first segment's own ending guard fires at its
// start (the same, seen by the event locator before the duration turns negative), or, on a
// grazing curve whose first segment ends in its touch, that guard fires in the last segment
// (of the same mode, running on across the section into the first): the touch reaching the
// section, its guard within rounding of zero at the last segment's end. (In the reference box: a
// grazing curve ended so at (0.1318, 0.1577) as a DOUBLE_GRAZING, and its part beyond the
// section, crossed by the omega-branch at a = 0.17, was never traced.)
// `end` is the last admissible orbit: its first segment must be of zero length to rounding
// (the guard firing anywhere else inside it is a grazing, not a crossing); for a touch seen in
// the last segment, up to 1e-6: the guard is quadratic about the touch, its value at the
// section ~h'' d^2 / 2 for the first segment d long, and rounding makes it fire while d is
// still ~sqrt(2 eps / h'') (4e-9 .. 1.9e-8 measured at three of the box's four such ends, the
// fourth below 1e-9).
bool CurveEnds::IsSectionCrossing(const Admissibility& v, const PeriodicOrbit& end) const {
  const double first_max = v.guard >= 0 && v.segment != 0 ? 1e-6 : 1e-9;
  return MayBeSectionCrossing(v) && (v.guard < 0 || std::abs(end.durations[0]) <= first_max);
}

// IsSectionCrossing without the end's first-segment duration (which needs the boundary
// bisected to rounding).
bool CurveEnds::MayBeSectionCrossing(const Admissibility& v) const {
  const std::vector<SegmentSpec>& segs = system_.bvp().signature().segments;
  const int k = static_cast<int>(segs.size());
  if (v.admissible || k < 3) return false;
  if (v.guard < 0) return v.segment == 0 || v.segment == k - 1;
  if (v.segment == k - 1) {
    return !v.at_start && segs[0].tangent && v.guard == segs[0].guard &&
           segs[k - 1].mode == segs[0].mode;
  }
  return v.segment == 0 && v.guard == segs[0].guard && !segs[0].tangent;
}

void CurveEnds::Bisect(const Vec& t, double tol, Boundary* b) const {
  tol *= 1.0 + b->ya.lpNorm<Eigen::Infinity>();
  PseudoArclengthCorrector corrector = system_.NewCorrector();
  auto trial = [&](const Vec& mid) {
    Vec yc;
    std::string reason;
    Admissibility violation;
    const Side side = CorrectMidpoint(&corrector, t, mid, b->violation, &yc, &reason, &violation);
    if (side == Side::kUncorrected) {
      b->yb = mid;
    } else if (side == Side::kAdmissible) {
      b->ya = yc;
    } else {
      b->yb = b->beyond = yc, b->why = reason, b->violation = violation;
      b->beyond_corrected =
          !b->from_prediction || (yc - mid).norm() <= kMaxDrift * (mid - b->ya).norm();
    }
  };
  TryKnownEnd(t, tol, b, trial);
  for (int it = 0; it < 80 && t.dot(b->yb - b->ya) > tol && !system_.Stopped(); ++it) {
    trial(0.5 * (b->ya + b->yb));
  }
}

// The midpoints of a bisection close in on one point, each corrected in the hyperplane normal to
// the same t, so chord iterations on the factorization of an earlier midpoint's full correction
// converge in a few residual evaluations, where a full correction evaluates and factorizes the
// Jacobian (its condition row one monodromy factor per unknown) at every iteration. Their point
// decides where it is admissible, or where it violates what was already seen beyond (`seen`); a
// new kind of violation is left to a full correction, which also renews the factorization. Next
// to a section crossing, where the first segment's length goes to zero, chord iterations
// converged to neighbouring orbits whose first segment's guard fires at its start, ~3e-8 before
// the crossing that full corrections bracket (in the reference box 15 section crossings were so
// taken for grazings, and 7 curves were lost). Where a full correction would fail beyond the
// boundary, a chord point beyond may still decide it: the boundary is then bracketed by a nearer
// corrected point. In the reference box 8.6k of the bisections' 37.9k midpoints are corrected in
// full, and the period-1 network is that of full corrections throughout (the period-2 one moves
// as under any rounding-level change: docs/performance.md).
CurveEnds::Side CurveEnds::CorrectMidpoint(PseudoArclengthCorrector* corrector, const Vec& t,
                                           const Vec& mid, const Admissibility& seen, Vec* yc,
                                           std::string* why, Admissibility* violation) const {
  if (system_.ChordCorrect(corrector, mid, t, yc)) {
    if (system_.Admissible(system_.Unpack(*yc), why, violation)) return Side::kAdmissible;
    if (SameViolation(*violation, seen)) return Side::kBeyond;
  }
  if (!system_.CorrectKeeping(corrector, mid, t, yc)) return Side::kUncorrected;
  return system_.Admissible(system_.Unpack(*yc), why, violation) ? Side::kAdmissible
                                                                 : Side::kBeyond;
}

namespace {

// The segment j vanishing at a curve's end, seen (v, at the last admissible orbit o) as its
// duration turning negative, or as a guard firing before the duration does (the duration goes
// like the square root of the distance to the grazing, and its end guard's rate h' with it):
// j's own guard inside j while j is at most 1e-5 long (1e-3 where it fires at j's start: j wants
// to end at once; a PD curve of the reference box stopped with a progression phase 2e-5 long
// whose l1 fired at its start), or, at the very start of the next segment, the guard that led
// into j from the segment before it (j would start again at once), or, before the end of the
// segment before it, that segment's own guard (the one that starts j) firing early: the flow of
// that mode touches the guard where j shrinks away, as a contact phase's force reaching the
// progression threshold just before a short progression phase between two contact phases
// vanishes (a PD curve of the reference box with longer steps: l1 inside CwoP 6e-3 before its
// end, CwP 3e-3 long, bracket 6e-3 as Newton fails next to the end); j at most 1e-2 long (a
// touch inside a segment followed by a long one is an interior grazing, the touch form's); or a
// guard firing at the very start of a segment while the one before it is at most 1e-3 long: that
// one vanishing brings the start onto the guard (a flight starting on the impact surface as the
// contact phase before it, 6.7e-5 long, shrinks away at a double grazing). -1: none of these. A
// solution is kept only within the bracket (CurveEnds::AcceptEnd), so a wrong guess costs a Newton
// run.
int VanishingSegment(const Admissibility& v, const PeriodicOrbit& o) {
  const std::vector<SegmentSpec>& segs = o.signature.segments;
  const int i = v.segment;
  const int k = static_cast<int>(segs.size());
  if (v.guard < 0) return i;
  if (v.guard == segs[i].guard && std::abs(o.durations[i]) <= (v.at_start ? 1e-3 : 1e-5)) {
    return i;
  }
  if (i >= 2 && v.at_start && segs[i - 2].mode == segs[i].mode && v.guard == segs[i - 2].guard) {
    return i - 1;
  }
  if (!v.at_start && v.guard == segs[i].guard && i + 2 < k && segs[i + 2].mode == segs[i].mode &&
      o.durations[i + 1] <= 1e-2) {
    return i + 1;
  }
  if (i >= 1 && v.at_start && std::abs(o.durations[i - 1]) <= 1e-3) return i - 1;
  return -1;
}

}  // namespace

// A known end (SetKnownEnd) inside the bracket: trial points next to it first. Each is a trial
// like any midpoint, so the bracket holds whatever they give; where the boundary is next to the
// known point the bracket is then closed, or a few halvings from closing, instead of ~17
// halvings of the whole step. A root stepped off, where the bracket's violation is that root's
// segment vanishing: before it a quarter of the tolerance, 8, 64, ... times that while they are
// beyond (at most kKnownEndTrials), then a quarter of the tolerance after it. A curve's own
// start, where its first step corrected beyond it: a quarter of the tolerance after it, kept
// only where that point violates what the step did (else the bracket is left as it was).
// Measured in the reference box's trace (`trace_network 1`): of the 335 curves stepped off a
// root, 329 had an end so bracketed, the boundary within a quarter tolerance of the root at 164,
// within 2, 16 and 128 before it at 51, 64 and 47 (the root is known to the accuracy it was
// located to on the curve it came from), farther before it at 1 and after it at 2; of the 369
// curves started at their point, 449 ends were bracketed from the start, 441 closed by the trial
// after it, 2 where that trial violated another guard (left to the bisection) and 6 where it was
// admissible.
void CurveEnds::TryKnownEnd(const Vec& t, double tol, Boundary* b,
                            const std::function<void(const Vec&)>& trial) const {
  if (!known_end_ || known_end_->size() != t.size()) return;
  const bool at_start = known_vanishing_ < 0;
  if (at_start ? b->ya != *known_end_ || b->from_prediction
               : b->violation.guard >= 0 || b->violation.segment != known_vanishing_) {
    return;
  }
  auto inside = [&](double offset) {
    const double along = t.dot(*known_end_ + offset * t - b->ya);
    return t.dot(b->yb - b->ya) > tol && along > 0.0 && along < t.dot(b->yb - b->ya);
  };
  const double quarter = 0.25 * tol;
  if (!inside(quarter) || system_.Stopped()) return;
  if (at_start) {
    const Boundary seen = *b;
    trial(*known_end_ + quarter * t);
    if (!SameViolation(b->violation, seen.violation)) *b = seen;
    return;
  }
  // Before the root first: Newton converges on that side, where beyond it, next to the
  // vanishing segment's singular saltation, it can fail after every iteration.
  double back = quarter;
  for (int k = 0; k < kKnownEndTrials && inside(-back) && !system_.Stopped(); ++k, back *= 8.0) {
    const Vec before = b->ya;
    trial(*known_end_ - back * t);
    if (b->ya != before) break;  // admissible: the boundary is bracketed next to the root
  }
  if (inside(quarter) && !system_.Stopped()) trial(*known_end_ + quarter * t);
}

// A solved end is kept when within the bracket of the end (beyond it, within what the curve
// moves until the vanishing segment `vanishing`, if any, is gone: ReachToVanishing), admissible
// (for a zero-length segment: but for that segment's own duration, zero to rounding; a touch at the
// start of segment `touch_start` where TouchesAtStart) and, on a fold / PD curve, with the
// multiplier +1 / -1 among the eigenvalues to 1e-8 (independent of sigma and its borders: where a
// zero-length segment's saltation degenerates, sigma = 0 was met without it).
// *point receives the accepted end (its stability is the one checked; `stability` given: that
// one).
bool CurveEnds::AcceptEnd(const Codim2Point& end, const StatusOr<PeriodicOrbit>& solved,
                          int vanishing, int zero_length, int touch_start,
                          const Stability* stability, CurvePoint* point) const {
  if (!solved.ok()) return false;
  const double moved = std::hypot(solved->params[system_.index1()] - end.point.value1,
                                  solved->params[system_.index2()] - end.point.value2);
  double window = 2.0 * end.bracket + 1e-9;
  if (moved > window && vanishing >= 0) {
    window += 2.0 * ReachToVanishing(end.point.orbit, vanishing);
  }
  if (moved > window) return false;
  for (const Admissibility& w :
       AdmissibilityViolations(system_.model(), system_.propagator(), *solved)) {
    if (w.segment == touch_start && w.at_start &&
        TouchesAtStart(system_.model(), *solved, w.segment, w.guard)) {
      continue;
    }
    if (w.segment != zero_length || w.guard >= 0) return false;
  }
  *point = system_.PointFromOrbit(*solved, stability);
  return OnCondition(*point);
}

// How far the curve's parameters move from orbit o (a curve point) while segment j's duration d
// goes to zero, to first order: d |dlambda / ds| / |dtau_j / ds| from the curve's tangent at o. The
// bisection brackets where the orbit stops being admissible, and where the vanishing segment's
// own guard fires at its start by rounding while it is still d long, that is not yet where it
// vanishes (in the reference box with longer steps a fold curve's end bracketed to 1.2e-11 with
// its contact phase 3.2e-6 long, the tangent-form end 2.05e-7 further in omega): the solved end
// may lie that much beyond the bracket. 0 where d <= 0 or the tangent is not found.
double CurveEnds::ReachToVanishing(const PeriodicOrbit& o, int j) const {
  const double d = o.durations[j];
  if (!(d > 0.0)) return 0.0;
  const Vec y = system_.Pack(o);
  Vec t;
  const int m = system_.m();
  if (!system_.Tangent(y, Vec::Unit(y.size(), m), &t)) return 0.0;
  const double rate = std::abs(t[system_.bvp().DurationIndex(j)]);
  return rate > 0.0 ? d * std::hypot(t[m], t[m + 1]) / rate : 0.0;
}

// The end solved in tangent form (grazing_end.h): where the violation beyond it is a segment
// vanishing between two segments of one mode (TangentForm; seen in the ways VanishingSegment
// lists), or a guard touching zero inside a segment (TouchForm at that segment and guard; at the
// admissible end the touch is within the bracket of zero). Kept when the solution lies within
// the bisection's bracket of the end (else
// it is another root: where the vanishing segment's events leave the monodromy discontinuous,
// the tangent form's fold or PD condition is not the curve's) and is admissible; the end is then
// that point, in tangent form, with bracket 0. Failing that: held at zero length (events of two
// surfaces), and on a grazing curve the touch merged into the event next to it
// (SolveMergedTouchEnd; admissible but for the next mode's guard touching zero to third order
// at its start, which rounding may show as firing there). Last, where none of these solves (a
// contact phase vanishing between two flights: the zero-length system is singular, the
// tangent form's root another point), the limit of the curve's points as the segment's length
// goes to zero (ExtrapolateZeroLength), kept under the same checks (the flight after the
// zero-length segment starts on the impact surface at zero speed, its guard touching zero
// there to third order, as above) and when its estimated error is below the bisection's
// bracket; that error is then the end's bracket.
bool CurveEnds::SolveEnd(Codim2Point* end) const {
  const Admissibility& v = end->violation;
  const std::vector<SegmentSpec>& segs = end->point.orbit.signature.segments;
  const int i = v.segment;
  if (v.admissible || i < 0 || i >= static_cast<int>(segs.size())) return false;
  const PeriodicOrbit& o = end->point.orbit;
  const int k = static_cast<int>(segs.size());
  const int j = VanishingSegment(v, o);
  const HybridModel& model = system_.model();
  Propagator& propagator = system_.propagator();
  const CurveKind kind = system_.kind();
  const int index1 = system_.index1(), index2 = system_.index2();
  CurvePoint point;
  auto accept = [&](const StatusOr<PeriodicOrbit>& solved, int zero_length, int touch_start = -1,
                    const Stability* stability = nullptr) {
    return AcceptEnd(*end, solved, j, zero_length, touch_start, stability, &point);
  };
  const bool same_mode = j > 0 && j + 1 < k && segs[j - 1].mode == segs[j + 1].mode;
  StatusOr<PeriodicOrbit> solved = Status(StatusCode::kUnimplemented, "");
  std::string how = " (solved in tangent form)";
  if (same_mode) {
    const StatusOr<PeriodicOrbit> form = TangentForm(o, j);
    if (form.ok()) solved = SolveGrazingEnd(model, propagator, *form, kind, index1, index2);
  } else if (j < 0 && v.guard >= 0) {
    const StatusOr<PeriodicOrbit> form = TouchForm(model, propagator, o, 1e-6, i, v.guard);
    if (form.ok()) solved = SolveGrazingEnd(model, propagator, *form, kind, index1, index2);
  }
  bool ok = accept(solved, -1);
  // Held at zero length only where the two events are of different surfaces (the same surface
  // twice, as l1 into and out of progression, is the degenerate case of tangent_grazing.h).
  if (!ok && EventsOfTwoSurfaces(model, o.signature, j)) {
    solved = SolveZeroLengthEnd(model, propagator, o, j, kind, index1, index2);
    how = " (solved with segment " + std::to_string(j) + " of zero length)";
    ok = accept(solved, j);
  }
  if (!ok && kind == CurveKind::kGrazing) {
    solved = SolveMergedTouchEnd(model, propagator, o, j, index1, index2);
    how = " (solved with the touch merged into the event next to it)";
    ok = accept(solved, -1, j);
  }
  double error = 0.0;
  if (!ok && j >= 0) {
    const StatusOr<ExtrapolatedEnd> limit =
        ExtrapolateZeroLength(model, propagator, o, j, kind, index1, index2);
    if (limit.ok() && limit->error < end->bracket) {
      ok = accept(limit->orbit, j, j + 1, &limit->stability);
      error = limit->error;
      how = " (extrapolated to segment " + std::to_string(j) + " of zero length)";
    }
  }
  if (!ok) return false;
  end->point = std::move(point);
  end->bracket = error;
  end->detail += how;
  return true;
}

void CurveEnds::EndOnBox(const Vec& y, const Vec& y1, std::vector<CurvePoint>* points) const {
  const int m = system_.m();
  const CurveOptions& options = system_.options();
  double first = 2.0, bound = 0.0;
  int index = -1;
  for (const int j : {m, m + 1}) {
    const double lo = j == m ? options.min1 : options.min2;
    const double hi = j == m ? options.max1 : options.max2;
    for (const double c : {lo, hi}) {
      if (!std::isfinite(c) || (y1[j] - c) * (y[j] - c) >= 0.0) continue;
      const double w = (c - y[j]) / (y1[j] - y[j]);
      if (w < first) first = w, bound = c, index = j;
    }
  }
  if (index < 0) return;
  Vec guess = y + first * (y1 - y), fixed = Vec::Zero(system_.n()), yc;
  guess[index] = bound;
  fixed[index] = 1.0;
  int iterations = 0;
  if (!system_.Correct(guess, fixed, &yc, &iterations)) return;
  yc[index] = bound;  // exactly: the corrector keeps it to rounding
  CurvePoint p = system_.MakePoint(yc);
  std::string why;
  if (yc[m] >= options.min1 && yc[m] <= options.max1 && yc[m + 1] >= options.min2 &&
      yc[m + 1] <= options.max2 && system_.Admissible(p.orbit, &why) && !system_.Stopped()) {
    points->push_back(std::move(p));
  }
}

void CurveEnds::CrossingsOnStep(const Vec& y, const Vec& y1,
                                std::vector<CurvePoint>* crossings) const {
  const int m = system_.m();
  for (const int j : {m, m + 1}) {
    for (double c : j == m ? system_.options().crossings1 : system_.options().crossings2) {
      if ((y[j] - c) * (y1[j] - c) > 0.0 || y[j] == y1[j]) continue;
      const double w = (c - y[j]) / (y1[j] - y[j]);
      Vec guess = y + w * (y1 - y), fixed = Vec::Zero(system_.n()), yc;
      guess[j] = c;
      fixed[j] = 1.0;
      int it = 0;
      if (!system_.Correct(guess, fixed, &yc, &it)) continue;
      CurvePoint point = system_.MakePoint(yc);
      if (!system_.Stopped()) crossings->push_back(std::move(point));
    }
  }
}

// Whether a fold / PD curve's point has its multiplier +1 / -1 to 1e-8 (always true on other
// curves).
bool CurveEnds::OnCondition(const CurvePoint& point) const {
  const CurveKind kind = system_.kind();
  if (kind != CurveKind::kFold && kind != CurveKind::kPeriodDoubling) return true;
  const double target = kind == CurveKind::kFold ? 1.0 : -1.0;
  const std::vector<std::complex<double>>& mu = point.stability.multipliers;
  return std::any_of(mu.begin(), mu.end(),
                     [&](const std::complex<double>& z) { return std::abs(z - target) <= 1e-8; });
}

// The bisection corrects without settling the condition (CurveSystem::Correct: its points only
// bracket the end), so the last admissible point, kept as the curve's last vertex, can have its
// multiplier farther off +-1 than a step's vertex (2.2e-8 at a fold curve's end in the reference
// box, next to a segment 1.0e-3 long). Where it is more than 1e-8 off, the vertex is that point
// corrected again with the condition settled, if that is admissible; the end itself (its bracket
// and solution) stays as bisected.
CurvePoint CurveEnds::SettledVertex(const Vec& ya, const Vec& t, CurvePoint end) const {
  if (OnCondition(end)) return end;
  Vec settled;
  int iterations = 0;
  std::string why;
  if (!system_.Correct(ya, t, &settled, &iterations) ||
      !system_.Admissible(system_.Unpack(settled), &why)) {
    return end;
  }
  CurvePoint point = system_.MakePoint(settled);
  return system_.Stopped() ? end : point;
}

// A cusp on the step from y (tangent t) to the end ya: a fold curve approaching a fold-grazing
// nearly at rest in the parameter plane (its orbit changing while the parameters barely move)
// can turn just before its end. The direction at the end itself is not to be trusted (below),
// and next to it Newton may fail (the fixed-signature system meets its zero-length solutions
// there), so the step is probed at 7 inner points closing in on the end and the cusp located
// before the first one past a reversal, until the sign change is bracketed to rounding (psi is
// 1e-13 .. 1e-9 there). In the reference box this found 2 more cusps with the default steps
// (4e-9 and 5e-9, box-scaled, before their curve's end, where psi was 4e-13 of the wrong sign)
// and 3 more with target_iterations 4 (where the search's trial points next to the end did not
// correct): 21 -> 23 and 20 -> 23 cusps, the same 23 (evenly spaced probes found 22 with the
// longer steps: their hooks are shorter than an eighth of the step).
void CurveEnds::CuspBeforeEnd(const Vec& y, const Vec& t, const Vec& ya,
                              std::vector<Codim2Point>* codim2) const {
  Vec ta;
  if (system_.kind() != CurveKind::kFold || !system_.Tangent(ya, t, &ta)) return;
  const size_t found = codim2->size();
  codim2_.CuspOnStep(y, t, ya, ta, codim2, 0.0, 7);
  // Not the end's own: there the fixed-signature curve meets the family of zero-length
  // solutions and its parameters are stationary (they move as the square of the vanishing
  // duration), so the direction's sign at ya is noise and a reversal is "located" at the
  // end itself (five of the box's ends, within 1e-10 of it; the cusp this check adds in the
  // box lies 1e-8 before its end, with the direction resolved on both sides: |u| 1.8e-6 at
  // the step's start, 3.3e-7 at its end).
  const int m = system_.m();
  if (codim2->size() > found &&
      std::hypot((codim2->back().point.value1 - ya[m]) / system_.w1(),
                 (codim2->back().point.value2 - ya[m + 1]) / system_.w2()) <= 1e-9) {
    codim2->pop_back();
  }
}

std::string CurveEnds::EndAtBoundary(const Vec& y, const Vec& t, const Vec& yb,
                                     const std::string& why, const Admissibility& violation,
                                     const std::vector<Codim2TestFunction>& tests,
                                     std::vector<double>* dets, const CurveOutputs& out,
                                     bool from_prediction) const {
  // A curve ends where its orbit grazes (a segment vanishes or a guard is touched inside
  // one): on a fold or PD curve a fold- or flip-grazing, on a grazing curve a double
  // grazing (a second boundary touched at once).
  // Bisected first to 1e-8 (relative): where the end is then solved in tangent form (and no
  // test function changes sign between the bisected and the solved end) that is all it
  // needs; else (and where the violation may be a section crossing, told apart by a
  // first segment of zero length to rounding) on to 1e-12.
  Boundary b{y, yb, yb, why, violation, !from_prediction, from_prediction};
  Bisect(t, 1e-8, &b);
  if (MayBeSectionCrossing(b.violation)) Bisect(t, 1e-12, &b);
  const CurveKind kind = system_.kind();
  const Codim2Kind k = kind == CurveKind::kFold            ? Codim2Kind::kFoldGrazing
                       : kind == CurveKind::kGrazing       ? Codim2Kind::kDoubleGrazing
                       : kind == CurveKind::kNeimarkSacker ? Codim2Kind::kNsGrazing
                                                           : Codim2Kind::kFlipGrazing;
  CurvePoint end = system_.MakePoint(b.ya);
  Codim2Point point{k, end, b.why, b.Width(t), b.violation};
  const bool crossing_first = IsSectionCrossing(b.violation, end.orbit);
  bool solved =
      !crossing_first && SolveEnd(&point) &&
      CurveCodim2::SameSigns(tests, end.stability.monodromy, point.point.stability.monodromy);
  if (!crossing_first && !solved) {
    Bisect(t, 1e-12, &b);
    end = system_.MakePoint(b.ya);
    point = {k, end, b.why, b.Width(t), b.violation};
    solved = SolveEnd(&point);
  }
  // Roots of the test functions between the last point and the boundary (a fold- or
  // flip-grazing root can lie next to a double grazing end), and requested values crossed
  // there (at a section crossing the curve goes on from b.ya in the rotated signature: a
  // crossing of omega = 0.065 by a PD curve of the reference box, within such a step, was lost).
  codim2_.RootsOnStep(y, t, b.ya, end.stability.monodromy, tests, dets, out.codim2);
  CrossingsOnStep(y, b.ya, out.crossings);
  // And a cusp just before the end.
  CuspBeforeEnd(y, t, b.ya, out.codim2);
  if (system_.Stopped()) return kCancelledEnd;  // nothing computed after a stop is kept
  if (IsSectionCrossing(b.violation, end.orbit)) {
    SectionCrossing* crossing = out.crossing;
    crossing->happened = true;
    crossing->orbit = end.orbit;
    crossing->violation = b.violation;
    // As the vanishing of that segment (SwitchSignature); seen as a guard firing, the first
    // segment, which ends on it.
    if (b.violation.guard >= 0) crossing->violation.segment = 0;
    crossing->violation.guard = -1;
    crossing->direction = system_.ParamDirection(t).normalized();
    crossing->end = point;
    crossing->unverified = !b.beyond_corrected;
    out.points->push_back(SettledVertex(b.ya, t, end));
    return "crossed the Poincare section";
  }
  // Bracketed only by a prediction and not solved: no orbit beyond the last point is known to
  // violate anything. A prediction off the curve is not admissible for reasons of its own: next
  // to a slow lift-off (the contact force's rate ~2e-3) the guard row's residual at a prediction
  // (~2e-7) moves that event ~1e-4 earlier, which reads as the guard crossed inside the segment
  // (period-2 curves next to a = 0.689, omega = 0.1, in the box omega [0.09, 0.11],
  // a [0.25, 0.75]: such ends were reported as codimension-2 points with brackets up to 345;
  // and section crossings only a prediction brackets are taken up as any other, but where the
  // rotated signature does not correct they are unverified ends too (ContinueCurve): the last
  // flight vanishing in a prediction ~65 ahead while it was 24 long at the last point, 8 ends
  // with brackets of ~100. Of the box's 64 entries bracketed above 1e-8, 4 are left).
  // The direction ends there, and the codimension-2 point it may be heading for is not claimed:
  // kept apart (CurveResult::unverified_ends), for switching to try the curves that may leave
  // it.
  if (!b.beyond_corrected && !solved) {
    out.unverified->push_back(point);
    return UnverifiedEndText(system_.options(), point, b.why);
  }
  // The last admissible point is the curve's last vertex, so that its polyline reaches the end
  // (to the bisection's bracket) rather than stopping a step short of it: a region's polygons
  // follow the polylines (with the default longer steps the reference box's region had 11 more
  // boundary edges that no traced curve crossed, next to curve ends).
  out.points->push_back(SettledVertex(b.ya, t, std::move(end)));
  out.codim2->push_back(point);
  return std::string("ended at a ") + Codim2KindName(k) + " point: " + point.detail;
}

}  // namespace drillbif::internal
