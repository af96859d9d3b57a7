#include "drillbif/simulate/simulator.h"

#include <algorithm>
#include <cmath>
#include <string>
#include <utility>
#include <vector>

#include "common/phase_progress.h"
#include "drillbif/common/checked.h"

namespace drillbif {

Status SimulationOptions::Validate() const {
  if (transient_periods < 0) {
    return InvalidArgument("transient_periods must be >= 0, got " +
                           std::to_string(transient_periods));
  }
  if (sample_periods < 1) {
    return InvalidArgument("sample_periods must be >= 1, got " + std::to_string(sample_periods));
  }
  if (!CheckedAdd(transient_periods, sample_periods)) {
    return InvalidArgument("transient_periods + sample_periods must be <= 2^63 - 1, got " +
                           std::to_string(transient_periods) + " + " +
                           std::to_string(sample_periods));
  }
  if (!(outputs.trajectory_dt >= 0.0) || !std::isfinite(outputs.trajectory_dt)) {
    return InvalidArgument("trajectory_dt must be finite and >= 0 (0: no trajectory)");
  }
  if (!(state_tolerance >= 0.0)) return InvalidArgument("state_tolerance must be >= 0");
  if (max_events_per_period < 1) return InvalidArgument("max_events_per_period must be >= 1");
  return Status::Ok();
}

std::string SimulationSummary::BriefReport() const {
  return RunSummary::BriefReport(CountOf(segments, "segment") + ", " + CountOf(events, "event") +
                                 ", " + CountOf(evaluations, "evaluation"));
}

StateVector DefaultInitialState(const HybridModel& model) {
  return StateVector::Zero(model.state_dim());
}

namespace {

SimulationResult Fail(SimulationResult r, Status status) {
  r.summary.Fail(std::move(status));
  return r;
}

double WrapPhase(double s) {
  s = std::fmod(s, kTwoPi);
  if (s < 0.0) s += kTwoPi;
  return s >= kTwoPi ? 0.0 : s;
}

}  // namespace

namespace {

// The outputs of a run, into the result's vectors or to the sink (SimulationOptions::sink).
class Outputs {
 public:
  Outputs(SimulationSink* sink, SimulationResult* result) : sink_(sink), r_(*result) {}

  // Each false when the sink asks to stop.
  bool Poincare(PoincareSample sample) {
    if (sink_ != nullptr) return sink_->OnPoincare(sample);
    r_.poincare.push_back(std::move(sample));
    return true;
  }
  bool Event(EventRecord event) {
    if (sink_ != nullptr) return sink_->OnEvent(event);
    r_.events.push_back(std::move(event));
    return true;
  }
  bool Trajectory(TrajectoryPoint point) {
    if (sink_ != nullptr) return sink_->OnTrajectoryPoint(point);
    r_.trajectory.push_back(std::move(point));
    return true;
  }
  // Starts the mode list of forcing period `period`, handing the last one to the sink.
  bool BeginPeriod(int64_t period, int mode) {
    const bool go_on = EndPeriod();
    if (sink_ == nullptr) {
      r_.period_modes.push_back({mode});
    } else {
      modes_.assign(1, mode);
      modes_period_ = period;
      open_ = true;
    }
    return go_on;
  }
  void AddMode(int mode) { (sink_ != nullptr ? modes_ : r_.period_modes.back()).push_back(mode); }
  // Hands the open mode list to the sink (with no sink, it is in the result already).
  bool EndPeriod() {
    if (!open_) return true;
    open_ = false;
    return sink_->OnPeriodModes(modes_period_, modes_);
  }

 private:
  SimulationSink* sink_;
  SimulationResult& r_;
  std::vector<int> modes_;  // with a sink: the open period's modes
  int64_t modes_period_ = 0;
  bool open_ = false;
};

}  // namespace

SimulationResult Simulate(const HybridModel& model, Propagator& propagator, const Params& params,
                          const StateVector& x0, const SimulationOptions& options,
                          const ProgressCallback& progress) {
  SimulationResult r;
  if (Status s = options.Validate(); !s.ok()) return Fail(std::move(r), s);
  if (Status s = model.ValidateParams(params); !s.ok()) return Fail(std::move(r), s);
  if (Status s = model.ValidateState(x0, params, options.state_tolerance); !s.ok()) {
    return Fail(std::move(r), s);
  }
  // Our own callback, or the one of the computation that runs us (through the propagator).
  internal::PhaseProgress phase(propagator, progress);
  const SimulationOutputs& out = options.outputs;
  Outputs emit(options.sink, &r);
  const int ps = model.phase_index();
  const double omega = model.ForcingFrequency(params);
  const int64_t transient = options.transient_periods;
  const int64_t total = transient + options.sample_periods;  // no overflow: Validate
  const int n_measures = static_cast<int>(model.measure_names().size());
  MeasureVector sums = MeasureVector::Zero(n_measures);

  StateVector x = x0;
  x[ps] = WrapPhase(x0[ps]);
  const double s_start = x[ps];
  int mode = model.ModeAt(x, params);
  int64_t period = 0;  // sections passed
  int events_this_period = 0;
  // Time since the start, from the period index and the phase (no accumulated rounding).
  auto time_of = [&](int64_t k, double s) {
    return (kTwoPi * static_cast<double>(k) + s - s_start) / omega;
  };
  // Ends the run CANCELLED where it stands; the open mode list goes to the sink unless the sink
  // itself stopped the run.
  auto stop = [&](const std::string& why, bool flush) {
    if (flush) static_cast<void>(emit.EndPeriod());
    r.summary.Cancel(why + " at period " + std::to_string(period));
    r.final_state = x;
    r.final_mode = mode;
    return std::move(r);
  };
  auto fail = [&](Status status) {
    static_cast<void>(emit.EndPeriod());
    return Fail(std::move(r), std::move(status));
  };
  if (out.modes && transient == 0 && !emit.BeginPeriod(0, mode)) return stop("stopped", false);

  while (period < total) {
    const bool in_window = period >= transient;
    AdvanceRequest req;
    req.mode = mode;
    req.x0 = x;
    req.t_max = (kTwoPi - x[ps]) / omega;
    req.measures = in_window && out.measures;
    req.sample_dt = in_window ? out.trajectory_dt : 0.0;
    AdvanceResult adv = propagator.Advance(req, params);
    ++r.summary.segments;
    r.summary.evaluations += adv.evaluations;
    if (adv.end == AdvanceEnd::kFailed) {
      if (adv.status.code() == StatusCode::kCancelled || propagator.stopped()) {
        return stop("cancelled", true);
      }
      return fail(Status(adv.status.code(),
                         adv.status.message() + " (period " + std::to_string(period) + ")"));
    }
    if (req.measures) sums += adv.measures;
    if (req.sample_dt > 0.0) {
      for (const TrajectorySample& smp : adv.samples) {
        TrajectoryPoint tp{time_of(period, x[ps] + omega * smp.t), mode, smp.x};
        tp.x[ps] = WrapPhase(smp.x[ps]);
        if (!emit.Trajectory(std::move(tp))) return stop("stopped by the sink", false);
      }
    }
    x = adv.x;
    // The section is reached when the segment ran to its limit, or an event fell on it.
    const bool at_section = adv.end == AdvanceEnd::kTimeLimit || x[ps] >= kTwoPi;
    if (adv.end == AdvanceEnd::kEvent) {
      const double s_event = std::min(x[ps], std::nextafter(kTwoPi, 0.0));
      Transition tr = model.Jump(mode, adv.guard, x, params);
      ++r.summary.events;
      if (in_window && out.events) {
        EventRecord e;
        e.period = period, e.s = s_event, e.t = time_of(period, s_event);
        e.guard = adv.guard, e.from_mode = mode, e.to_mode = tr.next_mode;
        e.tangential = adv.tangential, e.x = x;
        e.x[ps] = s_event;
        if (!emit.Event(std::move(e))) return stop("stopped by the sink", false);
      }
      if (in_window && out.modes && tr.next_mode != mode) emit.AddMode(tr.next_mode);
      mode = tr.next_mode;
      x = tr.x;
      if (++events_this_period > options.max_events_per_period) {
        return fail(Status(StatusCode::kFailedPrecondition,
                           "more than " + std::to_string(options.max_events_per_period) +
                               " events in forcing period " + std::to_string(period) +
                               " (chattering or Zeno behaviour)"));
      }
    }
    if (at_section) {
      x[ps] = 0.0;  // exactly: the forcing phase never drifts
      ++period;
      events_this_period = 0;
      // The period that ended here, then the sample at its end, then the next period.
      if (!emit.EndPeriod()) return stop("stopped by the sink", false);
      if (period > transient && out.poincare && !emit.Poincare({period, mode, x})) {
        return stop("stopped by the sink", false);
      }
      if (out.modes && period >= transient && period < total && !emit.BeginPeriod(period, mode)) {
        return stop("stopped by the sink", false);
      }
      if (!phase.Tick(static_cast<double>(period) / static_cast<double>(total))) {
        return stop("cancelled", true);
      }
    } else {
      x[ps] = std::min(x[ps], std::nextafter(kTwoPi, 0.0));
    }
  }
  if (!emit.EndPeriod()) return stop("stopped by the sink", false);

  if (out.measures) {
    const double window = static_cast<double>(options.sample_periods) * kTwoPi / omega;
    for (int k = 0; k < n_measures; ++k) r.measure_means.push_back(sums[k] / window);
    for (double v : r.measure_means) {
      if (!std::isfinite(v)) return Fail(std::move(r), Internal("a measure is not finite"));
    }
  }
  r.final_state = x;
  r.final_mode = mode;
  r.summary.Complete();
  return r;
}

}  // namespace drillbif
