#include "drillbif/continuation/continuation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "common/phase_progress.h"
#include "continuation/branch_tracer.h"

namespace drillbif {

const char* SpecialPointKindName(SpecialPointKind kind) {
  switch (kind) {
    case SpecialPointKind::kFold:
      return "FOLD";
    case SpecialPointKind::kPeriodDoubling:
      return "PERIOD_DOUBLING";
    case SpecialPointKind::kNeimarkSacker:
      return "NEIMARK_SACKER";
    case SpecialPointKind::kBranchPoint:
      return "BRANCH_POINT";
    case SpecialPointKind::kGrazingL1:
      return "GRAZING_L1";
    case SpecialPointKind::kGrazingL2:
      return "GRAZING_L2";
    case SpecialPointKind::kGrazingPi:
      return "GRAZING_PI";
    case SpecialPointKind::kSignatureChange:
      return "SIGNATURE_CHANGE";
    case SpecialPointKind::kRopMax:
      return "ROP_MAX";
    case SpecialPointKind::kPowerMax:
      return "POWER_MAX";
  }
  return "?";
}

namespace {

bool IsGrazing(SpecialPointKind k) {
  // Every change of signature: the monodromy on each side is a different product of segment
  // flows and saltation matrices, so the multipliers jump across all of them (l1 and l2 as Pi).
  return k == SpecialPointKind::kGrazingPi || k == SpecialPointKind::kGrazingL1 ||
         k == SpecialPointKind::kGrazingL2 || k == SpecialPointKind::kSignatureChange;
}

bool IsSmoothBifurcation(SpecialPointKind k) {
  return k == SpecialPointKind::kFold || k == SpecialPointKind::kPeriodDoubling ||
         k == SpecialPointKind::kNeimarkSacker;
}

// Marks the folds, PDs and NS points of one branch that lie within kNearGrazingRelativeDistance
// of its parameter scale from one of its grazings (the nearest one). Their test functions change
// sign where the multipliers jump across the grazing (|mu| goes from below 1 to 2.9 on the
// reference b-branch), not at an isolated smooth bifurcation: reported, they would be mistaken
// for one.
void MarkNearGrazings(const std::vector<ContinuationPoint>& points,
                      std::vector<SpecialPoint>* specials) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (const ContinuationPoint& p : points) {
    lo = std::min(lo, p.value);
    hi = std::max(hi, p.value);
  }
  for (const SpecialPoint& s : *specials) {
    lo = std::min(lo, s.point.value);
    hi = std::max(hi, s.point.value);
  }
  // Parameters are dimensionless and O(1): the scale is 1 unless the branch spans more.
  const double scale = hi > lo ? std::max(1.0, hi - lo) : 1.0;
  const double within = kNearGrazingRelativeDistance * scale;
  for (SpecialPoint& s : *specials) {
    if (!IsSmoothBifurcation(s.kind)) continue;
    for (const SpecialPoint& g : *specials) {
      if (!IsGrazing(g.kind)) continue;
      const double d = std::abs(s.point.value - g.point.value);
      if (d > within || (s.near_grazing.near && d >= s.near_grazing.distance)) continue;
      s.near_grazing = NearGrazing{true, g.kind, g.point.value, d};
    }
  }
}

}  // namespace

Status StepControl::Validate() const {
  if (!(initial_step > 0.0 && min_step > 0.0 && max_step >= min_step && std::isfinite(max_step))) {
    return InvalidArgument("steps: need 0 < min_step <= max_step < inf and initial_step > 0");
  }
  if (target_iterations < 1 || max_iterations < target_iterations) {
    return InvalidArgument("steps: need 1 <= target_iterations <= max_iterations");
  }
  if (max_steps < 1) return InvalidArgument("steps: max_steps must be >= 1");
  if (!(tolerance > 0.0)) return InvalidArgument("steps: tolerance must be > 0");
  return Status::Ok();
}

Status ContinuationOptions::Validate() const {
  if (param.empty()) return InvalidArgument("param: the continuation parameter must be named");
  if (std::isnan(min) || std::isnan(max) || !(max > min)) {
    return InvalidArgument("the parameter range is empty: need min < max (got min = " +
                           std::to_string(min) + ", max = " + std::to_string(max) + ")");
  }
  if (Status s = steps.Validate(); !s.ok()) return s;
  if (!(locate_tolerance > 0.0)) return InvalidArgument("locate_tolerance must be > 0");
  return Status::Ok();
}

std::string ContinuationSummary::BriefReport() const {
  return RunSummary::BriefReport(CountOf(steps, "step") + " (" + std::to_string(rejected_steps) +
                                 " rejected), " + CountOf(newton_iterations, "Newton iteration"));
}

ContinuationResult Continue(const HybridModel& model, Propagator& propagator,
                            const PeriodicOrbit& start, const ContinuationOptions& options,
                            const ContinuationCallback& callback,
                            const ProgressCallback& progress) {
  ContinuationResult result;
  ContinuationSummary& sum = result.summary;
  internal::PhaseProgress phase(propagator, progress);
  auto fail = [&](Status s) {
    sum.Fail(std::move(s));
    return result;
  };
  auto cancelled_at_start = [&] {
    sum.Cancel("cancelled before the first step");
    return result;
  };
  if (Status s = options.Validate(); !s.ok()) return fail(s);
  StatusOr<int> param = model.ParamIndex(options.param);
  if (!param.ok()) return fail(Status(StatusCode::kInvalidArgument, param.status().message()));
  if (Status s = ValidateSignature(model, start.signature); !s.ok()) return fail(s);
  if (Status s = model.ValidateParams(start.params); !s.ok()) return fail(s);
  const double value = start.params[*param];
  if (value < options.min || value > options.max) {
    return fail(InvalidArgument("the start orbit's " + options.param + " = " +
                                std::to_string(value) + " is outside [min, max]"));
  }
  const Admissibility adm = CheckAdmissible(model, propagator, start);
  if (phase.stopped()) return cancelled_at_start();
  if (!adm.admissible) {
    return fail(Status(StatusCode::kFailedPrecondition,
                       "the start orbit is not admissible: " + adm.message));
  }

  std::vector<int> signs;
  if (options.direction != ContinuationDirection::kDecreasing) signs.push_back(+1);
  if (options.direction != ContinuationDirection::kIncreasing) signs.push_back(-1);
  std::vector<ContinuationPoint> backward;
  std::vector<std::string> endings;
  sum.termination = Termination::kCompleted;
  bool cancelled = false;
  for (size_t d = 0; d < signs.size() && !cancelled; ++d) {
    internal::BranchTracer tracer(model, propagator, options, *param);
    ContinuationResult part;
    if (Status s = tracer.Init(start, signs[d], d == 0, &part); !s.ok()) {
      if (phase.stopped() && result.points.empty()) return cancelled_at_start();
      if (phase.stopped()) {
        cancelled = true;
        break;
      }
      return fail(s);
    }
    while (tracer.Step(&part)) {
      const double fraction = (d + double(tracer.steps()) / options.steps.max_steps) / signs.size();
      if ((callback && !callback(part.points.back(), fraction)) || !phase.Continue(fraction)) {
        cancelled = true;
        break;
      }
    }
    cancelled = cancelled || tracer.termination() == Termination::kCancelled;
    sum.steps += tracer.steps();
    sum.rejected_steps += tracer.rejected();
    sum.newton_iterations += tracer.newton_iterations();
    const char* way = signs[d] > 0 ? "increasing" : "decreasing";
    endings.push_back(std::string(way) + ": " + (cancelled ? "cancelled" : tracer.message()));
    if (tracer.termination() == Termination::kFailed) sum.termination = Termination::kFailed;
    auto& specials = result.special_points;
    specials.insert(specials.end(), part.special_points.begin(), part.special_points.end());
    if (signs[d] > 0) {
      result.points = std::move(part.points);
    } else {
      backward = std::move(part.points);
    }
    if (tracer.closed()) break;  // the other direction would retrace the same loop
  }
  // Branch order: the decreasing part reversed, then the start and the increasing part.
  std::reverse(backward.begin(), backward.end());
  backward.insert(backward.end(), result.points.begin(), result.points.end());
  result.points = std::move(backward);
  MarkNearGrazings(result.points, &result.special_points);
  for (const std::string& e : endings) sum.message += (sum.message.empty() ? "" : "; ") + e;
  if (cancelled) {
    sum.termination = Termination::kCancelled;
    sum.status = Status(StatusCode::kCancelled, "continuation cancelled");
  } else if (sum.termination == Termination::kFailed) {
    sum.status = Internal(sum.message);
  }
  return result;
}

}  // namespace drillbif
