// Two-parameter curve continuation (see continuation/curve.h).
#include "drillbif/continuation/curve.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/phase_progress.h"
#include "continuation/arclength.h"
#include "continuation/curve_codim2.h"
#include "continuation/curve_ends.h"
#include "continuation/curve_system.h"
#include "continuation/signature_switch.h"
#include "continuation/tangent_grazing.h"

namespace drillbif {

const char* CurveKindName(CurveKind kind) {
  switch (kind) {
    case CurveKind::kFold:
      return "FOLD";
    case CurveKind::kPeriodDoubling:
      return "PERIOD_DOUBLING";
    case CurveKind::kGrazing:
      return "GRAZING";
    case CurveKind::kNeimarkSacker:
      return "NEIMARK_SACKER";
  }
  return "?";
}

const char* Codim2KindName(Codim2Kind kind) {
  switch (kind) {
    case Codim2Kind::kFoldGrazing:
      return "FOLD_GRAZING";
    case Codim2Kind::kFlipGrazing:
      return "FLIP_GRAZING";
    case Codim2Kind::kFoldFlip:
      return "FOLD_FLIP";
    case Codim2Kind::kDoubleGrazing:
      return "DOUBLE_GRAZING";
    case Codim2Kind::kNsGrazing:
      return "NS_GRAZING";
    case Codim2Kind::kResonance11:
      return "RESONANCE_1_1";
    case Codim2Kind::kResonance12:
      return "RESONANCE_1_2";
    case Codim2Kind::kResonance13:
      return "RESONANCE_1_3";
    case Codim2Kind::kResonance14:
      return "RESONANCE_1_4";
    case Codim2Kind::kCusp:
      return "CUSP";
  }
  return "?";
}

Status CurveOptions::Validate() const {
  if (param1.empty() || param2.empty() || param1 == param2) {
    return InvalidArgument("param1 and param2 must name two different parameters");
  }
  if (std::isnan(min1) || std::isnan(max1) || !(max1 > min1) || std::isnan(min2) ||
      std::isnan(max2) || !(max2 > min2)) {
    return InvalidArgument("the box is empty: need min1 < max1 and min2 < max2");
  }
  return steps.Validate();
}

namespace {

// How far a curve's polyline may stray from the curve in the parameter plane (box-scaled): the
// distance within which a start or a switch is taken to lie on a traced curve
// (TraceOptions::duplicate_distance's default).
constexpr double kMaxSagitta = 1e-5;

using Vec = Eigen::VectorXd;
using Mat = Eigen::MatrixXd;
using internal::CurveOutputs;
using internal::SectionCrossing;

// Whether the step from y (unit tangent t) of arclength h to y1 (unit tangent t1) continues the
// curve through y. Along a smooth curve y(s) = y + s t + s^2 / 2 kappa n + O(s^3) and
// t(s) = t + s kappa n + O(s^2), so the corrected point's offset from the prediction,
// y1 - (y + h t), equals h / 2 (t1 - t) up to O(h^3) terms: the tangents at both ends account for
// it. A point on another branch of solutions nearby (a curve of the same condition and signature
// next to this one) has a tangent that does not: in the reference (omega, a) box, with
// target_iterations 4, two steps of 0.5 from a PD curve's hairpin (at omega = 0.1922) landed on
// another PD curve 1.7e-4 away in omega (their orbits' segments 0.1 .. 0.4 apart), each within
// kMaxDrift, residuals 0.13 h and 0.21 h, and the two curves were traced as two others, each
// joining an end of one to an end of the other. The step is refused above 0.1 h (0.4% of the
// steps of that box with target_iterations 4, 456 of 20262 above 0.05 h; a refused step is
// retried at half the length, where a smooth curve's residual is an eighth). Steps no longer
// than the first are not checked: a jump needs a step that reaches the other curve, and a curve
// stepped off a codimension-2 root starts where its orbit changes like the square root of the
// arclength (the O(h^3) terms are not small there): refused and halved, the first steps of the
// fold curve stepped off (0.050365, 0.16908) stayed where its 1e-6 long progression phase ends
// at once by rounding, and that curve was lost.
constexpr double kMaxTangentMismatch = 0.1;

bool StepConsistent(const Vec& y, const Vec& t, double h, const Vec& y1, const Vec& t1) {
  return (y1 - (y + h * t) - 0.5 * h * (t1 - t)).norm() <= kMaxTangentMismatch * h;
}

// Traces a curve from its start: the stepping loop over the curve's system (curve_system.h),
// its codimension-2 points (curve_codim2.h) and its ends (curve_ends.h), in one signature.
class CurveTracer {
 public:
  CurveTracer(const HybridModel& model, Propagator& propagator, const CurveOptions& options,
              CurveKind kind, int index1, int index2, const PeriodicOrbit& start)
      : system_(model, propagator, options, kind, index1, index2, start),
        codim2_(system_),
        ends_(system_, codim2_),
        start_(system_.Pack(start)) {}
  // Its pieces refer to each other: not copied or moved.
  CurveTracer(const CurveTracer&) = delete;
  CurveTracer& operator=(const CurveTracer&) = delete;

  // Puts the start exactly on the curve: Newton on the extended system with lambda2 fixed (the
  // located point satisfies the defining condition only to the location's accuracy, and a grazing
  // point re-expressed with a tangent end is slightly off the touch). Where the curve's tangent
  // has next to no parameter part (a fold curve at a fold-grazing, its parameters moving as the
  // square of the vanishing duration), holding either parameter leaves Newton's matrix singular
  // (condition ~1e14 measured, steps ~1e-8 that never settle): corrected then across the curve,
  // orthogonal to its tangent there.
  bool CorrectStart() {
    const int n = system_.n();
    Vec fixed = Vec::Zero(n), y;
    fixed[system_.m() + 1] = 1.0;
    int iterations = 0;
    if (!system_.Correct(start_, fixed, &y, &iterations)) {
      Vec f;
      Mat jac;
      if (!system_.Evaluate(start_, &f, &jac)) return false;
      // The null vector of the (n - 1) x n Jacobian: the last column of Q in jac^T = Q R.
      const Mat q = Eigen::HouseholderQR<Mat>(jac.transpose()).householderQ();
      if (!system_.Correct(start_, q.col(n - 1), &y, &iterations)) return false;
    }
    start_ = y;
    return true;
  }

  // The codimension-2 point `root` the curve was stepped off (its segment `vanishing` of zero
  // length) or, `vanishing` -1, started at (after CorrectStart: its corrected start) as a known
  // end (CurveEnds::SetKnownEnd).
  void SetKnownEnd(const PeriodicOrbit& root, int vanishing) {
    ends_.SetKnownEnd(vanishing < 0 ? start_ : system_.Pack(root), vanishing);
  }

  // The start (on the curve after CorrectStart).
  const Vec& start() const { return start_; }
  // The curve point of y.
  CurvePoint MakePoint(const Vec& y) const { return system_.MakePoint(y); }
  // Distance of two curve points' parameters, scaled by the box's widths.
  double BoxDistance(const CurvePoint& a, const CurvePoint& b) const {
    return system_.BoxDistance(a, b);
  }

  // Traces one direction from the start, leaving it along the parameter direction `dir`
  // (box-scaled; (0, +-1): across the one-parameter branch the start was located on); returns
  // why it ended. At a Poincare-section crossing (an event reaching s = 0: the first or last
  // segment vanishes) the orbit goes on and only its representation changes: the last point is
  // appended, *out.crossing filled, and ContinueCurve goes on in the rotated signature.
  std::string Trace(const Eigen::Vector2d& dir, const CurveOutputs& out,
                    ContinuationSummary* sum) const;

 private:
  // Where the steps from y (tangent t) fail or collapse next to a boundary: a prediction beyond
  // it (the first step tried from y, h_first, or 1.5 times the step at which the tangent says the
  // first shrinking segment vanishes), when not admissible, brackets that boundary with y: the
  // end there (CurveEnds::EndAtBoundary). `failed`: what happened, e.g. "the corrector failed";
  // the returned reason begins with it. None where both predictions are admissible.
  // Vertices within the step from y (tangent t) to y1 (t1) of arclength h, appended to *points,
  // where the step's chord strays from the curve (kMaxSagitta).
  void InsertVertices(const Vec& y, const Vec& t, const Vec& y1, const Vec& t1, double h,
                      std::vector<CurvePoint>* points) const;
  std::optional<std::string> EndAhead(const std::string& failed, const Vec& y, const Vec& t,
                                      double h_first,
                                      const std::vector<internal::Codim2TestFunction>& tests,
                                      std::vector<double>* dets, const CurveOutputs& out) const;

  internal::CurveSystem system_;
  internal::CurveCodim2 codim2_;
  internal::CurveEnds ends_;
  Vec start_;
};

// The curve is drawn by its vertices' polyline (a region's polygons, the duplicate checks). Where
// a step's chord strays from the curve by more than kMaxSagitta in the parameter plane, vertices
// are inserted within the step, evenly in arclength (the sagitta goes as the square of the
// chord), each corrected from the cubic through the step's ends and tangents. The step sequence
// is left as it is, so that what the trace finds does not depend on it; an inserted vertex whose
// correction fails, lands off its prediction or is not admissible is left out.
void CurveTracer::InsertVertices(const Vec& y, const Vec& t, const Vec& y1, const Vec& t1, double h,
                                 std::vector<CurvePoint>* points) const {
  const double sagitta = system_.ChordSagitta(y, t, y1, t1, h);
  if (!(sagitta > kMaxSagitta)) return;
  const int pieces = static_cast<int>(std::min(16.0, std::ceil(std::sqrt(sagitta / kMaxSagitta))));
  for (int k = 1; k < pieces && !system_.Stopped(); ++k) {
    const double s = static_cast<double>(k) / pieces;
    // The cubic Hermite basis at s and its derivatives.
    const double h00 = (1.0 + 2.0 * s) * (1.0 - s) * (1.0 - s), h10 = s * (1.0 - s) * (1.0 - s);
    const double h01 = s * s * (3.0 - 2.0 * s), h11 = s * s * (s - 1.0);
    const double d00 = 6.0 * s * s - 6.0 * s, d10 = 3.0 * s * s - 4.0 * s + 1.0;
    const double d11 = 3.0 * s * s - 2.0 * s;
    const Vec guess = h00 * y + h10 * h * t + h01 * y1 + h11 * h * t1;
    const Vec dir = (d00 * (y - y1) + d10 * h * t + d11 * h * t1).normalized();
    Vec yk;
    int iterations = 0;
    if (!system_.Correct(guess, dir, &yk, &iterations) ||
        (yk - guess).norm() > internal::CurveEnds::kMaxDrift * h / pieces) {
      continue;
    }
    CurvePoint q = system_.MakePoint(yk);
    std::string why;
    if (!system_.Admissible(q.orbit, &why)) continue;
    points->push_back(std::move(q));
  }
}

std::optional<std::string> CurveTracer::EndAhead(
    const std::string& failed, const Vec& y, const Vec& t, double h_first,
    const std::vector<internal::Codim2TestFunction>& tests, std::vector<double>* dets,
    const CurveOutputs& out) const {
  const internal::OrbitBvp& bvp = system_.bvp();
  double vanish = std::numeric_limits<double>::infinity();
  for (int i = 0; i < bvp.segments(); ++i) {
    const double tau = y[bvp.DurationIndex(i)], rate = t[bvp.DurationIndex(i)];
    if (rate < 0.0) vanish = std::min(vanish, -tau / rate);
  }
  for (const double ahead_by : {h_first, 1.5 * vanish}) {
    if (!std::isfinite(ahead_by)) continue;
    const Vec ahead = y + ahead_by * t;
    std::string why;
    Admissibility violation;
    if (!system_.Admissible(system_.Unpack(ahead), &why, &violation)) {
      const size_t before = out.unverified->size();
      const std::string end =
          ends_.EndAtBoundary(y, t, ahead, why, violation, tests, dets, out, true);
      return failed + (out.unverified->size() == before ? " short of a boundary, " : " ") + end;
    }
  }
  return std::nullopt;
}

std::string CurveTracer::Trace(const Eigen::Vector2d& dir, const CurveOutputs& out,
                               ContinuationSummary* sum) const {
  const CurveOptions& options = system_.options();
  const int m = system_.m();
  Vec y = start_, t, prev = Vec::Zero(system_.n());
  system_.SetBorders(
      OrbitStability(system_.model(), system_.propagator(), system_.Unpack(y)).monodromy);
  prev[m] = dir[0] * system_.w1();
  prev[m + 1] = dir[1] * system_.w2();
  if (!system_.Tangent(y, prev, &t)) return "no tangent at the start point";
  double h = options.steps.initial_step;
  const auto tests = codim2_.Tests();
  std::vector<double> dets;
  for (const internal::Codim2TestFunction& test : tests) dets.push_back(codim2_.TestValue(test, y));
  // Stall watch: parameters (scaled by the box where it is finite) 50 accepted steps back.
  constexpr int kStallWindow = 50;
  std::vector<Eigen::Vector2d> recent;
  double h_first = h;  // the first step tried from y
  for (int step = 0; step < options.steps.max_steps; ++step) {
    if (system_.Stopped()) return internal::CurveEnds::kCancelledEnd;
    Vec y1;
    int iterations = 0;
    Vec t1;
    // A step is refused (and retried shorter, as when Newton fails) when the corrected point
    // drifted (CurveEnds::kMaxDrift) or, for a step longer than the first, does not continue
    // the curve it came from (StepConsistent).
    if (!system_.Correct(y + h * t, t, &y1, &iterations, &t1) ||
        (y1 - (y + h * t)).norm() > internal::CurveEnds::kMaxDrift * h ||
        (h > options.steps.initial_step && !StepConsistent(y, t, h, y1, t1))) {
      ++sum->rejected_steps;
      h *= 0.5;
      if (system_.Stopped()) return internal::CurveEnds::kCancelledEnd;
      if (h < options.steps.min_step) {
        // Newton failed on every step from y down to min_step: next to a boundary where the
        // curve's own system degenerates (a segment vanishing like a square root) no
        // prediction beyond it corrects.
        if (std::optional<std::string> end =
                EndAhead("the corrector failed", y, t, h_first, tests, &dets, out)) {
          return *end;
        }
        return "the corrector failed down to min_step";
      }
      --step;
      continue;
    }
    sum->newton_iterations += iterations;
    const double taken = h;  // this step's arclength (h becomes the next one's below)
    const double v1 = y1[m], v2 = y1[m + 1];
    if (v1 < options.min1 || v1 > options.max1 || v2 < options.min2 || v2 > options.max2) {
      // A curve that leaves the box ends on it exactly (the trace's edge rounds start from such
      // ends, and a start located on the edge is known by them): the point where the step
      // crosses the edge, solved with that parameter fixed from the chord's interpolation. A
      // long step's chord can put that guess too far off the curve for the corrector (with
      // target_iterations 4 a PD curve ended 5.9e-5 of the box short of the edge, and the
      // edge's branch traced it again from its point there): the step is retried shorter.
      const size_t before = out.points->size();
      ends_.EndOnBox(y, y1, out.points);
      if (system_.Stopped()) return internal::CurveEnds::kCancelledEnd;
      if (out.points->size() == before && 0.5 * h >= options.steps.min_step) {
        ++sum->rejected_steps;
        h *= 0.5;
        --step;
        continue;
      }
      ++sum->steps;
      return "left the box";
    }
    ++sum->steps;
    h = std::clamp(h * internal::StepFactor(iterations, options.steps.target_iterations),
                   options.steps.min_step, options.steps.max_step);
    // A curve that creeps (the step collapsed while Newton still converges, as next to a
    // fold-grazing where a segment's duration goes to zero like a square root) is ended rather
    // than left to spend max_steps: at the boundary ahead where there is one (three PD curves
    // stepped off flip-grazings in the reference box crept, their parameters moving ~1e-9 per
    // step, towards a progression phase between two contact phases vanishing 4e-4 ahead), else as
    // stalled.
    recent.emplace_back(v1 / system_.w1(), v2 / system_.w2());
    if (static_cast<int>(recent.size()) > kStallWindow) {
      const double moved = (recent.back() - recent.front()).norm();
      recent.erase(recent.begin());
      if (moved < 1e-6) {
        if (std::optional<std::string> end =
                EndAhead("the steps collapsed", y, t, h_first, tests, &dets, out)) {
          return *end;
        }
        char where[160];
        std::snprintf(where, sizeof where,
                      "stalled: the parameters moved %.1e (of the box) in %d steps, near "
                      "(%.9g, %.9g)",
                      moved, kStallWindow, v1, v2);
        return where;
      }
    }
    CurvePoint p = system_.MakePoint(y1);
    std::string why;
    Admissibility violation;
    const bool admissible = system_.Admissible(p.orbit, &why, &violation);
    if (system_.Stopped()) return internal::CurveEnds::kCancelledEnd;
    if (!admissible) {
      // A curve ends where its orbit grazes (a segment vanishes or a guard is touched inside
      // one): on a fold or PD curve a fold- or flip-grazing, on a grazing curve a double
      // grazing (a second boundary touched at once).
      return ends_.EndAtBoundary(y, t, y1, why, violation, tests, &dets, out, false);
    }
    ends_.CrossingsOnStep(y, y1, out.crossings);
    codim2_.RootsOnStep(y, t, y1, p.stability.monodromy, tests, &dets, out.codim2);
    InsertVertices(y, t, y1, t1, taken, out.points);
    system_.SetBorders(p.stability.monodromy);
    out.points->push_back(std::move(p));
    codim2_.CuspOnStep(y, t, y1, t1, out.codim2);
    y = y1;
    t = t1;
    h_first = h;
  }
  return "reached max_steps";
}

CurveResult TraceCurve(const HybridModel& model, Propagator& propagator, const SpecialPoint& start,
                       const PeriodicOrbit* root, int vanishing, const CurveOptions& options,
                       const ProgressCallback& progress) {
  CurveResult result;
  ContinuationSummary& sum = result.summary;
  internal::PhaseProgress phase(propagator, progress);
  auto cancelled = [&] {
    sum.termination = Termination::kCancelled;
    sum.status = Cancelled("curve cancelled");
    sum.message = sum.message.empty() ? "cancelled" : sum.message;
    return result;
  };
  auto fail = [&](Status s) {
    sum.termination = Termination::kFailed;
    sum.status = s;
    sum.message = s.message();
    return result;
  };
  if (Status s = options.Validate(); !s.ok()) return fail(s);
  StatusOr<int> i1 = model.ParamIndex(options.param1);
  if (!i1.ok()) return fail(Status(StatusCode::kInvalidArgument, i1.status().message()));
  StatusOr<int> i2 = model.ParamIndex(options.param2);
  if (!i2.ok()) return fail(Status(StatusCode::kInvalidArgument, i2.status().message()));
  const PeriodicOrbit& orbit = start.point.orbit;
  PeriodicOrbit tangent_orbit;
  switch (start.kind) {
    case SpecialPointKind::kFold:
      result.kind = CurveKind::kFold;
      break;
    case SpecialPointKind::kPeriodDoubling:
      result.kind = CurveKind::kPeriodDoubling;
      break;
    case SpecialPointKind::kNeimarkSacker:
      result.kind = CurveKind::kNeimarkSacker;
      break;
    case SpecialPointKind::kGrazingL1:
    case SpecialPointKind::kGrazingL2:
    case SpecialPointKind::kGrazingPi: {
      // The touching point: the vanishing segment i (zero length at the located point) goes, and
      // segment i - 1, in the same mode as i + 1, ends tangentially on its guard instead. Without
      // a vanishing segment (the grazing seen from the side where the guard is not reached, e.g.
      // a free flight touching Pi), the segment where a guard touches zero is split there.
      // A corner (a segment of zero length between events of two surfaces) without a tangent
      // form at that segment is traced as it is, the segment held at zero length.
      result.kind = CurveKind::kGrazing;
      const bool tangent_given =
          std::any_of(orbit.signature.segments.begin(), orbit.signature.segments.end(),
                      [](const SegmentSpec& seg) { return seg.tangent; });
      const int corner = internal::CornerSegment(model, orbit);
      const bool corner_given = corner >= 0 && !internal::TangentForm(orbit, corner).ok();
      StatusOr<PeriodicOrbit> tangent =
          tangent_given || corner_given ? StatusOr<PeriodicOrbit>(orbit)
                                        : internal::GrazingTangentForm(model, propagator, orbit);
      if (phase.stopped()) return cancelled();
      if (!tangent.ok()) return fail(tangent.status());
      tangent_orbit = *std::move(tangent);
      break;
    }
    default:
      return fail(InvalidArgument(std::string("a curve starts at a FOLD, PERIOD_DOUBLING, "
                                              "NEIMARK_SACKER or GRAZING point, not at ") +
                                  SpecialPointKindName(start.kind)));
  }
  const PeriodicOrbit& traced = result.kind == CurveKind::kGrazing ? tangent_orbit : orbit;
  CurveTracer tracer(model, propagator, options, result.kind, *i1, *i2, traced);
  if (!tracer.CorrectStart()) {
    if (phase.stopped()) return cancelled();
    return fail(Internal("could not put the start point on the curve"));
  }
  if (root != nullptr && root->signature == traced.signature) tracer.SetKnownEnd(*root, vanishing);
  CurvePoint start_point = tracer.MakePoint(tracer.start());
  if (phase.stopped()) return cancelled();
  // One direction, through Poincare-section crossings: each goes on with a tracer in the rotated
  // signature (internal::SwitchSignature), leaving along the direction the curve arrived with.
  constexpr int kMaxSectionCrossings = 32;
  auto run = [&](double sign, std::vector<CurvePoint>* points) {
    std::vector<std::unique_ptr<CurveTracer>> rotated;
    const CurveTracer* current = &tracer;
    Eigen::Vector2d dir(0.0, sign);
    for (int crossed = 0;; ++crossed) {
      SectionCrossing cross;
      const std::string end = current->Trace(
          dir, {points, &result.crossings, &result.codim2, &result.unverified_ends, &cross}, &sum);
      const std::string through =
          crossed == 0 ? "" : "through " + std::to_string(crossed) + " section crossings, ";
      if (!cross.happened || phase.stopped()) return through + end;
      if (crossed == kMaxSectionCrossings) return through + "stopped at the next one";
      const internal::SwitchedOrbit sw =
          internal::SwitchSignature(model, propagator, cross.orbit, cross.violation);
      rotated.push_back(std::make_unique<CurveTracer>(model, propagator, options, result.kind, *i1,
                                                      *i2, sw.orbit));
      if (!rotated.back()->CorrectStart()) {
        if (phase.stopped()) return through + "cancelled";
        // Not taken up there (seen where the first segment's guard fires at its start, after
        // contact phases): the curve ends there, reported as before, with the reason; not as a
        // point where only a prediction brackets the crossing (CurveEnds::EndAtBoundary).
        const std::string why = "a Poincare-section crossing whose rotated signature " + sw.detail +
                                " could not be corrected";
        if (cross.unverified) {
          result.unverified_ends.push_back(cross.end);
          return through + "stopped " +
                 internal::UnverifiedEndText(options, cross.end, cross.end.detail + "; " + why);
        }
        result.codim2.push_back(cross.end);
        return through + "ended at a " + Codim2KindName(cross.end.kind) +
               " point: " + cross.end.detail + " (" + why + ")";
      }
      current = rotated.back().get();
      dir = cross.direction;
    }
  };
  std::vector<CurvePoint> backward, forward;
  const std::string end_forward = run(+1.0, &forward);
  phase.Continue(0.5);
  const std::string end_backward = phase.stopped() ? "cancelled" : run(-1.0, &backward);
  std::reverse(backward.begin(), backward.end());
  result.points = std::move(backward);
  result.points.push_back(std::move(start_point));
  result.points.insert(result.points.end(), forward.begin(), forward.end());
  // A cusp next to one of the curve's ends is that end: at a fold-grazing end the parameters move
  // as the square of the vanishing duration, so the direction test sees a reversal there, and a
  // curve started just off its end (stepped off a codimension-2 root, trace.cc) begins inside
  // that hook, where the cusp test's tangent ratio is relative to an already stationary tangent.
  // Measured in the reference box: such points 7e-10 from the end (box-scaled), real cusps in a
  // hook before an end 4e-9 .. 5e-9 from it; 1e-9 lies between.
  auto at_an_end = [&](const Codim2Point& cusp) {
    return cusp.kind == Codim2Kind::kCusp &&
           std::any_of(result.codim2.begin(), result.codim2.end(), [&](const Codim2Point& e) {
             return e.kind != Codim2Kind::kCusp && !e.detail.empty() &&
                    tracer.BoxDistance(e.point, cusp.point) <= 1e-9;
           });
  };
  result.codim2.erase(std::remove_if(result.codim2.begin(), result.codim2.end(), at_an_end),
                      result.codim2.end());
  sum.message = "increasing " + options.param2 + ": " + end_forward + "; decreasing " +
                options.param2 + ": " + end_backward;
  if (phase.stopped()) return cancelled();
  // Not a single step either way (and no codimension-2 end next to the start, claimed or not):
  // no curve.
  sum.termination =
      forward.empty() && backward.empty() && result.codim2.empty() && result.unverified_ends.empty()
          ? Termination::kFailed
          : Termination::kCompleted;
  if (sum.termination == Termination::kFailed) {
    sum.status = Internal("no step from the start point: " + sum.message);
    sum.message = sum.status.message();
  }
  return result;
}

}  // namespace

CurveResult ContinueCurve(const HybridModel& model, Propagator& propagator,
                          const SpecialPoint& start, const CurveOptions& options,
                          const ProgressCallback& progress) {
  return TraceCurve(model, propagator, start, nullptr, -1, options, progress);
}

CurveResult internal::ContinueCurveFromRoot(const HybridModel& model, Propagator& propagator,
                                            const SpecialPoint& start, const PeriodicOrbit& root,
                                            int vanishing, const CurveOptions& options) {
  return TraceCurve(model, propagator, start, &root, vanishing, options, {});
}

}  // namespace drillbif
