#include "jobs/optimum_job.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include "drillbif/flow/exact_propagator.h"
#include "drillbif/orbit/attractors.h"
#include "drillbif/orbit/signature.h"
#include "drillbif/region/robust_optimum.h"
#include "drillbif/version.h"
#include "jobs/job_common.h"
#include "jobs/optimum_cache.h"

namespace drillbif::jobs {
namespace {

using internal::Model;
using internal::Seconds;

constexpr int kMaxDefaultNodes = 1001;  // per parameter, when the grid follows the margin

// Engine options from the request, or INVALID_ARGUMENT naming the field.
StatusOr<OptimumOptions> ToOptimumOptions(const v1::OptimumRequest& request) {
  OptimumOptions o;
  if (request.margin_size() > 0) o.margin.assign(request.margin().begin(), request.margin().end());
  o.scaled = request.scaled();
  if (Status s = o.Validate(); !s.ok()) return s;
  if (request.grid_size() != 0 &&
      (request.grid_size() != 2 || request.grid(0) < 3 || request.grid(1) < 3 ||
       request.grid(0) > kMaxRegionNodes || request.grid(1) > kMaxRegionNodes)) {
    return InvalidArgument("grid: give two node counts in [3, " + std::to_string(kMaxRegionNodes) +
                           "] (one per trace parameter)");
  }
  if (request.trace().has_region()) {
    return InvalidArgument("trace.region: the optimum computes its own region; set grid instead");
  }
  if (request.trace().period2()) {
    return InvalidArgument(
        "trace.period2: the optimum is over period-1 motion; its boundaries "
        "are the period-1 curves");
  }
  if (request.trace().max_period() > 1) {
    return InvalidArgument(
        "trace.max_period: the optimum is over period-1 motion; its boundaries "
        "are the period-1 curves");
  }
  return o;
}

// The grid asked for, or one whose spacing is half the margin in each parameter.
std::pair<int, int> GridFor(const v1::OptimumRequest& request, const OptimumOptions& o,
                            const TraceOptions& box) {
  if (request.grid_size() == 2) return {request.grid(0), request.grid(1)};
  const double w1 = box.width1(), w2 = box.width2();
  const double h1 = 0.5 * (o.scaled ? o.margin[0] * w1 : o.margin.front());
  const double h2 = 0.5 * (o.scaled ? o.margin[0] * w2 : o.margin.back());
  auto nodes = [](double width, double h) {
    return static_cast<int>(std::clamp(std::ceil(width / h) + 1.0, 3.0, 1.0 * kMaxDefaultNodes));
  };
  return {nodes(w1, h1), nodes(w2, h2)};
}

// The coexistence check at the optimum (OptimumResult.attractors): fills `out` and returns the
// message's sentence on it.
// `orbit` (optional) gets the optimum's orbit when one of the starts settles on it.
std::string CheckCoexistence(const DriftingOscillator& model, Propagator& propagator,
                             const Params& params, const Signature& optimum,
                             const ProgressCallback& progress, v1::OptimumResult* out,
                             std::optional<PeriodicOrbit>* orbit) {
  const auto start = std::chrono::steady_clock::now();
  const std::vector<StateVector> states = DriftingOscillator::SpreadStates(params);
  const StatusOr<AttractorSample> sample =
      SampleAttractors(model, propagator, params, states, GuessOptions(), progress);
  out->set_check_seconds(Seconds(start));
  if (!sample.ok()) return "coexistence not checked: " + sample.status().message();
  std::string others;
  bool optimum_seen = false;
  for (const Attractor& a : sample->attractors) {
    v1::Attractor* p = out->add_attractors();
    p->set_signature(SignatureString(model, a.orbit.signature));
    p->set_period(a.orbit.signature.periods);
    p->set_rop(a.rop);
    p->set_stable(a.stable);
    p->set_reached_from(static_cast<int>(a.reached_from.size()));
    if (SameUpToSection(a.orbit.signature, optimum)) {
      if (orbit != nullptr && !optimum_seen) *orbit = a.orbit;
      optimum_seen = true;
      continue;
    }
    others += std::string(others.empty() ? "" : ", ") + p->signature() + " (ROP " +
              internal::Num(a.rop) + ", from " + std::to_string(a.reached_from.size()) + ")";
  }
  out->set_not_periodic(static_cast<int>(sample->not_periodic.size()));
  const std::string of = " of " + std::to_string(states.size()) + " spread initial states";
  std::string sentence;
  if (others.empty() && sample->not_periodic.empty()) {
    sentence = "every one" + of + " settles on the optimum's orbit";
  } else {
    sentence = "other motions coexist there (simulation from" + of + "): ";
    if (!others.empty()) sentence += others;
    if (!sample->not_periodic.empty()) {
      sentence +=
          std::string(others.empty() ? "" : "; ") + std::to_string(sample->not_periodic.size()) +
          " settle on no periodic orbit of period <= " + std::to_string(GuessOptions().max_period);
    }
  }
  if (!optimum_seen) sentence += "; none settles on the optimum's orbit";
  return sentence;
}

// The curves of the request's trace: `cache`'s (*reused set), else traced and put there unless
// cancelled (*cancelled set: the curves traced until then).
StatusOr<std::shared_ptr<const OptimumCurves>> CurvesFor(const TracePlan& plan,
                                                         const std::string& key,
                                                         const ProgressCallback& progress,
                                                         OptimumCache* cache, bool* reused,
                                                         bool* cancelled) {
  *reused = *cancelled = false;
  if (cache != nullptr) {
    if (std::shared_ptr<const OptimumCurves> held = cache->FindCurves(key)) {
      *reused = true;
      return held;
    }
  }
  StatusOr<internal::EngineTrace> traced = internal::TraceCurvesOf(plan, progress);
  if (!traced.ok() && traced.status().code() == StatusCode::kCancelled) {
    *cancelled = true;
    return std::make_shared<const OptimumCurves>();
  }
  DRILLBIF_ASSIGN_OR_RETURN(const internal::EngineTrace trace, std::move(traced));
  *cancelled = trace.result.summary.cancelled();
  std::shared_ptr<const OptimumCurves> curves =
      OptimumCurvesOf(trace.start, trace.options, trace.result);
  if (cache != nullptr && !*cancelled) cache->PutCurves(key, curves);
  return curves;
}

StatusOr<v1::OptimumResult> Optimum(const v1::OptimumRequest& request, const RunContext& context,
                                    OptimumDetail* detail) {
  DRILLBIF_ASSIGN_OR_RETURN(const OptimumPlan plan, PlanOptimum(request));
  const ProgressCallback& progress = context.progress;
  OptimumCache* const cache = context.optimum_cache;
  // The curves take most of the time: 85% of the progress bar; the region the next 12%, the
  // query 1% and the coexistence check the last 2%. Each stage reports its own fractions from 0
  // to 1: mapped into its share, the job's progress stays monotone.
  constexpr double kShare = 0.85, kRegionEnd = 0.97, kQueryEnd = 0.98;
  ProgressCallback curves_progress;
  if (progress) curves_progress = [&](double f) { return progress(kShare * f); };
  const std::string key = cache != nullptr ? OptimumCache::KeyOf(request.trace()) : "";
  const auto trace_start = std::chrono::steady_clock::now();
  bool reused = false, cancelled = false;
  // The trace's tasks run where the context says (a server's workers, as a trace job's do).
  TracePlan trace = plan.trace;
  trace.options.task_runner = context.trace_tasks;
  StatusOr<std::shared_ptr<const OptimumCurves>> found =
      CurvesFor(trace, key, curves_progress, cache, &reused, &cancelled);
  if (!found.ok()) return found.status();
  v1::OptimumResult out;
  out.set_engine_version(EngineVersion());
  out.set_trace_seconds(Seconds(trace_start));
  out.set_curves_reused(reused);
  const OptimumCurves& curves = **found;
  out.set_curves(static_cast<int>(curves.kinds.size()));
  if (cancelled) {
    internal::SetRunEnd(Termination::kCancelled, "cancelled while tracing the curves", &out);
    return out;
  }

  const auto region_start = std::chrono::steady_clock::now();
  const auto [n1, n2] = plan.grid;
  const auto& model = Model();
  ExactPropagator propagator(model);
  std::shared_ptr<const StabilityRegion> held =
      cache != nullptr ? cache->FindRegion(key, n1, n2) : nullptr;
  out.set_region_reused(held != nullptr);
  if (held == nullptr) {
    RegionProgress region_progress;
    if (progress) {
      region_progress = [&](double f) { return progress(kShare + (kRegionEnd - kShare) * f); };
    }
    auto computed = std::make_shared<StabilityRegion>(ComputeStabilityRegion(
        model, propagator, curves.start, curves.region_curves,
        internal::RegionOptionsFor(curves.options, n1, n2), region_progress));
    if (computed->summary.failed()) return computed->summary.status;
    if (cache != nullptr && !computed->summary.cancelled()) cache->PutRegion(key, n1, n2, computed);
    held = std::move(computed);
  }
  const StabilityRegion& region = *held;
  out.set_region_seconds(Seconds(region_start));
  out.add_grid(n1);
  out.add_grid(n2);
  out.add_spacing(region.width1() / (n1 - 1));
  out.add_spacing(region.width2() / (n2 - 1));
  out.set_inside_nodes(region.summary.inside_nodes);
  if (region.summary.cancelled()) {
    internal::SetRunEnd(Termination::kCancelled, "cancelled while computing the stability region",
                        &out);
    return out;
  }

  const auto query_start = std::chrono::steady_clock::now();
  const RobustOptimum best = FindRobustOptimum(
      region, plan.options, internal::StageProgress(progress, kRegionEnd, kQueryEnd));
  out.set_query_seconds(Seconds(query_start));
  out.set_candidates(static_cast<int32_t>(best.summary.candidates));
  if (!best.summary.completed()) {
    internal::SetRunEnd(best.summary, &out);
    return out;
  }
  Params params = curves.start.params;
  const int k1 = model.ParamIndex(region.param1).value();
  const int k2 = model.ParamIndex(region.param2).value();
  params[k1] = best.value1;
  params[k2] = best.value2;
  *out.mutable_params() = internal::ToProtoParams(params);
  out.set_rop(best.rop);
  for (double m : best.margin) {
    if (std::isfinite(m)) out.add_margin(m);
  }
  out.set_distance_scaled(std::isfinite(best.distance_scaled) ? best.distance_scaled : 0.0);
  out.set_nearest_curve(best.nearest_curve);
  out.set_nearest_curve_kind(best.nearest_curve >= 0
                                 ? CurveKindName(curves.kinds[best.nearest_curve])
                             : best.nearest_curve == RegionVertex::kSeam ? "SEAM"
                                                                         : "UNTRACED");
  out.set_near_box_edge(best.near_box_edge);
  const Signature& optimum_signature = region.signatures[region.grid.label[best.node]];
  out.set_signature(SignatureString(model, optimum_signature));

  const std::string coexistence =
      CheckCoexistence(model, propagator, params, optimum_signature,
                       internal::StageProgress(progress, kQueryEnd, 1.0), &out,
                       detail != nullptr ? &detail->orbit : nullptr);
  if (detail != nullptr) {
    detail->obstacles = RegionObstacles(region);
    detail->kinds = curves.kinds;
    detail->region = held;
    detail->curves = *found;
    detail->options = plan.options;
    detail->width1 = region.width1();
    detail->width2 = region.width2();
  }

  if (progress && !progress(1.0)) {  // stopped during the coexistence check
    internal::SetRunEnd(Termination::kCancelled,
                        "cancelled while checking the coexistence of other motions", &out);
    return out;
  }
  const bool failed = curves.failed;
  std::string message = "ROP " + internal::Num(best.rop) + " at " + region.param1 + " = " +
                        internal::Num(best.value1) + ", " + region.param2 + " = " +
                        internal::Num(best.value2) + "; " + region.summary.message;
  if (failed) message += "; a curve failed to trace, so a boundary may be missing";
  if (best.near_box_edge) message += "; the margin reaches beyond the box, where nothing is known";
  if (!out.margin_size()) message += "; no bifurcation curve bounds the region in the box";
  message += "; " + coexistence;
  // A curve that failed to trace leaves the answer in doubt: the job calls it FAILED.
  internal::SetRunEnd(failed ? Termination::kFailed : Termination::kCompleted, message, &out);
  return out;
}

}  // namespace

StatusOr<OptimumPlan> PlanOptimum(const v1::OptimumRequest& request) {
  OptimumPlan plan;
  DRILLBIF_ASSIGN_OR_RETURN(plan.options, ToOptimumOptions(request));
  StatusOr<TracePlan> trace = PlanTrace(request.trace());
  if (!trace.ok()) {
    const Status& s = trace.status();
    return s.code() == StatusCode::kInvalidArgument ? InvalidArgument("trace." + s.message()) : s;
  }
  plan.trace = std::move(trace).value();
  plan.grid = GridFor(request, plan.options, plan.trace.options);
  return plan;
}

JobCost OptimumCost(const OptimumPlan& plan) {
  JobCost cost = TraceCost(plan.trace);
  const JobCost region = RegionCost(plan.grid.first, plan.grid.second);
  // The coexistence check: 8 simulations of ~600 periods, ~50 ms; the query milliseconds.
  cost.seconds.amount += region.seconds.amount + 0.1;
  cost.memory_bytes.amount += region.memory_bytes.amount;
  // The result is one point and the attractors found there: a few kB.
  cost.result_bytes = {1e4, "the optimum"};
  if (region.seconds.amount > cost.seconds.amount / 2) cost.seconds.driver = region.seconds.driver;
  if (region.memory_bytes.amount > cost.memory_bytes.amount / 2) {
    cost.memory_bytes.driver = region.memory_bytes.driver + " (request.grid, or the margin)";
  }
  return cost;
}

StatusOr<v1::OptimumResult> RunOptimum(const v1::OptimumRequest& request,
                                       const RunContext& context) {
  return RunOptimumWithDetail(request, context, nullptr);
}

StatusOr<v1::OptimumResult> RunOptimumWithDetail(const v1::OptimumRequest& request,
                                                 const RunContext& context, OptimumDetail* detail) {
  try {
    return Optimum(request, context, detail);
  } catch (const std::bad_alloc&) {
    return Internal("out of memory while computing the optimum");
  } catch (const std::exception& e) {
    return Internal(std::string("optimum failed: ") + e.what());
  }
}

}  // namespace drillbif::jobs
