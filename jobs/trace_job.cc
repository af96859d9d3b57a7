#include "jobs/trace_job.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <map>
#include <memory>
#include <new>
#include <optional>
#include <string>

#include "drillbif/common/checked.h"
#include "drillbif/common/threads.h"
#include "drillbif/continuation/trace.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/orbit/periodic_orbit.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/version.h"
#include "jobs/item_batcher.h"
#include "jobs/job_common.h"
#include "jobs/optimum_cache.h"
#include "jobs/region_output.h"

namespace drillbif::jobs {
namespace {

using internal::Model;
using internal::Num;
using internal::Osc;

// The request's box as engine options, or INVALID_ARGUMENT naming the field.
StatusOr<TraceOptions> ToTraceOptions(const v1::TraceRequest& request, const Params& params) {
  const Osc& model = Model();
  if (request.trace_params_size() != 2) {
    return InvalidArgument("trace_params: name exactly two parameters (e.g. omega,a), got " +
                           std::to_string(request.trace_params_size()));
  }
  if (request.min_size() != 2 || request.max_size() != 2) {
    return InvalidArgument("min, max: give one bound per trace parameter (two each)");
  }
  TraceOptions opt;
  opt.param1 = request.trace_params(0);
  opt.param2 = request.trace_params(1);
  if (opt.param1 == opt.param2) {
    return InvalidArgument("trace_params: the two parameters must differ, got " + opt.param1 +
                           " twice");
  }
  for (int k = 0; k < 2; ++k) {
    const std::string& name = request.trace_params(k);
    StatusOr<int> index = model.ParamIndex(name);
    if (!index.ok()) return InvalidArgument("trace_params: " + index.status().message());
    const double lo = request.min(k), hi = request.max(k);
    if (!(std::isfinite(lo) && std::isfinite(hi) && lo < hi)) {
      return InvalidArgument("min, max of " + name + ": need finite min < max, got [" + Num(lo) +
                             ", " + Num(hi) + "]");
    }
    const std::string field = "min, max of " + name;
    if (Status s =
            internal::CheckParamValues(params, *index, {{field.c_str(), lo}, {field.c_str(), hi}});
        !s.ok()) {
      return s;
    }
    if (params[*index] < lo || params[*index] > hi) {
      return InvalidArgument("params." + name + " = " + Num(params[*index]) +
                             ", the start orbit's value, is outside the box [" + Num(lo) + ", " +
                             Num(hi) + "]");
    }
    (k == 0 ? opt.min1 : opt.min2) = lo;
    (k == 0 ? opt.max1 : opt.max2) = hi;
  }
  opt.max_period = request.period2() ? 2 : 1;
  if (request.has_max_period() && request.max_period() != 0) {
    if (request.period2() && request.max_period() < 2) {
      return InvalidArgument("max_period: " + std::to_string(request.max_period()) +
                             " contradicts period2 (which is max_period 2)");
    }
    opt.max_period = request.max_period();
  }
  if (request.seeds_size() > kMaxTraceSeeds) {
    return InvalidArgument("seeds: at most " + std::to_string(kMaxTraceSeeds) +
                           " values (each is a simulation, an orbit solve and two branches), got " +
                           std::to_string(request.seeds_size()));
  }
  for (const double seed : request.seeds()) {
    if (!(std::isfinite(seed) && seed >= opt.min1 && seed <= opt.max1)) {
      return InvalidArgument("seeds: each value of " + opt.param1 + " must lie in the box [" +
                             Num(opt.min1) + ", " + Num(opt.max1) + "], got " + Num(seed));
    }
    opt.seeds1.push_back(seed);
  }
  opt.edge_branches = !request.no_edge_branches();
  opt.vertex_states = false;  // the results carry a vertex's parameters, ROP and stability only
  if (request.threads() < 0 || request.threads() > kMaxTraceThreads) {
    return InvalidArgument("threads: need 0 (every core) .. " + std::to_string(kMaxTraceThreads) +
                           ", got " + std::to_string(request.threads()));
  }
  // More threads than cores would only hold more curves in flight (memory) for no speed.
  opt.threads = std::min(ThreadsOrCores(request.threads()), Cores());
  switch (request.curve_steps()) {
    case v1::CURVE_STEPS_UNSPECIFIED:
    case v1::CURVE_STEPS_COARSE:
      break;  // the engine's default (target_iterations 4)
    case v1::CURVE_STEPS_FINE:
      opt.curve.steps.target_iterations = 3;
      break;
    default:
      return InvalidArgument("curve_steps: unknown value " +
                             std::to_string(static_cast<int>(request.curve_steps())));
  }
  if (Status s = opt.Validate(); !s.ok()) return s;
  return opt;
}

void ToProto(const CurvePoint& p, v1::CurveVertex* out) {
  *out->mutable_params() = internal::ToProtoParams(p.orbit.params);
  out->set_rop(p.measures.empty() ? 0.0 : p.measures[0]);
  out->set_stable(p.stability.stable);
}

void ToProto(const TracedCurve& c, v1::Curve* curve) {
  curve->set_kind(CurveKindName(c.curve.kind));
  curve->set_period(c.start.point.orbit.signature.periods);
  v1::SpecialPoint::Kind kind = v1::SpecialPoint::KIND_UNSPECIFIED;
  v1::SpecialPoint::Kind_Parse(SpecialPointKindName(c.start.kind), &kind);
  curve->set_start_kind(kind);
  curve->set_start_param(c.start_param);
  curve->set_from_curve(c.from_curve);
  curve->set_message(c.curve.summary.message);
  for (const CurvePoint& p : c.curve.points) ToProto(p, curve->add_points());
  for (const Codim2Point& e : c.curve.unverified_ends) {
    ToProto(e.point, curve->add_unverified_ends());
  }
}

// Streams the curves in index order, as the result lists them, though the engine hands over late
// the curves whose end may merge at a flip-grazing (TracedCurveCallback): a curve after one still
// held waits here serialized (~90 bytes a vertex, against ~750 for the engine's vertex), so that
// the engine can release it.
class CurvesInOrder {
 public:
  explicit CurvesInOrder(ItemBatcher<v1::TraceResult>* out) : out_(out) {}

  // False once the sink refused.
  bool Add(int index, const TracedCurve& c) {
    if (index != next_) {
      v1::Curve curve;
      ToProto(c, &curve);
      waiting_[index] = curve.SerializeAsString();
      return true;
    }
    if (!out_->Add([&](v1::TraceResult* batch) { ToProto(c, batch->add_curves()); })) return false;
    ++next_;
    for (auto it = waiting_.find(next_); it != waiting_.end(); it = waiting_.find(next_)) {
      const bool added = out_->Add(
          [&](v1::TraceResult* batch) { batch->add_curves()->ParseFromString(it->second); });
      waiting_.erase(it);
      if (!added) return false;
      ++next_;
    }
    return true;
  }

 private:
  ItemBatcher<v1::TraceResult>* out_;
  int next_ = 0;                        // the index of the next curve to stream
  std::map<int, std::string> waiting_;  // curves handed over before it, serialized
};

// The trace as the proto result: its curves too unless `with_curves` is false (they were
// streamed), its codimension-2 points (each once, with the index of the first curve that has it)
// and notes.
v1::TraceResult ToProto(const TraceResult& r, bool with_curves) {
  v1::TraceResult out;
  for (const std::string& note : r.summary.notes) out.add_notes(note);
  for (size_t i = 0; i < r.curves.size(); ++i) {
    const TracedCurve& c = r.curves[i];
    if (with_curves) ToProto(c, out.add_curves());
    for (const Codim2Point& q : c.curve.codim2) {
      // A point met from several curves is listed once, with the first curve that has it.
      if (q.same_as_curve >= 0) continue;
      v1::Codim2Point* cp = out.add_codim2_points();
      cp->set_kind(Codim2KindName(q.kind));
      *cp->mutable_params() = internal::ToProtoParams(q.point.orbit.params);
      cp->set_curve(static_cast<int>(i));
      cp->set_detail(q.detail);
      cp->set_bracket(q.bracket);
    }
  }
  // The trace completes with its failed curves and branches in the notes: the job calls it FAILED.
  internal::SetRunEnd(r.summary.cancelled()      ? Termination::kCancelled
                      : internal::TraceFailed(r) ? Termination::kFailed
                                                 : Termination::kCompleted,
                      std::to_string(r.curves.size()) + " curves, " +
                          std::to_string(out.codim2_points_size()) + " codimension-2 points, " +
                          std::to_string(r.summary.notes.size()) + " notes",
                      &out);
  return out;
}

// The region's grid from the request: two values in [3, kMaxRegionNodes], or 201 each.
StatusOr<std::pair<int, int>> GridSizeOf(const v1::RegionRequest& request) {
  if (request.grid_size() == 0) return std::pair<int, int>(201, 201);
  if (request.grid_size() != 2 || request.grid(0) < 3 || request.grid(1) < 3 ||
      request.grid(0) > kMaxRegionNodes || request.grid(1) > kMaxRegionNodes) {
    return InvalidArgument("region.grid: give two node counts in [3, " +
                           std::to_string(kMaxRegionNodes) + "] (one per trace parameter)");
  }
  return std::pair<int, int>(request.grid(0), request.grid(1));
}

// Cost model (docs/performance.md, "Admission control"). The period-1 map of the (omega, a) box
// [0.05, 2] x [0.01, 8] (most of where the model is of interest: the reference span) takes 26 s
// and its period-2 map 8.5 min at ~1.6 GB; a small box takes ~1.5 s (start orbit, branches,
// edge branches). The time grows with the box's area in units of the reference spans and about
// 20-fold per period. Curve results are ~100 bytes a vertex.
constexpr double kTraceBaseSeconds = 5;
constexpr double kTraceReferenceSeconds = 30;
constexpr double kPeriodFactor = 20;
constexpr double kTraceBytesPerSecond = 2e5;
constexpr double kTraceMemoryPerSecond = 3e6;
// A region node, measured on the server (bench/largest_jobs.sh: trace jobs of the small (omega,
// a) box with 601^2 and 901^2 grids, the growth of the server's VmHWM and the run time between the
// two): ~480 bytes held at the peak (the engine's grid and per-node orbits, the result proto and
// its serialization) and 26 us (idle) to 45 us (a loaded 2-core machine) to fill. 600 bytes and
// 50 us keep the largest admitted region (~1.6e6 nodes) under the 1 GB memory limit.
constexpr double kRegionSecondsPerNode = 5e-5;
constexpr double kRegionBytesPerNode = 600;
// The stored region: the ROP (a double) and the label of each node with their tags, ~13.5 bytes
// a node in the store (the same runs' db size).
constexpr double kRegionResultBytesPerNode = 16;

// The span of values of a parameter the reference box covers (omega in [0.05, 2], a in
// [0.01, 8]), and for the others the range their studies use (MODEL.md).
double ReferenceSpan(const std::string& param) {
  if (param == "omega") return 2.0;
  if (param == "a") return 8.0;
  if (param == "b") return 0.2;
  if (param == "xi") return 0.5;
  if (param == "g") return 0.1;
  return kTwoPi;  // phi0
}

StatusOr<v1::TraceResult> Trace(const v1::TraceRequest& request, const RunContext& context) {
  DRILLBIF_ASSIGN_OR_RETURN(TracePlan plan, PlanTrace(request));
  plan.options.task_runner = context.trace_tasks;
  const ProgressCallback& progress = context.progress;
  OptimumCache* const cache = context.optimum_cache;
  // With a region, the curves take the first 90% of the progress bar.
  const double share = request.has_region() ? 0.9 : 1.0;
  ProgressCallback curves_progress;
  if (progress) curves_progress = [&](double f) { return progress(share * f); };
  // Streamed: each curve goes to the sink once it is final.
  std::optional<ItemBatcher<v1::TraceResult>> curves;
  std::optional<CurvesInOrder> in_order;
  TracedCurveCallback on_curve;
  if (context.sink != nullptr) {
    curves.emplace(context.sink);
    in_order.emplace(&*curves);
    on_curve = [&](int index, const TracedCurve& c) { return in_order->Add(index, c); };
  }
  StatusOr<internal::EngineTrace> trace = internal::TraceCurvesOf(plan, curves_progress, on_curve);
  if (curves && !curves->Flush()) return curves->status();
  if (!trace.ok()) {
    if (trace.status().code() != StatusCode::kCancelled) return trace.status();
    v1::TraceResult out;
    internal::SetRunEnd(Termination::kCancelled, "cancelled while looking for the start orbit",
                        &out);
    out.set_engine_version(EngineVersion());
    return out;
  }
  const std::pair<int, int> grid = plan.region_grid.value_or(std::pair<int, int>(0, 0));
  v1::TraceResult out = ToProto(trace->result, /*with_curves=*/!curves);
  // Curves an optimum can use (period 1 only, as its are) go to the cache for later optimum jobs.
  const bool for_optimum = cache != nullptr && !trace->result.summary.cancelled() &&
                           !request.period2() && request.max_period() <= 1;
  const std::string key = for_optimum ? OptimumCache::KeyOf(request) : "";
  if (for_optimum) {
    cache->PutCurves(key, OptimumCurvesOf(trace->start, trace->options, trace->result));
  }
  if (request.has_region() && !trace->result.summary.cancelled()) {
    const Osc& model = Model();
    ExactPropagator propagator(model);
    RegionProgress region_progress;
    if (progress) region_progress = [&](double f) { return progress(share + (1 - share) * f); };
    auto region = std::make_shared<StabilityRegion>(ComputeStabilityRegion(
        model, propagator, trace->start, RegionCurvesOf(trace->result.curves),
        internal::RegionOptionsFor(trace->options, grid.first, grid.second), region_progress));
    if (region->summary.failed()) return region->summary.status;
    if (region->summary.cancelled()) out.set_status(internal::ResultStatus(region->summary));
    jobs::ToProto(model, *region, out.mutable_region());
    if (for_optimum && !region->summary.cancelled()) {
      cache->PutRegion(key, grid.first, grid.second, std::move(region));
    }
  }
  out.set_engine_version(EngineVersion());
  out.set_wall_seconds(internal::Seconds(trace->started));
  return out;
}

}  // namespace

StatusOr<TracePlan> PlanTrace(const v1::TraceRequest& request) {
  TracePlan plan;
  plan.params = internal::ToEngineParams(request.params());
  DRILLBIF_RETURN_IF_ERROR(Model().ValidateParams(plan.params));
  DRILLBIF_ASSIGN_OR_RETURN(plan.options, ToTraceOptions(request, plan.params));
  DRILLBIF_ASSIGN_OR_RETURN(plan.search, internal::StartSearchOf(request, plan.params));
  plan.options.seed_state = plan.search.x0;
  if (request.has_region()) {
    DRILLBIF_ASSIGN_OR_RETURN(plan.region_grid, GridSizeOf(request.region()));
  }
  return plan;
}

JobCost TraceCost(const TracePlan& plan) {
  const TraceOptions& o = plan.options;
  const double area = o.width1() / ReferenceSpan(o.param1) * (o.width2() / ReferenceSpan(o.param2));
  const double periods = std::pow(kPeriodFactor, std::max(0, o.max_period - 1));
  const std::string box = "the box " + o.param1 + " in [" + Num(o.min1) + ", " + Num(o.max1) +
                          "], " + o.param2 + " in [" + Num(o.min2) + ", " + Num(o.max2) + "]";
  const std::string driver = box + " (request.min, request.max) with orbits of period up to " +
                             std::to_string(o.max_period) +
                             " (request.period2, request.max_period)";
  JobCost cost;
  const double seconds = kTraceBaseSeconds + kTraceReferenceSeconds * area * periods;
  cost.seconds = {seconds, driver};
  cost.result_bytes = {seconds * kTraceBytesPerSecond, driver};
  cost.memory_bytes = {seconds * kTraceMemoryPerSecond, driver};
  if (plan.region_grid) {
    const JobCost region = RegionCost(plan.region_grid->first, plan.region_grid->second);
    cost.seconds.amount += region.seconds.amount;
    cost.result_bytes.amount += region.result_bytes.amount;
    cost.memory_bytes.amount += region.memory_bytes.amount;
    // A refusal names what drives it: the region's grid when it is most of the cost.
    const std::string grid = region.seconds.driver + " (request.region.grid)";
    if (region.seconds.amount > cost.seconds.amount / 2) cost.seconds.driver = grid;
    if (region.result_bytes.amount > cost.result_bytes.amount / 2) cost.result_bytes.driver = grid;
    if (region.memory_bytes.amount > cost.memory_bytes.amount / 2) cost.memory_bytes.driver = grid;
  }
  return cost;
}

JobCost RegionCost(int n1, int n2) {
  const double nodes = CountOrInfinity(CheckedMul(int64_t{n1}, int64_t{n2}));
  const std::string driver =
      "a region grid of " + std::to_string(n1) + " x " + std::to_string(n2) + " nodes";
  JobCost cost;
  cost.seconds = {nodes * kRegionSecondsPerNode, driver};
  cost.result_bytes = {nodes * kRegionResultBytesPerNode, driver};
  cost.memory_bytes = {nodes * kRegionBytesPerNode, driver};
  return cost;
}

namespace internal {

// Share of the progress bar of the start orbit's search.
constexpr double kStartShare = 0.02;

StatusOr<EngineTrace> TraceCurvesOf(const TracePlan& plan, const ProgressCallback& progress,
                                    const TracedCurveCallback& on_curve) {
  EngineTrace out;
  out.started = std::chrono::steady_clock::now();
  const Osc& model = Model();
  out.options = plan.options;
  ExactPropagator propagator(model);
  // The start orbit's search is the first 2% of the progress, the curves the rest: the fraction
  // stays monotone (a long transient reports its own fractions from 0 to 1).
  StatusOr<PeriodicOrbit> orbit =
      StartOrbit(propagator, plan.params, plan.search.x0, plan.search.transient_periods,
                 StageProgress(progress, 0.0, kStartShare));
  if (!orbit.ok()) return orbit.status();
  out.start = *orbit;
  out.result = TraceCurves(model, propagator, out.start, out.options,
                           StageProgress(progress, kStartShare, 1.0), on_curve);
  if (out.result.summary.failed()) return out.result.summary.status;
  return out;
}

bool TraceFailed(const TraceResult& trace) {
  for (const TracedCurve& c : trace.curves) {
    if (c.curve.summary.termination == Termination::kFailed) return true;
  }
  for (const std::string& note : trace.summary.notes) {
    if (note.find(" failed: ") != std::string::npos) return true;
  }
  return false;
}

RegionOptions RegionOptionsFor(const TraceOptions& trace, int n1, int n2) {
  RegionOptions o;
  o.box() = trace.box();
  o.n1 = n1, o.n2 = n2;
  return o;
}

}  // namespace internal

StatusOr<v1::TraceResult> RunTrace(const v1::TraceRequest& request, const RunContext& context) {
  try {
    return Trace(request, context);
  } catch (const std::bad_alloc&) {
    return Internal("out of memory while tracing");
  } catch (const std::exception& e) {
    return Internal(std::string("trace failed: ") + e.what());
  }
}

}  // namespace drillbif::jobs
