// One-parameter continuation of periodic orbits with detection, location and signature switching.
//
// Pseudo-arclength (Keller): on the branch G(X, lambda) = 0 of the orbit's boundary-value system
// (orbit/periodic_orbit.h) a step predicts Y + h t along the unit tangent t of Y = (X, lambda) and
// corrects by Newton on [G; t . (Y - Y_pred)] = 0 with the bordered Jacobian [G_X G_lambda; t^T].
// The step h adapts to the corrector's iteration count (target_iterations), and a failed or
// out-of-bounds step is retried shorter.
//
// Test functions, evaluated at every accepted point; a sign change between two points is located
// by a safeguarded secant (Illinois) on the arclength, each trial point corrected onto the branch,
// until the parameter is known to locate_tolerance:
//   fold (LP)             t_lambda, the parameter component of the tangent
//   period doubling (PD)  Re prod (mu_i + 1) over the nontrivial Floquet multipliers
//   Neimark-Sacker (NS)   Re prod_{i<j} (mu_i mu_j - 1), reported when the pair is complex
//   branch point (BP)     det [G_X G_lambda; t^T]
//   ROP / Pc maximum      d ROP / ds along the tangent (Pc where the orbit never progresses)
//   grazing, vanishing    a segment's duration, or the interior minimum of a guard of a segment,
//                         crossing zero (found by the admissibility check of every point)
// At a located grazing point the signature changes: a vanished segment is removed (and equal
// neighbours merged); a guard touching zero inside a segment splits it around a new zero-length
// segment of the mode across that guard. Continuation goes on with the new signature, so every
// reported point is admissible.
#ifndef DRILLBIF_CONTINUATION_CONTINUATION_H_
#define DRILLBIF_CONTINUATION_CONTINUATION_H_

#include <functional>
#include <limits>
#include <string>
#include <vector>

#include "drillbif/orbit/periodic_orbit.h"

namespace drillbif {

enum class SpecialPointKind {
  kFold,
  kPeriodDoubling,
  kNeimarkSacker,
  kBranchPoint,
  kGrazingL1,
  kGrazingL2,
  kGrazingPi,
  kSignatureChange,
  kRopMax,
  kPowerMax,
};
const char* SpecialPointKindName(SpecialPointKind kind);  // "FOLD", "PERIOD_DOUBLING", ...

// A point of a branch.
struct ContinuationPoint {
  double value = 0.0;            // the continuation parameter
  PeriodicOrbit orbit;           // parameters, signature, segments
  std::vector<double> measures;  // means over the orbit: ROP, Pc
  Stability stability;           // multipliers, stable flag
  double period = 0.0;           // 2 pi n / omega
};

// The stability of a branch on one side of a grazing: the limit of its multipliers there.
struct SideStability {
  bool known = false;        // false where that side was not computed (e.g. the branch ends)
  bool stable = false;       // every nontrivial |mu| < 1 on that side
  double max_modulus = 0.0;  // largest nontrivial |mu| on that side
};

// The grazing whose unfolding a fold, period doubling or Neimark-Sacker point belongs to: one
// located so close to a grazing of the same branch (within kNearGrazingRelativeDistance of the
// branch's parameter scale) that its test function changes sign where the multipliers jump across
// the grazing. The multipliers on each side are that grazing's SpecialPoint::before / after.
struct NearGrazing {
  bool near = false;  // false: no grazing of the branch within the distance
  SpecialPointKind kind = SpecialPointKind::kGrazingPi;  // the grazing's kind
  double value = 0.0;                                    // the grazing's parameter value
  double distance = 0.0;  // |point's value - grazing's value|, in parameter units
};

// Distance, relative to the branch's parameter scale max(1, span of its values), within which a
// fold / PD / NS point is reported as part of a grazing's unfolding (NearGrazing). The reference
// b-branch over [0, 0.2] has such points 3e-9 to 6.4e-7 from a Pi grazing, against >= 7e-3 between
// its isolated bifurcations and grazings; the bracket they are located to (locate_tolerance,
// 1e-10) is far below it.
inline constexpr double kNearGrazingRelativeDistance = 1e-6;

struct SpecialPoint {
  SpecialPointKind kind = SpecialPointKind::kFold;
  // The orbit at the located point. At a grazing or signature change, point.stability holds the
  // multipliers of the side before (the monodromy exactly at the grazing, with its zero-length
  // segment or touching guard, is degenerate and in general has neither side's multipliers), and
  // point.stability.stable is true only when both sides are known and stable.
  ContinuationPoint point;
  // Width, in the continued parameter, of the interval known to hold the point: at most
  // locate_tolerance where its location converged; 0 where it is solved directly (a branch's turn,
  // a grazing solved in tangent form); wider where trial points next to it stopped correcting,
  // the point then being the last trial that did, inside the interval.
  double bracket = 0.0;
  std::string detail;  // e.g. the signature before and after a switch
  // At a grazing or signature change (else not known): the stability just before the point on the
  // old signature (1e-6 of the step's arclength before it, up to 1e-2 where nearer points do not
  // correct) and just after it on the new one (the first point of the new signature's branch).
  SideStability before, after;
  // For a fold, period doubling or Neimark-Sacker point: the grazing of the same branch it sits
  // next to, if any (see NearGrazing).
  NearGrazing near_grazing;
};

enum class ContinuationDirection { kIncreasing, kDecreasing, kBoth };

// How a pseudo-arclength continuation steps and corrects: the same controls for one-parameter
// branches (ContinuationOptions::steps) and two-parameter curves (CurveOptions::steps), each with
// defaults of its own. Arclength is measured in the units of the unknowns and the parameters.
struct StepControl {
  double initial_step = 0.05;  // arclength of the first step
  double min_step = 1e-7;      // a step that must shrink below this ends the direction
  double max_step = 2.0;       // longest step
  int target_iterations = 3;   // corrector iterations aimed for; the step adapts
  int max_iterations = 8;      // more fails the step (it is retried shorter)
  int max_steps = 10000;       // per direction
  double tolerance = 1e-11;    // corrector: scaled Newton step
  // The corrector's Newton systems solved by condensing the segments' unknowns (orbit/condensed.h)
  // instead of a dense LU: the same iterates up to rounding, faster, but rounding-sensitive
  // outcomes of a trace move (docs/engine.md, periodic orbits), so off by default.
  bool condensed_solve = false;

  // INVALID_ARGUMENT naming the field for steps that are not positive and ordered, iterations
  // not 1 <= target <= max, max_steps < 1 or a tolerance not > 0.
  Status Validate() const;
};

struct ContinuationOptions {
  std::string param;                                      // name of the continuation parameter
  double min = -std::numeric_limits<double>::infinity();  // parameter bounds: stop there
  double max = std::numeric_limits<double>::infinity();
  ContinuationDirection direction = ContinuationDirection::kBoth;
  // max_steps per direction: the a-branch of MODEL.md takes ~2000.
  StepControl steps;
  double locate_tolerance = 1e-10;  // special points: parameter bracket width
  bool locate = true;               // detect and locate special points
  // Also ROP_MAX / POWER_MAX (the slope test: four measure evaluations per point); off where only
  // bifurcations are wanted (TraceCurves).
  bool locate_measure_maxima = true;
  // The measures each point carries (bit k: measure k of HybridModel::measure_names(), ROP and
  // Pc; the others are 0). Pc costs ~20 times ROP (quadrature of the contact power).
  unsigned point_measures = kAllMeasures;
  bool switch_signatures = true;  // at grazing, switch and go on (else stop there)
  // Stop a direction at the first special point of one of these kinds (e.g. {kFold}: up to the
  // fold, for the stable part of a branch).
  std::vector<SpecialPointKind> stop_at;

  Status Validate() const;
};

// How a continuation ended (common/termination.h): kCompleted when each direction reached a
// bound, its step budget or a stop_at point (the message says which, "increasing: ...;
// decreasing: ..."); kFailed when one could not go on (e.g. the corrector failed down to
// min_step; status INTERNAL with that message) or could not start; kCancelled when stopped.
struct ContinuationSummary : RunSummary {
  int64_t steps = 0;              // accepted steps, over all directions
  int64_t rejected_steps = 0;     // steps retried shorter
  int64_t newton_iterations = 0;  // corrector iterations
  // "completed: 785 steps (2 rejected), 2345 Newton iterations; increasing: reached max; ..."
  std::string BriefReport() const;
};

struct ContinuationResult {
  std::vector<ContinuationPoint> points;     // along the branch, in increasing arclength
  std::vector<SpecialPoint> special_points;  // in the order found
  ContinuationSummary summary;
};

// Receives each accepted point and the fraction of the step budget used; false cancels.
using ContinuationCallback = std::function<bool(const ContinuationPoint&, double fraction)>;

// Continues the branch through `start` (a solved, admissible orbit). `callback` receives every
// accepted point (not throttled). `progress` (optional, common/progress.h) receives the same
// fraction through a ProgressThrottle and is polled inside the steps too (every flow: a step's
// corrector, location of special points and signature switching), so that a stop ends the run
// within milliseconds however long a step takes; without it the run polls the throttle the
// propagator carries, if any (flow/propagator.h). A stop by either gives termination kCancelled,
// status CANCELLED and the points accepted before it.
ContinuationResult Continue(const HybridModel& model, Propagator& propagator,
                            const PeriodicOrbit& start, const ContinuationOptions& options,
                            const ContinuationCallback& callback = {},
                            const ProgressCallback& progress = {});

// Branch switching at a located period-doubling point: the period-2n orbit born there. Found by
// simulating from the PD orbit perturbed along the eigenvector of its multiplier -1 (size
// `perturbation`, relative), at the parameter `offset` past the point on each side in turn, until
// an attracting orbit of twice the period appears; then solved as a boundary-value problem.
// FAILED_PRECONDITION when neither side has one (e.g. a subcritical doubling, whose period-2n
// orbit is unstable).
struct PeriodDoublingSwitchOptions {
  // Parameter distance from the PD point: far enough that the new orbit attracts at a useful rate
  // (its own multiplier tends to 1 at the doubling) and its two halves differ (by ~sqrt(offset)).
  double offset = 1e-3;
  double perturbation = 1e-4;    // relative size of the kick along the eigenvector
  int transient_periods = 2000;  // forcing periods simulated before reading the orbit
  // Relative return distance accepted from the simulation; Newton then solves the orbit exactly.
  double return_tolerance = 1e-4;
};
// `progress` (optional) can stop the search (CANCELLED); without it the search polls the
// throttle the propagator carries, if any.
StatusOr<PeriodicOrbit> SwitchAtPeriodDoubling(const HybridModel& model, Propagator& propagator,
                                               const SpecialPoint& period_doubling,
                                               const std::string& param,
                                               const PeriodDoublingSwitchOptions& options = {},
                                               const ProgressCallback& progress = {});

// Branch switching at a period doubling without simulation, for sub- and supercritical doublings
// alike: the orbit at the doubling traversed twice solves the period-2n boundary-value system,
// where the doubled branch and the period-2n branch cross (a branch point: [G_X G_lambda] has a
// two-dimensional null space). The period-2n orbit is predicted from the doubled orbit along the
// null direction orthogonal to the doubled branch's tangent, at arclength `step` (relative to
// 1 + |X|), and corrected by Newton with the pseudo-arclength condition; the step is halved while
// the result is inadmissible (a doubling next to a grazing) or not yet a genuine period-2n orbit.
// `orbit` must be solved with a multiplier -1 (a located PERIOD_DOUBLING or a PD curve's point);
// FAILED_PRECONDITION when no step gives an admissible period-2n orbit.
// `progress` as for SwitchAtPeriodDoubling.
StatusOr<PeriodicOrbit> SwitchAtPeriodDoublingAlgebraic(
    const HybridModel& model, Propagator& propagator, const PeriodicOrbit& orbit,
    const std::string& param, double step = 1e-3, const ProgressCallback& progress = {});

}  // namespace drillbif

#endif  // DRILLBIF_CONTINUATION_CONTINUATION_H_
