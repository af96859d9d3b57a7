#include "drillbif/continuation/continuation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <utility>

#include "common/phase_progress.h"
#include "continuation/branch_tracer.h"
#include "continuation/directions.h"

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

namespace internal {

namespace {

std::vector<int> Signs(ContinuationDirection direction) {
  std::vector<int> signs;
  if (direction != ContinuationDirection::kDecreasing) signs.push_back(+1);
  if (direction != ContinuationDirection::kIncreasing) signs.push_back(-1);
  return signs;
}

// The start's checks before any step: false with `refused` set to Continue's result (failed, or
// cancelled at the start) when the branch cannot start; else the parameter's index.
bool StartAccepted(const HybridModel& model, Propagator& propagator, const PeriodicOrbit& start,
                   const ContinuationOptions& options, PhaseProgress& phase, int* param,
                   ContinuationResult* refused) {
  auto fail = [&](Status s) {
    refused->summary.Fail(std::move(s));
    return false;
  };
  if (Status s = options.Validate(); !s.ok()) return fail(s);
  StatusOr<int> index = model.ParamIndex(options.param);
  if (!index.ok()) return fail(Status(StatusCode::kInvalidArgument, index.status().message()));
  if (Status s = ValidateSignature(model, start.signature); !s.ok()) return fail(s);
  if (Status s = model.ValidateParams(start.params); !s.ok()) return fail(s);
  const double value = start.params[*index];
  if (value < options.min || value > options.max) {
    return fail(InvalidArgument("the start orbit's " + options.param + " = " +
                                std::to_string(value) + " is outside [min, max]"));
  }
  const Admissibility adm = CheckAdmissible(model, propagator, start);
  if (phase.stopped()) {
    refused->summary.Cancel("cancelled before the first step");
    return false;
  }
  if (!adm.admissible) {
    return fail(Status(StatusCode::kFailedPrecondition,
                       "the start orbit is not admissible: " + adm.message));
  }
  *param = *index;
  return true;
}

// Direction d of `count` from an accepted start (BranchDirection's fields but `refused`).
BranchDirection RunDirection(const HybridModel& model, Propagator& propagator,
                             const PeriodicOrbit& start, const ContinuationOptions& options,
                             int param, int sign, size_t d, size_t count,
                             const ContinuationCallback& callback, PhaseProgress& phase) {
  BranchDirection run;
  run.sign = sign;
  internal::BranchTracer tracer(model, propagator, options, param);
  run.init = tracer.Init(start, sign, d == 0, &run.part);
  if (!run.init.ok()) {
    run.init_stopped = phase.stopped();
    return run;
  }
  while (tracer.Step(&run.part)) {
    const double fraction = (d + double(tracer.steps()) / options.steps.max_steps) / count;
    if ((callback && !callback(run.part.points.back(), fraction)) || !phase.Continue(fraction)) {
      run.cancelled = true;
      break;
    }
  }
  run.cancelled = run.cancelled || tracer.termination() == Termination::kCancelled;
  run.steps = tracer.steps();
  run.rejected = tracer.rejected();
  run.newton_iterations = tracer.newton_iterations();
  run.message = run.cancelled ? "cancelled" : tracer.message();
  run.failed = tracer.termination() == Termination::kFailed;
  run.closed = tracer.closed();
  return run;
}

}  // namespace

size_t DirectionCount(const ContinuationOptions& options) {
  return Signs(options.direction).size();
}

BranchDirection ContinueDirection(const HybridModel& model, Propagator& propagator,
                                  const PeriodicOrbit& start, const ContinuationOptions& options,
                                  size_t d, const ContinuationCallback& callback,
                                  const ProgressCallback& progress) {
  PhaseProgress phase(propagator, progress);
  BranchDirection run;
  int param = 0;
  if (!StartAccepted(model, propagator, start, options, phase, &param, &run.refused.emplace())) {
    return run;
  }
  run.refused.reset();
  const std::vector<int> signs = Signs(options.direction);
  return RunDirection(model, propagator, start, options, param, signs[d], d, signs.size(), callback,
                      phase);
}

ContinuationResult JoinDirections(std::vector<BranchDirection> runs) {
  if (!runs.empty() && runs.front().refused) return *std::move(runs.front().refused);
  ContinuationResult result;
  ContinuationSummary& sum = result.summary;
  std::vector<ContinuationPoint> backward;
  std::vector<std::string> endings;
  sum.termination = Termination::kCompleted;
  bool cancelled = false;
  for (size_t d = 0; d < runs.size() && !cancelled; ++d) {
    BranchDirection& run = runs[d];
    if (!run.init.ok()) {
      if (run.init_stopped && result.points.empty()) {
        sum.Cancel("cancelled before the first step");
        return result;
      }
      if (run.init_stopped) {
        cancelled = true;
        break;
      }
      sum.Fail(run.init);
      return result;
    }
    cancelled = run.cancelled;
    sum.steps += run.steps;
    sum.rejected_steps += run.rejected;
    sum.newton_iterations += run.newton_iterations;
    endings.push_back(std::string(run.sign > 0 ? "increasing" : "decreasing") + ": " + run.message);
    if (run.failed) sum.termination = Termination::kFailed;
    auto& specials = result.special_points;
    specials.insert(specials.end(), run.part.special_points.begin(), run.part.special_points.end());
    if (run.sign > 0) {
      result.points = std::move(run.part.points);
    } else {
      backward = std::move(run.part.points);
    }
    if (run.closed) break;  // the other direction would retrace the same loop
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

}  // namespace internal

ContinuationResult Continue(const HybridModel& model, Propagator& propagator,
                            const PeriodicOrbit& start, const ContinuationOptions& options,
                            const ContinuationCallback& callback,
                            const ProgressCallback& progress) {
  internal::PhaseProgress phase(propagator, progress);
  ContinuationResult refused;
  int param = 0;
  if (!internal::StartAccepted(model, propagator, start, options, phase, &param, &refused)) {
    return refused;
  }
  // One direction after the other, up to the first that ends the branch (a start that fails or
  // is stopped, a stop, a closed branch): JoinDirections reads no further.
  const std::vector<int> signs = internal::Signs(options.direction);
  std::vector<internal::BranchDirection> runs;
  for (size_t d = 0; d < signs.size(); ++d) {
    runs.push_back(internal::RunDirection(model, propagator, start, options, param, signs[d], d,
                                          signs.size(), callback, phase));
    const internal::BranchDirection& run = runs.back();
    if (!run.init.ok() || run.cancelled || run.closed) break;
  }
  return internal::JoinDirections(std::move(runs));
}

}  // namespace drillbif
