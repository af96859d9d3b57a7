#include "jobs/trace_runner.h"

#include <chrono>
#include <cmath>
#include <exception>
#include <memory>
#include <new>
#include <string>

#include "drillbif/continuation/trace.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/orbit/periodic_orbit.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/version.h"
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
  for (const double seed : request.seeds()) {
    if (!(std::isfinite(seed) && seed >= opt.min1 && seed <= opt.max1)) {
      return InvalidArgument("seeds: each value of " + opt.param1 + " must lie in the box [" +
                             Num(opt.min1) + ", " + Num(opt.max1) + "], got " + Num(seed));
    }
    opt.seeds1.push_back(seed);
  }
  opt.edge_branches = !request.no_edge_branches();
  switch (request.curve_steps()) {
    case v1::CURVE_STEPS_UNSPECIFIED:
    case v1::CURVE_STEPS_FINE:
      break;
    case v1::CURVE_STEPS_COARSE:
      opt.curve.target_iterations = 4;
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

// The curves as the proto result.
v1::TraceResult ToProto(const TraceResult& r) {
  v1::TraceResult out;
  for (const std::string& note : r.summary.notes) out.add_notes(note);
  for (size_t i = 0; i < r.curves.size(); ++i) {
    const TracedCurve& c = r.curves[i];
    v1::Curve* curve = out.add_curves();
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
    for (const Codim2Point& q : c.curve.codim2) {
      v1::Codim2Point* cp = out.add_codim2_points();
      cp->set_kind(Codim2KindName(q.kind));
      *cp->mutable_params() = internal::ToProtoParams(q.point.orbit.params);
      cp->set_curve(static_cast<int>(i));
      cp->set_detail(q.detail);
      cp->set_bracket(q.bracket);
    }
  }
  out.set_status(r.summary.cancelled        ? "CANCELLED"
                 : internal::TraceFailed(r) ? "FAILED"
                                            : "COMPLETED");
  out.set_message(std::to_string(r.curves.size()) + " curves, " +
                  std::to_string(out.codim2_points_size()) + " codimension-2 points, " +
                  std::to_string(r.summary.notes.size()) + " notes");
  return out;
}

// The region's grid from the request: two values >= 3 (the engine checks the total), or 201 each.
StatusOr<std::pair<int, int>> GridSizeOf(const v1::RegionRequest& request) {
  if (request.grid_size() == 0) return std::pair<int, int>(201, 201);
  if (request.grid_size() != 2 || request.grid(0) < 3 || request.grid(1) < 3) {
    return InvalidArgument("region.grid: give two node counts >= 3 (one per trace parameter)");
  }
  return std::pair<int, int>(request.grid(0), request.grid(1));
}

StatusOr<v1::TraceResult> Trace(const v1::TraceRequest& request, const ProgressCallback& progress,
                                OptimumCache* cache) {
  std::pair<int, int> grid;
  if (request.has_region()) {
    StatusOr<std::pair<int, int>> g = GridSizeOf(request.region());
    if (!g.ok()) return g.status();
    grid = *g;
  }
  // With a region, the curves take the first 90% of the progress bar.
  const double share = request.has_region() ? 0.9 : 1.0;
  ProgressCallback curves_progress;
  if (progress) curves_progress = [&](double f) { return progress(share * f); };
  StatusOr<internal::EngineTrace> trace = internal::TraceRequestCurves(request, curves_progress);
  if (!trace.ok()) return trace.status();
  v1::TraceResult out = ToProto(trace->result);
  // Curves an optimum can use (period 1 only, as its are) go to the cache for later optimum jobs.
  const bool for_optimum = cache != nullptr && !trace->result.summary.cancelled &&
                           !request.period2() && request.max_period() <= 1;
  const std::string key = for_optimum ? OptimumCache::KeyOf(request) : "";
  if (for_optimum) {
    cache->PutCurves(key, OptimumCurvesOf(trace->start, trace->options, trace->result));
  }
  if (request.has_region() && !trace->result.summary.cancelled) {
    const Osc& model = Model();
    ExactPropagator propagator(model);
    RegionProgress region_progress;
    if (progress) region_progress = [&](double f) { return progress(share + (1 - share) * f); };
    auto region = std::make_shared<StabilityRegion>(ComputeStabilityRegion(
        model, propagator, trace->start, RegionCurvesOf(trace->result.curves),
        internal::RegionOptionsFor(trace->options, grid.first, grid.second), region_progress));
    if (!region->summary.status.ok()) return region->summary.status;
    if (region->summary.cancelled) out.set_status("CANCELLED");
    jobs::ToProto(model, *region, out.mutable_region());
    if (for_optimum && !region->summary.cancelled) {
      cache->PutRegion(key, grid.first, grid.second, std::move(region));
    }
  }
  out.set_engine_version(EngineVersion());
  out.set_wall_seconds(internal::Seconds(trace->started));
  return out;
}

}  // namespace

namespace internal {

StatusOr<EngineTrace> TraceRequestCurves(const v1::TraceRequest& request,
                                         const ProgressCallback& progress) {
  EngineTrace out;
  out.started = std::chrono::steady_clock::now();
  const Osc& model = Model();
  const Params params = ToEngineParams(request.params());
  if (Status s = model.ValidateParams(params); !s.ok()) return s;
  StatusOr<TraceOptions> options = ToTraceOptions(request, params);
  if (!options.ok()) return options.status();
  const StatusOr<StartSearch> search = StartSearchOf(request, params);
  if (!search.ok()) return search.status();
  out.options = *options;
  out.options.seed_state = search->x0;
  ExactPropagator propagator(model);
  StatusOr<PeriodicOrbit> orbit =
      StartOrbit(propagator, params, search->x0, search->transient_periods);
  if (!orbit.ok()) return orbit.status();
  out.start = *orbit;
  out.result = TraceCurves(model, propagator, out.start, out.options, progress);
  if (!out.result.summary.status.ok()) return out.result.summary.status;
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
  o.param1 = trace.param1;
  o.param2 = trace.param2;
  o.min1 = trace.min1, o.max1 = trace.max1;
  o.min2 = trace.min2, o.max2 = trace.max2;
  o.n1 = n1, o.n2 = n2;
  return o;
}

}  // namespace internal

StatusOr<v1::TraceResult> RunTrace(const v1::TraceRequest& request,
                                   const ProgressCallback& progress, OptimumCache* cache) {
  try {
    return Trace(request, progress, cache);
  } catch (const std::bad_alloc&) {
    return Internal("out of memory while tracing");
  } catch (const std::exception& e) {
    return Internal(std::string("trace failed: ") + e.what());
  }
}

}  // namespace drillbif::jobs
