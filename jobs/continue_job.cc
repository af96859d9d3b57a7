#include "jobs/continue_job.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <complex>
#include <exception>
#include <memory>
#include <new>
#include <optional>
#include <string>
#include <utility>

#include "drillbif/common/checked.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/model/drifting_oscillator.h"
#include "drillbif/orbit/periodic_orbit.h"
#include "drillbif/orbit/signature.h"
#include "drillbif/version.h"
#include "jobs/item_batcher.h"

namespace drillbif::jobs {
namespace {

using internal::Model;
using internal::Num;
using internal::Osc;
using internal::Seconds;
using internal::StartOrbit;
using internal::ToEngineParams;
using internal::ToProtoMode;
using internal::ToProtoParams;

// Cost model (docs/performance.md, "Admission control"): a continuation step takes 50 us on the
// reference b-branch (786 steps in 0.04 s) and 150 us on the a-branch (2817 in 0.43 s); 1 ms
// covers longer orbits. A branch point is ~700 bytes in the result and ~20 kB while the engine
// holds it (the orbit's segments, Jacobians and multipliers).
constexpr double kSecondsPerStep = 1e-3;
constexpr double kSecondsPerTransientPeriod = 1e-5;
constexpr double kPointBytes = 700;
constexpr double kPointMemoryBytes = 20e3;
// Share of the progress bar of the start orbit's search.
constexpr double kStartShare = 0.05;

// A step option must be a finite number > 0.
Status CheckPositive(const char* field, double v) {
  if (v > 0.0 && std::isfinite(v)) return Status::Ok();
  return InvalidArgument(std::string(field) + " must be a finite number > 0, got " + Num(v));
}

// Continuation options from a request, the engine's defaults filling unset fields, each checked
// so that the message names the request field. The parameter name and the range are checked
// against the model by the caller.
StatusOr<ContinuationOptions> ToContinuationOptions(const v1::ContinueRequest& request) {
  ContinuationOptions options;
  options.param = request.param();
  options.min = request.min();
  options.max = request.max();
  switch (request.direction()) {
    case v1::ContinueRequest::DIRECTION_UNSPECIFIED:
    case v1::ContinueRequest::BOTH:
      options.direction = ContinuationDirection::kBoth;
      break;
    case v1::ContinueRequest::INCREASING:
      options.direction = ContinuationDirection::kIncreasing;
      break;
    case v1::ContinueRequest::DECREASING:
      options.direction = ContinuationDirection::kDecreasing;
      break;
    default:
      return InvalidArgument("direction: unknown value " + std::to_string(request.direction()));
  }
  if (request.has_initial_step()) options.steps.initial_step = request.initial_step();
  if (request.has_min_step()) options.steps.min_step = request.min_step();
  if (request.has_max_step()) options.steps.max_step = request.max_step();
  if (request.has_max_steps()) options.steps.max_steps = request.max_steps();
  if (request.has_target_iterations())
    options.steps.target_iterations = request.target_iterations();
  if (request.has_locate_tolerance()) options.locate_tolerance = request.locate_tolerance();
  if (request.has_switch_signatures()) options.switch_signatures = request.switch_signatures();
  for (int k : request.stop_at()) {
    // The proto's kind names are the engine's (SpecialPointKindName).
    bool found = false;
    for (int e = 0; e <= static_cast<int>(SpecialPointKind::kPowerMax); ++e) {
      const auto kind = static_cast<SpecialPointKind>(e);
      if (v1::SpecialPoint::Kind_Name(static_cast<v1::SpecialPoint::Kind>(k)) ==
          SpecialPointKindName(kind)) {
        options.stop_at.push_back(kind);
        found = true;
      }
    }
    if (!found) return InvalidArgument("stop_at: no special point kind " + std::to_string(k));
  }

  if (!std::isfinite(options.min) || !std::isfinite(options.max)) {
    return InvalidArgument("min and max must be finite (got min = " + Num(options.min) +
                           ", max = " + Num(options.max) + ")");
  }
  if (!(options.max > options.min)) {
    return InvalidArgument("the range [min, max] is empty: max must be > min (got min = " +
                           Num(options.min) + ", max = " + Num(options.max) + ")");
  }
  if (Status s = CheckPositive("initial_step", options.steps.initial_step); !s.ok()) return s;
  if (Status s = CheckPositive("min_step", options.steps.min_step); !s.ok()) return s;
  if (Status s = CheckPositive("max_step", options.steps.max_step); !s.ok()) return s;
  if (options.steps.max_step < options.steps.min_step) {
    return InvalidArgument(
        "max_step must be >= min_step (got max_step = " + Num(options.steps.max_step) +
        ", min_step = " + Num(options.steps.min_step) + ")");
  }
  if (options.steps.max_steps < 1 || options.steps.max_steps > kMaxContinuationSteps) {
    return InvalidArgument("max_steps must be in [1, " + std::to_string(kMaxContinuationSteps) +
                           "], got " + std::to_string(options.steps.max_steps));
  }
  if (options.steps.target_iterations < 1 ||
      options.steps.target_iterations > options.steps.max_iterations) {
    return InvalidArgument("target_iterations must be in [1, " +
                           std::to_string(options.steps.max_iterations) + "], got " +
                           std::to_string(options.steps.target_iterations));
  }
  if (Status s = CheckPositive("locate_tolerance", options.locate_tolerance); !s.ok()) return s;
  // Whatever else the engine requires.
  if (Status s = options.Validate(); !s.ok()) return s;
  return options;
}

void ToProto(const Stability& in, google::protobuf::RepeatedPtrField<v1::Multiplier>* out) {
  out->Reserve(static_cast<int>(in.multipliers.size()));
  for (const std::complex<double>& mu : in.multipliers) {
    v1::Multiplier* m = out->Add();
    m->set_re(mu.real());
    m->set_im(mu.imag());
    m->set_abs(std::abs(mu));
  }
}

void ToProto(const Signature& in, google::protobuf::RepeatedField<int>* out) {
  out->Reserve(static_cast<int>(in.segments.size()));
  for (const SegmentSpec& seg : in.segments) out->Add(ToProtoMode(seg.mode));
}

// ROP and Pc of a point (0 if the engine did not measure them).
double MeasureOf(const ContinuationPoint& pt, int index) {
  return static_cast<int>(pt.measures.size()) > index ? pt.measures[index] : 0.0;
}

void ToProto(const ContinuationPoint& in, v1::BranchPoint* out) {
  const Osc& model = Model();
  *out->mutable_params() = ToProtoParams(in.orbit.params);
  out->set_value(in.value);
  out->set_rop(MeasureOf(in, Osc::kDrift));
  out->set_power(MeasureOf(in, Osc::kPower));
  out->set_period(in.period);
  ToProto(in.stability, out->mutable_multipliers());
  out->set_structural_zeros(in.stability.structural_zeros);
  out->set_structural_ones(in.stability.structural_ones);
  out->set_stable(in.stability.stable);
  ToProto(in.orbit.signature, out->mutable_signature());
  out->set_signature_text(SignatureString(model, in.orbit.signature));
  out->mutable_durations()->Add(in.orbit.durations.begin(), in.orbit.durations.end());
  if (!in.orbit.starts.empty()) {
    const StateVector& x = in.orbit.starts.front();
    out->set_p(x[Osc::kP]);
    out->set_y(x[Osc::kY]);
    out->set_q(x[Osc::kQ]);
  }
}

void ToProto(const SpecialPoint& in, v1::SpecialPoint* out) {
  const Osc& model = Model();
  // The proto's names are the engine's (SpecialPointKindName), so the mapping is by name.
  v1::SpecialPoint::Kind kind = v1::SpecialPoint::KIND_UNSPECIFIED;
  if (!v1::SpecialPoint::Kind_Parse(SpecialPointKindName(in.kind), &kind)) {
    kind = v1::SpecialPoint::KIND_UNSPECIFIED;
  }
  out->set_kind(kind);
  const ContinuationPoint& pt = in.point;
  out->set_value(pt.value);
  out->set_bracket(in.bracket);
  *out->mutable_params() = ToProtoParams(pt.orbit.params);
  out->set_rop(MeasureOf(pt, Osc::kDrift));
  out->set_power(MeasureOf(pt, Osc::kPower));
  ToProto(pt.stability, out->mutable_multipliers());
  out->set_stable(pt.stability.stable);
  out->set_detail(in.detail);
  ToProto(pt.orbit.signature, out->mutable_signature());
  out->set_signature_text(SignatureString(model, pt.orbit.signature));
  auto side = [](const SideStability& s, v1::SideStability* o) {
    o->set_stable(s.stable);
    o->set_max_abs(s.max_modulus);
  };
  if (in.before.known) side(in.before, out->mutable_stability_before());
  if (in.after.known) side(in.after, out->mutable_stability_after());
  out->set_stability_changes(in.before.known && in.after.known &&
                             in.before.stable != in.after.stable);
  if (in.near_grazing.near) {
    v1::SpecialPoint::Kind graze = v1::SpecialPoint::KIND_UNSPECIFIED;
    if (v1::SpecialPoint::Kind_Parse(SpecialPointKindName(in.near_grazing.kind), &graze)) {
      v1::NearGrazing* near = out->mutable_near_grazing();
      near->set_kind(graze);
      near->set_value(in.near_grazing.value);
      near->set_distance(in.near_grazing.distance);
    }
  }
}

// The result of a continuation; its branch points go to `points` when given (streamed), else
// into the result. Errors: the sink's.
StatusOr<v1::ContinueResult> ToProto(const ContinuationResult& r,
                                     ItemBatcher<v1::ContinueResult>* points = nullptr) {
  v1::ContinueResult out;
  internal::SetRunEnd(r.summary, &out);
  if (points != nullptr) {
    for (const ContinuationPoint& pt : r.points) {
      if (!points->Add([&](v1::ContinueResult* batch) { ToProto(pt, batch->add_points()); })) {
        return points->status();
      }
    }
    if (!points->Flush()) return points->status();
  } else {
    out.mutable_points()->Reserve(static_cast<int>(r.points.size()));
    for (const ContinuationPoint& pt : r.points) ToProto(pt, out.add_points());
  }
  for (const SpecialPoint& sp : r.special_points) ToProto(sp, out.add_special_points());
  out.set_steps(r.summary.steps);
  out.set_rejected_steps(r.summary.rejected_steps);
  out.set_newton_iterations(r.summary.newton_iterations);
  out.set_engine_version(EngineVersion());
  return out;
}

}  // namespace

StatusOr<ContinuePlan> PlanContinue(const v1::ContinueRequest& request) {
  const Osc& model = Model();
  ContinuePlan plan;
  plan.params = ToEngineParams(request.params());
  DRILLBIF_RETURN_IF_ERROR(model.ValidateParams(plan.params));
  if (request.param().empty()) {
    return InvalidArgument(
        "param: the continuation parameter must be named (one of a, b, omega, xi, g, phi0)");
  }
  StatusOr<int> index = model.ParamIndex(request.param());
  if (!index.ok()) return InvalidArgument("param: " + index.status().message());
  plan.index = *index;
  DRILLBIF_ASSIGN_OR_RETURN(plan.options, ToContinuationOptions(request));
  // Both ends must be valid values of the parameter (the branch may run up to them).
  DRILLBIF_RETURN_IF_ERROR(internal::CheckParamValues(
      plan.params, plan.index, {{"min", plan.options.min}, {"max", plan.options.max}}));
  const double value = plan.params[plan.index];
  if (value < plan.options.min || value > plan.options.max) {
    return InvalidArgument("the start value of the continuation parameter, params." +
                           request.param() + " = " + Num(value) + ", is outside [min, max] = [" +
                           Num(plan.options.min) + ", " + Num(plan.options.max) + "]");
  }
  DRILLBIF_ASSIGN_OR_RETURN(plan.search, internal::StartSearchOf(request, plan.params));
  plan.follow_period_doubling = request.follow_period_doubling();
  return plan;
}

JobCost ContinueCost(const ContinuePlan& plan) {
  const int64_t directions = plan.options.direction == ContinuationDirection::kBoth ? 2 : 1;
  // The period-doubled branch, when followed, has the same budget.
  const int64_t branches = plan.follow_period_doubling ? 2 : 1;
  const double steps = CountOrInfinity(
      CheckedMul(CheckedMul(int64_t{plan.options.steps.max_steps}, directions), branches));
  const std::string driver = "request.max_steps = " + std::to_string(plan.options.steps.max_steps) +
                             " per direction" + (directions == 2 ? ", both directions" : "") +
                             (branches == 2 ? ", and the period-doubled branch" : "");
  JobCost cost;
  cost.seconds.amount =
      steps * kSecondsPerStep + plan.search.transient_periods * kSecondsPerTransientPeriod;
  cost.seconds.driver = driver + " (and request.transient_periods = " +
                        std::to_string(plan.search.transient_periods) + ")";
  cost.result_bytes = {steps * kPointBytes, driver};
  cost.memory_bytes = {steps * kPointMemoryBytes, driver};
  return cost;
}

StatusOr<v1::ContinueResult> RunContinue(const v1::ContinueRequest& request,
                                         const RunContext& context) {
  const auto start = std::chrono::steady_clock::now();
  const Osc& model = Model();
  DRILLBIF_ASSIGN_OR_RETURN(const ContinuePlan plan, PlanContinue(request));
  const ProgressCallback& progress = context.progress;
  const ValueCallback& on_value = context.on_value;
  try {
    ExactPropagator propagator(model);
    // The start orbit's search is the first 5% of the progress (a transient of 500 periods
    // takes milliseconds; a long one is bounded by admission).
    StatusOr<PeriodicOrbit> orbit =
        StartOrbit(propagator, plan.params, plan.search.x0, plan.search.transient_periods,
                   internal::StageProgress(progress, 0.0, kStartShare));
    const bool cancelled = !orbit.ok() && orbit.status().code() == StatusCode::kCancelled;
    if (!orbit.ok() && !cancelled) return orbit.status();
    if (cancelled || (progress && !progress(kStartShare))) {
      v1::ContinueResult out;
      internal::SetRunEnd(Termination::kCancelled, "cancelled before the continuation started",
                          &out);
      out.set_engine_version(EngineVersion());
      out.set_wall_seconds(Seconds(start));
      return out;
    }
    const ProgressCallback branch_progress = internal::StageProgress(progress, kStartShare, 1.0);
    ContinuationCallback callback;
    if (progress || on_value) {
      callback = [&branch_progress, &on_value](const ContinuationPoint& p, double fraction) {
        if (on_value) on_value(p.value);
        return !branch_progress || branch_progress(fraction);
      };
    }
    const ContinuationResult r =
        Continue(model, propagator, *orbit, plan.options, callback, branch_progress);
    // A start the engine refuses before the first step (e.g. an orbit that is not admissible) is
    // an error of the request, not a result.
    const StatusCode code = r.summary.status.code();
    if (r.summary.termination == Termination::kFailed && r.points.empty() &&
        (code == StatusCode::kInvalidArgument || code == StatusCode::kFailedPrecondition)) {
      return r.summary.status;
    }
    std::optional<ItemBatcher<v1::ContinueResult>> points;
    if (context.sink != nullptr) points.emplace(context.sink);
    DRILLBIF_ASSIGN_OR_RETURN(v1::ContinueResult out, ToProto(r, points ? &*points : nullptr));
    if (request.follow_period_doubling()) {
      // The first period doubling on the branch whose period-2n orbit attracts (a supercritical
      // doubling): switch onto it.
      v1::ContinueResult* doubled = out.mutable_period_doubled_branch();
      doubled->set_engine_version(EngineVersion());
      StatusOr<PeriodicOrbit> orbit2 =
          Status(StatusCode::kNotFound, "no period-doubling point on the branch");
      std::string tried;
      for (const SpecialPoint& sp : r.special_points) {
        if (sp.kind != SpecialPointKind::kPeriodDoubling) continue;
        orbit2 =
            SwitchAtPeriodDoubling(model, propagator, sp, request.param(), {}, branch_progress);
        if (orbit2.ok()) break;
        tried += (tried.empty() ? "" : "; ") + orbit2.status().message();
      }
      {
        if (!orbit2.ok()) {
          internal::SetRunEnd(Termination::kFailed,
                              tried.empty() ? orbit2.status().message() : tried, doubled);
        } else {
          ContinuationOptions options2 = plan.options;
          if (orbit2->params[plan.index] < options2.min ||
              orbit2->params[plan.index] > options2.max) {
            options2.min = std::min(options2.min, orbit2->params[plan.index]);
            options2.max = std::max(options2.max, orbit2->params[plan.index]);
          }
          DRILLBIF_ASSIGN_OR_RETURN(*doubled, ToProto(Continue(model, propagator, *orbit2, options2,
                                                               callback, progress)));
        }
      }
    }
    out.set_wall_seconds(Seconds(start));
    return out;
  } catch (const std::bad_alloc&) {
    return Internal("out of memory while continuing");
  } catch (const std::exception& e) {
    return Internal(std::string("continuation failed: ") + e.what());
  }
}

}  // namespace drillbif::jobs
