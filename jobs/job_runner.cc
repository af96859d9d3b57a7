#include "jobs/job_runner.h"

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <complex>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <utility>

#include "drillbif/continuation/continuation.h"
#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/model/drifting_oscillator.h"
#include "drillbif/orbit/periodic_orbit.h"
#include "drillbif/orbit/signature.h"
#include "drillbif/simulate/sweep.h"
#include "drillbif/version.h"
#include "jobs/job_common.h"

namespace drillbif::jobs {
namespace {

using internal::Model;
using internal::Num;
using internal::Osc;
using internal::Seconds;
using internal::StartOrbit;
using internal::ToEngineParams;
using internal::ToEngineState;
using internal::ToProtoParams;

// ---- proto -> engine -------------------------------------------------------------------------

// ---- engine -> proto -------------------------------------------------------------------------

v1::Mode ToProtoMode(int mode) {
  switch (mode) {
    case Osc::kNoContact:
      return v1::NO_CONTACT;
    case Osc::kContact:
      return v1::CONTACT;
    case Osc::kProgression:
      return v1::PROGRESSION;
  }
  return v1::MODE_UNSPECIFIED;
}

void ToProto(const PoincareSample& in, v1::PoincarePoint* out) {
  out->set_period(in.period);
  out->set_mode(ToProtoMode(in.mode));
  out->set_p(in.x[Osc::kP]);
  out->set_y(in.x[Osc::kY]);
  out->set_q(in.x[Osc::kQ]);
}

v1::SimulateResult ToProto(const SimulationResult& r, const SimulationOptions& options) {
  const Osc& model = Model();
  v1::SimulateResult out;
  out.set_status(TerminationName(r.termination));
  if (!r.status.ok()) out.set_message(r.status.message());
  if (r.termination == Termination::kCompleted && options.outputs.measures &&
      static_cast<int>(r.measure_means.size()) > Osc::kPower) {
    out.set_rop(r.measure_means[Osc::kDrift]);
    out.set_power(r.measure_means[Osc::kPower]);
  }
  out.mutable_poincare()->Reserve(static_cast<int>(r.poincare.size()));
  for (const PoincareSample& smp : r.poincare) ToProto(smp, out.add_poincare());
  for (const EventRecord& e : r.events) {
    v1::Event* pe = out.add_events();
    pe->set_period(e.period);
    pe->set_s(e.s);
    pe->set_t(e.t);
    const GuardSpec& guard = model.guards(e.from_mode)[e.guard];
    pe->set_surface(guard.surface);
    pe->set_guard(guard.name);
    pe->set_from_mode(ToProtoMode(e.from_mode));
    pe->set_to_mode(ToProtoMode(e.to_mode));
    pe->set_tangential(e.tangential);
    pe->set_p(e.x[Osc::kP]);
    pe->set_y(e.x[Osc::kY]);
    pe->set_q(e.x[Osc::kQ]);
  }
  for (size_t i = 0; i < r.period_modes.size(); ++i) {
    v1::PeriodModes* pm = out.add_period_modes();
    pm->set_period(options.transient_periods + static_cast<int>(i));
    for (int mode : r.period_modes[i]) pm->add_modes(ToProtoMode(mode));
  }
  out.mutable_trajectory()->Reserve(static_cast<int>(r.trajectory.size()));
  for (const TrajectoryPoint& tp : r.trajectory) {
    v1::TrajectoryPoint* pt = out.add_trajectory();
    pt->set_t(tp.t);
    pt->set_mode(ToProtoMode(tp.mode));
    pt->set_p(tp.x[Osc::kP]);
    pt->set_y(tp.x[Osc::kY]);
    pt->set_q(tp.x[Osc::kQ]);
    pt->set_s(tp.x[Osc::kS]);
  }
  out.set_segments(r.segments);
  out.set_events_total(r.events_total);
  out.set_evaluations(r.evaluations);
  out.set_engine_version(EngineVersion());
  return out;
}

// ---- validation and propagators --------------------------------------------------------------

// Options of a simulation from a request; the engine's own defaults fill unset fields.
StatusOr<SimulationOptions> ToSimulationOptions(const v1::SimulateRequest& request) {
  SimulationOptions options;
  if (request.has_transient_periods()) options.transient_periods = request.transient_periods();
  if (request.has_sample_periods()) options.sample_periods = request.sample_periods();
  const v1::SimulateRequest::Outputs o = EffectiveOutputs(request);
  options.outputs.measures = o.measures();
  options.outputs.poincare = o.poincare();
  options.outputs.events = o.events();
  options.outputs.modes = o.modes();
  options.outputs.trajectory_dt = o.trajectory_dt();
  if (!o.measures() && !o.poincare() && !o.events() && !o.modes() && o.trajectory_dt() == 0.0) {
    return InvalidArgument(
        "outputs: nothing requested (set measures, poincare, events, modes or trajectory_dt, "
        "or leave outputs unset for measures and poincare)");
  }
  if (Status s = options.Validate(); !s.ok()) return s;
  if (options.sample_periods > kMaxSamplePeriods) {
    return InvalidArgument("sample_periods must be <= " + std::to_string(kMaxSamplePeriods) +
                           ", got " + std::to_string(options.sample_periods));
  }
  return options;
}

// Trajectory points a run would record: about window length / dt (plus one per segment).
Status CheckTrajectorySize(const SimulationOptions& options, const Params& params) {
  const double dt = options.outputs.trajectory_dt;
  if (dt <= 0.0) return Status::Ok();
  const double window = options.sample_periods * kTwoPi / Model().ForcingFrequency(params);
  const double points = window / dt;
  if (!(points <= static_cast<double>(kMaxTrajectoryPoints))) {
    return InvalidArgument("trajectory_dt = " + Num(dt) + " would record about " +
                           std::to_string(static_cast<long long>(std::min(points, 1e18))) +
                           " trajectory points (at most " + std::to_string(kMaxTrajectoryPoints) +
                           "); raise trajectory_dt or lower sample_periods");
  }
  return Status::Ok();
}

StatusOr<std::unique_ptr<Propagator>> MakePropagator(const v1::SimulateRequest& request) {
  switch (request.propagator()) {
    case v1::PROPAGATOR_UNSPECIFIED:
    case v1::EXACT:
      return std::unique_ptr<Propagator>(std::make_unique<ExactPropagator>(Model()));
    case v1::CVODE: {
      CvodeOptions options;
      if (request.has_cvode_rtol()) options.rtol = request.cvode_rtol();
      if (Status s = options.Validate(); !s.ok()) {
        return InvalidArgument("cvode_rtol: " + s.message());
      }
      return std::unique_ptr<Propagator>(std::make_unique<CvodePropagator>(Model(), options));
    }
    default:
      break;
  }
  return InvalidArgument("propagator: unknown value " + std::to_string(request.propagator()));
}

StatusOr<SweepOptions> ToSweepOptions(const v1::SweepRequest& request) {
  SweepOptions options;
  options.param = request.param();
  options.min = request.min();
  options.max = request.max();
  if (request.has_steps()) options.steps = request.steps();
  switch (request.direction()) {
    case v1::SweepRequest::DIRECTION_UNSPECIFIED:
    case v1::SweepRequest::UP:
      options.direction = SweepDirection::kUp;
      break;
    case v1::SweepRequest::DOWN:
      options.direction = SweepDirection::kDown;
      break;
    case v1::SweepRequest::BOTH:
      options.direction = SweepDirection::kBoth;
      break;
    default:
      return InvalidArgument("direction: unknown value " + std::to_string(request.direction()));
  }
  if (request.has_transient_periods()) options.transient_periods = request.transient_periods();
  if (request.has_sample_periods()) options.sample_periods = request.sample_periods();
  options.threads = request.threads();
  if (Status s = options.Validate(); !s.ok()) return s;
  if (options.threads > kMaxSweepThreads) {
    return InvalidArgument("threads must be <= " + std::to_string(kMaxSweepThreads) + ", got " +
                           std::to_string(options.threads));
  }
  const long long directions = options.direction == SweepDirection::kBoth ? 2 : 1;
  const long long samples =
      static_cast<long long>(options.steps) * options.sample_periods * directions;
  if (samples > kMaxSweepSamples) {
    return InvalidArgument("steps * sample_periods * directions = " + std::to_string(samples) +
                           " Poincare samples, more than the " + std::to_string(kMaxSweepSamples) +
                           " one sweep may record");
  }
  return options;
}

void ToProto(const SweepPoint& in, bool sweep_cancelled, v1::SweepPoint* out) {
  out->set_value(in.value);
  // A grid value the workers never reached keeps the engine's initial kFailed with no message.
  if (sweep_cancelled && in.termination == Termination::kFailed && in.message.empty()) {
    out->set_status(TerminationName(Termination::kCancelled));
    out->set_message("not reached before the sweep was cancelled");
    return;
  }
  out->set_status(TerminationName(in.termination));
  out->set_message(in.message);
  out->mutable_samples()->Reserve(static_cast<int>(in.samples.size()));
  for (const PoincareSample& smp : in.samples) ToProto(smp, out->add_samples());
}

// ---- continuation ----------------------------------------------------------------------------

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
  if (request.has_initial_step()) options.initial_step = request.initial_step();
  if (request.has_min_step()) options.min_step = request.min_step();
  if (request.has_max_step()) options.max_step = request.max_step();
  if (request.has_max_steps()) options.max_steps = request.max_steps();
  if (request.has_target_iterations()) options.target_iterations = request.target_iterations();
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
  if (Status s = CheckPositive("initial_step", options.initial_step); !s.ok()) return s;
  if (Status s = CheckPositive("min_step", options.min_step); !s.ok()) return s;
  if (Status s = CheckPositive("max_step", options.max_step); !s.ok()) return s;
  if (options.max_step < options.min_step) {
    return InvalidArgument("max_step must be >= min_step (got max_step = " + Num(options.max_step) +
                           ", min_step = " + Num(options.min_step) + ")");
  }
  if (options.max_steps < 1 || options.max_steps > kMaxContinuationSteps) {
    return InvalidArgument("max_steps must be in [1, " + std::to_string(kMaxContinuationSteps) +
                           "], got " + std::to_string(options.max_steps));
  }
  if (options.target_iterations < 1 || options.target_iterations > options.max_iterations) {
    return InvalidArgument("target_iterations must be in [1, " +
                           std::to_string(options.max_iterations) + "], got " +
                           std::to_string(options.target_iterations));
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
  *out->mutable_params() = ToProtoParams(pt.orbit.params);
  out->set_rop(MeasureOf(pt, Osc::kDrift));
  out->set_power(MeasureOf(pt, Osc::kPower));
  ToProto(pt.stability, out->mutable_multipliers());
  out->set_stable(pt.stability.stable);
  out->set_detail(in.detail);
  ToProto(pt.orbit.signature, out->mutable_signature());
  out->set_signature_text(SignatureString(model, pt.orbit.signature));
}

v1::ContinueResult ToProto(const ContinuationResult& r) {
  v1::ContinueResult out;
  out.set_status(TerminationName(r.summary.termination));
  out.set_message(r.summary.message);
  out.mutable_points()->Reserve(static_cast<int>(r.points.size()));
  for (const ContinuationPoint& pt : r.points) ToProto(pt, out.add_points());
  for (const SpecialPoint& sp : r.special_points) ToProto(sp, out.add_special_points());
  out.set_steps(r.summary.steps);
  out.set_rejected_steps(r.summary.rejected_steps);
  out.set_newton_iterations(r.summary.newton_iterations);
  out.set_engine_version(EngineVersion());
  return out;
}

}  // namespace

v1::SimulateRequest::Outputs EffectiveOutputs(const v1::SimulateRequest& request) {
  if (request.has_outputs()) return request.outputs();
  const SimulationOutputs defaults;
  v1::SimulateRequest::Outputs outputs;
  outputs.set_measures(defaults.measures);
  outputs.set_poincare(defaults.poincare);
  outputs.set_events(defaults.events);
  outputs.set_modes(defaults.modes);
  outputs.set_trajectory_dt(defaults.trajectory_dt);
  return outputs;
}

StatusOr<v1::SimulateResult> RunSimulate(const v1::SimulateRequest& request,
                                         const ProgressCallback& progress) {
  const auto start = std::chrono::steady_clock::now();
  const Osc& model = Model();
  StatusOr<SimulationOptions> options = ToSimulationOptions(request);
  if (!options.ok()) return options.status();
  const Params params = ToEngineParams(request.params());
  if (Status s = model.ValidateParams(params); !s.ok()) return s;
  const StateVector x0 = ToEngineState(request.has_initial_state(), request.initial_state());
  if (Status s = model.ValidateState(x0, params, options->state_tolerance); !s.ok()) return s;
  if (Status s = CheckTrajectorySize(*options, params); !s.ok()) return s;
  StatusOr<std::unique_ptr<Propagator>> propagator = MakePropagator(request);
  if (!propagator.ok()) return propagator.status();

  try {
    const SimulationResult r = Simulate(model, **propagator, params, x0, *options, progress);
    v1::SimulateResult out = ToProto(r, *options);
    out.set_wall_seconds(Seconds(start));
    return out;
  } catch (const std::bad_alloc&) {
    return Internal("out of memory while simulating");
  } catch (const std::exception& e) {
    return Internal(std::string("simulation failed: ") + e.what());
  }
}

StatusOr<v1::SweepResult> RunSweep(const v1::SweepRequest& request,
                                   const ProgressCallback& progress,
                                   const ValueCallback& on_value) {
  const auto start = std::chrono::steady_clock::now();
  const Osc& model = Model();
  StatusOr<SweepOptions> options = ToSweepOptions(request);
  if (!options.ok()) return options.status();
  const Params params = ToEngineParams(request.params());
  const StateVector x0 = ToEngineState(request.has_initial_state(), request.initial_state());
  const PropagatorFactory make_propagator = [&model] {
    return std::unique_ptr<Propagator>(std::make_unique<ExactPropagator>(model));
  };

  try {
    const SweepResult r = Sweep(model, make_propagator, params, x0, *options, progress, on_value);
    // Sweep validates everything (parameter name, range ends, initial state) before it starts;
    // once started it always completes or is cancelled, single values failing on their own.
    if (r.termination == Termination::kFailed) {
      return r.status.ok() ? Internal("sweep failed without a reason") : r.status;
    }
    const bool cancelled = r.termination == Termination::kCancelled;
    v1::SweepResult out;
    out.set_status(TerminationName(r.termination));
    if (!r.status.ok()) out.set_message(r.status.message());
    for (const SweepPoint& pt : r.up) ToProto(pt, cancelled, out.add_up());
    for (const SweepPoint& pt : r.down) ToProto(pt, cancelled, out.add_down());
    out.set_periods_total(r.periods_total);
    out.set_events_total(r.events_total);
    out.set_engine_version(EngineVersion());
    out.set_wall_seconds(Seconds(start));
    return out;
  } catch (const std::bad_alloc&) {
    return Internal("out of memory while sweeping");
  } catch (const std::exception& e) {
    return Internal(std::string("sweep failed: ") + e.what());
  }
}

StatusOr<v1::ContinueResult> RunContinue(const v1::ContinueRequest& request,
                                         const ProgressCallback& progress,
                                         const ValueCallback& on_value) {
  const auto start = std::chrono::steady_clock::now();
  const Osc& model = Model();
  const Params params = ToEngineParams(request.params());
  if (Status s = model.ValidateParams(params); !s.ok()) return s;
  if (request.param().empty()) {
    return InvalidArgument(
        "param: the continuation parameter must be named (one of a, b, omega, xi, g, phi0)");
  }
  StatusOr<int> index = model.ParamIndex(request.param());
  if (!index.ok()) return InvalidArgument("param: " + index.status().message());
  StatusOr<ContinuationOptions> options = ToContinuationOptions(request);
  if (!options.ok()) return options.status();
  // Both ends must be valid values of the parameter (the branch may run up to them).
  if (Status s = internal::CheckParamValues(params, *index,
                                            {{"min", options->min}, {"max", options->max}});
      !s.ok()) {
    return s;
  }
  const double value = params[*index];
  if (value < options->min || value > options->max) {
    return InvalidArgument("the start value of the continuation parameter, params." +
                           request.param() + " = " + Num(value) + ", is outside [min, max] = [" +
                           Num(options->min) + ", " + Num(options->max) + "]");
  }
  const StatusOr<internal::StartSearch> search = internal::StartSearchOf(request, params);
  if (!search.ok()) return search.status();

  try {
    ExactPropagator propagator(model);
    StatusOr<PeriodicOrbit> orbit =
        StartOrbit(propagator, params, search->x0, search->transient_periods);
    if (!orbit.ok()) return orbit.status();
    // The search for the start orbit is not interruptible; honour a cancel that came meanwhile.
    if (progress && !progress(0.0)) {
      v1::ContinueResult out;
      out.set_status(TerminationName(Termination::kCancelled));
      out.set_message("cancelled before the continuation started");
      out.set_engine_version(EngineVersion());
      out.set_wall_seconds(Seconds(start));
      return out;
    }
    ContinuationCallback callback;
    if (progress || on_value) {
      callback = [&progress, &on_value](const ContinuationPoint& p, double fraction) {
        if (on_value) on_value(p.value);
        return !progress || progress(fraction);
      };
    }
    const ContinuationResult r = Continue(model, propagator, *orbit, *options, callback);
    // A start the engine refuses before the first step (e.g. an orbit that is not admissible) is
    // an error of the request, not a result.
    const StatusCode code = r.summary.status.code();
    if (r.summary.termination == Termination::kFailed && r.points.empty() &&
        (code == StatusCode::kInvalidArgument || code == StatusCode::kFailedPrecondition)) {
      return r.summary.status;
    }
    v1::ContinueResult out = ToProto(r);
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
        orbit2 = SwitchAtPeriodDoubling(model, propagator, sp, request.param());
        if (orbit2.ok()) break;
        tried += (tried.empty() ? "" : "; ") + orbit2.status().message();
      }
      {
        if (!orbit2.ok()) {
          doubled->set_status(TerminationName(Termination::kFailed));
          doubled->set_message(tried.empty() ? orbit2.status().message() : tried);
        } else {
          ContinuationOptions options2 = *options;
          if (orbit2->params[*index] < options2.min || orbit2->params[*index] > options2.max) {
            options2.min = std::min(options2.min, orbit2->params[*index]);
            options2.max = std::max(options2.max, orbit2->params[*index]);
          }
          *doubled = ToProto(Continue(model, propagator, *orbit2, options2, callback));
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
