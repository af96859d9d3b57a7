#include "client/trace_runner.h"

#include <chrono>
#include <cmath>
#include <exception>
#include <new>
#include <string>

#include "client/job_common.h"
#include "drillbif/continuation/trace.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/orbit/periodic_orbit.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/version.h"

namespace drillbif::client {
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
  return opt;
}

void ToProto(const CurvePoint& p, v1::CurveVertex* out) {
  *out->mutable_params() = internal::ToProtoParams(p.orbit.params);
  out->set_rop(p.measures.empty() ? 0.0 : p.measures[0]);
  out->set_stable(p.stability.stable);
}

// Finds the start orbit and traces; the request is valid.
StatusOr<v1::TraceResult> Trace(const Params& params, const TraceOptions& options,
                                const internal::StartSearch& search,
                                const ProgressCallback& progress,
                                std::chrono::steady_clock::time_point start) {
  const Osc& model = Model();
  ExactPropagator propagator(model);
  StatusOr<PeriodicOrbit> orbit =
      internal::StartOrbit(propagator, params, search.x0, search.transient_periods);
  if (!orbit.ok()) return orbit.status();
  const TraceResult r = TraceCurves(model, propagator, *orbit, options, progress);
  if (!r.summary.status.ok()) return r.summary.status;

  v1::TraceResult out;
  bool failed = false;
  for (const std::string& note : r.summary.notes) {
    out.add_notes(note);
    failed |= note.find(" failed: ") != std::string::npos;
  }
  for (size_t i = 0; i < r.curves.size(); ++i) {
    const TracedCurve& c = r.curves[i];
    v1::Curve* curve = out.add_curves();
    curve->set_kind(CurveKindName(c.curve.kind));
    curve->set_period(c.start.point.orbit.signature.periods);
    v1::SpecialPoint::Kind kind = v1::SpecialPoint::KIND_UNSPECIFIED;
    v1::SpecialPoint::Kind_Parse(SpecialPointKindName(c.start.kind), &kind);
    curve->set_start_kind(kind);
    curve->set_start_param(c.start_param);
    curve->set_message(c.curve.summary.message);
    failed |= c.curve.summary.termination == Termination::kFailed;
    for (const CurvePoint& p : c.curve.points) ToProto(p, curve->add_points());
    for (const Codim2Point& q : c.curve.codim2) {
      v1::Codim2Point* cp = out.add_codim2_points();
      cp->set_kind(Codim2KindName(q.kind));
      *cp->mutable_params() = internal::ToProtoParams(q.point.orbit.params);
      cp->set_curve(static_cast<int>(i));
      cp->set_detail(q.detail);
      cp->set_bracket(q.bracket);
    }
  }
  out.set_status(r.summary.cancelled ? "CANCELLED" : failed ? "FAILED" : "COMPLETED");
  out.set_message(std::to_string(r.curves.size()) + " curves, " +
                  std::to_string(out.codim2_points_size()) + " codimension-2 points, " +
                  std::to_string(r.summary.notes.size()) + " located points not traced (notes)");
  out.set_engine_version(EngineVersion());
  out.set_wall_seconds(internal::Seconds(start));
  return out;
}

}  // namespace

StatusOr<v1::TraceResult> RunTrace(const v1::TraceRequest& request,
                                   const ProgressCallback& progress) {
  const auto start = std::chrono::steady_clock::now();
  const Osc& model = Model();
  const Params params = internal::ToEngineParams(request.params());
  if (Status s = model.ValidateParams(params); !s.ok()) return s;
  StatusOr<TraceOptions> options = ToTraceOptions(request, params);
  if (!options.ok()) return options.status();
  const StatusOr<internal::StartSearch> search = internal::StartSearchOf(request, params);
  if (!search.ok()) return search.status();
  try {
    return Trace(params, *options, *search, progress, start);
  } catch (const std::bad_alloc&) {
    return Internal("out of memory while tracing");
  } catch (const std::exception& e) {
    return Internal(std::string("trace failed: ") + e.what());
  }
}

}  // namespace drillbif::client
