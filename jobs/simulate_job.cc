#include "jobs/simulate_job.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <memory>
#include <new>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "drillbif/common/checked.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/version.h"
#include "jobs/item_batcher.h"
#include "jobs/job_common.h"

namespace drillbif::jobs {
namespace {

using internal::Model;
using internal::Num;
using internal::Osc;
using internal::Seconds;
using internal::ToProtoMode;

// ---- cost model (docs/performance.md, "Admission control") -----------------------------------
// Exact propagator: 4.5 us per forcing period at the reference point (100000 periods in 0.45 s);
// motions with more segments per period cost more, hence twice that.
constexpr double kExactSecondsPerPeriod = 1e-5;
// CVODE at its default rtol 1e-10: 1.5 ms per period (1000 periods in 1.56 s), with a margin.
constexpr double kCvodeSecondsPerPeriod = 2e-3;
// Events per forcing period of a typical motion (the reference orbit has 4: impact,
// progression, stick, separation); the run itself stops at the result-size limit if a motion
// has more.
constexpr double kEventsPerPeriod = 8;
// Serialized sizes of the result's items (field tags, varints, doubles): measured on results.
constexpr double kPoincareBytes = 40, kEventBytes = 90, kPeriodModesBytes = 16,
                 kTrajectoryBytes = 55;

void ToProto(const EventRecord& e, v1::Event* out) {
  const GuardSpec& guard = Model().guards(e.from_mode)[e.guard];
  out->set_period(static_cast<int32_t>(e.period));
  out->set_s(e.s);
  out->set_t(e.t);
  out->set_surface(guard.surface);
  out->set_guard(guard.name);
  out->set_from_mode(ToProtoMode(e.from_mode));
  out->set_to_mode(ToProtoMode(e.to_mode));
  out->set_tangential(e.tangential);
  out->set_p(e.x[Osc::kP]);
  out->set_y(e.x[Osc::kY]);
  out->set_q(e.x[Osc::kQ]);
}

void ToProto(int64_t period, const std::vector<int>& modes, v1::PeriodModes* out) {
  out->set_period(static_cast<int32_t>(period));
  for (int mode : modes) out->add_modes(ToProtoMode(mode));
}

void ToProto(const TrajectoryPoint& tp, v1::TrajectoryPoint* out) {
  out->set_t(tp.t);
  out->set_mode(ToProtoMode(tp.mode));
  out->set_p(tp.x[Osc::kP]);
  out->set_y(tp.x[Osc::kY]);
  out->set_q(tp.x[Osc::kQ]);
  out->set_s(tp.x[Osc::kS]);
}

// The result of a run; its outputs are those the engine held (none when they were streamed).
// (Periods fit the proto's int32: admission keeps runs far below 2^31 periods.)
v1::SimulateResult ToProto(const SimulationResult& r, const SimulationOptions& options) {
  v1::SimulateResult out;
  internal::SetRunEnd(r.summary, &out);
  if (r.summary.completed() && options.outputs.measures &&
      static_cast<int>(r.measure_means.size()) > Osc::kPower) {
    out.set_rop(r.measure_means[Osc::kDrift]);
    out.set_power(r.measure_means[Osc::kPower]);
  }
  out.mutable_poincare()->Reserve(static_cast<int>(r.poincare.size()));
  for (const PoincareSample& smp : r.poincare) internal::ToProto(smp, out.add_poincare());
  for (const EventRecord& e : r.events) ToProto(e, out.add_events());
  for (size_t i = 0; i < r.period_modes.size(); ++i) {
    ToProto(options.transient_periods + static_cast<int64_t>(i), r.period_modes[i],
            out.add_period_modes());
  }
  out.mutable_trajectory()->Reserve(static_cast<int>(r.trajectory.size()));
  for (const TrajectoryPoint& tp : r.trajectory) ToProto(tp, out.add_trajectory());
  out.set_segments(r.summary.segments);
  out.set_events_total(r.summary.events);
  out.set_evaluations(r.summary.evaluations);
  out.set_engine_version(EngineVersion());
  return out;
}

// The engine's outputs, as they are produced, to a run's ResultSink: one batcher per field.
class SimulateStream final : public SimulationSink {
 public:
  explicit SimulateStream(ResultSink* sink)
      : poincare_(sink), events_(sink), modes_(sink), trajectory_(sink) {}

  bool OnPoincare(const PoincareSample& sample) override {
    return poincare_.Add(
        [&](v1::SimulateResult* r) { internal::ToProto(sample, r->add_poincare()); });
  }
  bool OnEvent(const EventRecord& event) override {
    return events_.Add([&](v1::SimulateResult* r) { ToProto(event, r->add_events()); });
  }
  bool OnPeriodModes(int64_t period, const std::vector<int>& modes) override {
    return modes_.Add(
        [&](v1::SimulateResult* r) { ToProto(period, modes, r->add_period_modes()); });
  }
  bool OnTrajectoryPoint(const TrajectoryPoint& point) override {
    return trajectory_.Add([&](v1::SimulateResult* r) { ToProto(point, r->add_trajectory()); });
  }

  // Sends what is batched; the sink's first error, if any.
  Status Finish() {
    for (ItemBatcher<v1::SimulateResult>* b : {&poincare_, &events_, &modes_, &trajectory_}) {
      b->Flush();
      DRILLBIF_RETURN_IF_ERROR(b->status());
    }
    return Status::Ok();
  }

 private:
  ItemBatcher<v1::SimulateResult> poincare_, events_, modes_, trajectory_;
};

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

std::unique_ptr<Propagator> SimulatePlan::MakePropagator() const {
  if (cvode) return std::make_unique<CvodePropagator>(Model(), cvode_options);
  return std::make_unique<ExactPropagator>(Model());
}

StatusOr<SimulatePlan> PlanSimulate(const v1::SimulateRequest& request) {
  SimulatePlan plan;
  SimulationOptions& options = plan.options;
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
  DRILLBIF_RETURN_IF_ERROR(options.Validate());
  if (options.sample_periods > kMaxSamplePeriods) {
    return InvalidArgument("sample_periods must be <= " + std::to_string(kMaxSamplePeriods) +
                           ", got " + std::to_string(options.sample_periods));
  }
  plan.params = internal::ToEngineParams(request.params());
  DRILLBIF_RETURN_IF_ERROR(Model().ValidateParams(plan.params));
  plan.x0 = internal::ToEngineState(request.has_initial_state(), request.initial_state());
  DRILLBIF_RETURN_IF_ERROR(Model().ValidateState(plan.x0, plan.params, options.state_tolerance));
  // Trajectory points a run would record: about window length / dt (plus one per segment).
  if (const double dt = options.outputs.trajectory_dt; dt > 0.0) {
    const double window = options.sample_periods * kTwoPi / Model().ForcingFrequency(plan.params);
    const double points = window / dt;
    if (!(points <= static_cast<double>(kMaxTrajectoryPoints))) {
      return InvalidArgument("trajectory_dt = " + Num(dt) + " would record about " +
                             std::to_string(static_cast<long long>(std::min(points, 1e18))) +
                             " trajectory points (at most " + std::to_string(kMaxTrajectoryPoints) +
                             "); raise trajectory_dt or lower sample_periods");
    }
  }
  switch (request.propagator()) {
    case v1::PROPAGATOR_UNSPECIFIED:
    case v1::EXACT:
      break;
    case v1::CVODE:
      plan.cvode = true;
      if (request.has_cvode_rtol()) plan.cvode_options.rtol = request.cvode_rtol();
      if (Status s = plan.cvode_options.Validate(); !s.ok()) {
        return InvalidArgument("cvode_rtol: " + s.message());
      }
      break;
    default:
      return InvalidArgument("propagator: unknown value " + std::to_string(request.propagator()));
  }
  return plan;
}

JobCost SimulateCost(const SimulatePlan& plan) {
  const SimulationOptions& o = plan.options;
  JobCost cost;
  const double periods =
      CountOrInfinity(CheckedAdd(int64_t{o.transient_periods}, int64_t{o.sample_periods}));
  double per_period = kExactSecondsPerPeriod;
  if (plan.cvode) {
    // BDF/Adams work grows like rtol^(-1/order); order ~5.
    per_period =
        kCvodeSecondsPerPeriod * std::max(1.0, std::pow(1e-10 / plan.cvode_options.rtol, 0.2));
  }
  cost.seconds.amount = periods * per_period;
  cost.seconds.driver =
      "request.transient_periods + request.sample_periods = " + Num(periods) + " forcing periods" +
      (plan.cvode
           ? " with the CVODE propagator at request.cvode_rtol = " + Num(plan.cvode_options.rtol)
           : "");
  const double samples = o.sample_periods;
  double bytes = 0;
  std::string outputs;
  const auto add = [&](bool on, double b, const char* name) {
    if (!on) return;
    bytes += b;
    outputs += outputs.empty() ? name : std::string(", ") + name;
  };
  add(o.outputs.poincare, samples * kPoincareBytes, "poincare");
  add(o.outputs.events, samples * kEventsPerPeriod * kEventBytes, "events");
  add(o.outputs.modes, samples * kPeriodModesBytes, "modes");
  if (o.outputs.trajectory_dt > 0) {
    const double points =
        samples * kTwoPi / Model().ForcingFrequency(plan.params) / o.outputs.trajectory_dt;
    add(true, points * kTrajectoryBytes, "trajectory_dt");
    cost.seconds.amount += points * 2e-7;  // evaluating the closed-form flow at each point
  }
  cost.result_bytes.amount = bytes;
  cost.result_bytes.driver = "request.sample_periods = " + std::to_string(o.sample_periods) +
                             " with outputs " + (outputs.empty() ? "measures" : outputs);
  // Streamed runs hold a page of items at a time; the engine's own state is a few kB.
  cost.memory_bytes = {4e6, cost.result_bytes.driver};
  return cost;
}

StatusOr<v1::SimulateResult> RunSimulate(const v1::SimulateRequest& request,
                                         const RunContext& context) {
  const auto start = std::chrono::steady_clock::now();
  DRILLBIF_ASSIGN_OR_RETURN(const SimulatePlan plan, PlanSimulate(request));
  try {
    const std::unique_ptr<Propagator> propagator = plan.MakePropagator();
    SimulationOptions options = plan.options;
    std::optional<SimulateStream> stream;
    if (context.sink != nullptr) options.sink = &stream.emplace(context.sink);
    const SimulationResult r =
        Simulate(Model(), *propagator, plan.params, plan.x0, options, context.progress);
    if (stream) DRILLBIF_RETURN_IF_ERROR(stream->Finish());
    v1::SimulateResult out = ToProto(r, plan.options);
    out.set_wall_seconds(Seconds(start));
    return out;
  } catch (const std::bad_alloc&) {
    return Internal("out of memory while simulating");
  } catch (const std::exception& e) {
    return Internal(std::string("simulation failed: ") + e.what());
  }
}

}  // namespace drillbif::jobs
