#include "drillbif/simulate/simulator.h"

#include <algorithm>
#include <cmath>

namespace drillbif {

Status SimulationOptions::Validate() const {
  if (transient_periods < 0) {
    return InvalidArgument("transient_periods must be >= 0, got " +
                           std::to_string(transient_periods));
  }
  if (sample_periods < 1) {
    return InvalidArgument("sample_periods must be >= 1, got " + std::to_string(sample_periods));
  }
  if (!(outputs.trajectory_dt >= 0.0) || !std::isfinite(outputs.trajectory_dt)) {
    return InvalidArgument("trajectory_dt must be finite and >= 0 (0: no trajectory)");
  }
  if (!(state_tolerance >= 0.0)) return InvalidArgument("state_tolerance must be >= 0");
  if (max_events_per_period < 1) return InvalidArgument("max_events_per_period must be >= 1");
  return Status::Ok();
}

const char* TerminationName(Termination t) {
  switch (t) {
    case Termination::kCompleted:
      return "COMPLETED";
    case Termination::kCancelled:
      return "CANCELLED";
    case Termination::kFailed:
      return "FAILED";
  }
  return "?";
}

StateVector DefaultInitialState(const HybridModel& model) {
  return StateVector::Zero(model.state_dim());
}

namespace {

SimulationResult Fail(SimulationResult r, Status status) {
  r.termination = Termination::kFailed;
  r.status = std::move(status);
  return r;
}

double WrapPhase(double s) {
  s = std::fmod(s, kTwoPi);
  if (s < 0.0) s += kTwoPi;
  return s >= kTwoPi ? 0.0 : s;
}

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
  const SimulationOutputs& out = options.outputs;
  const int ps = model.phase_index();
  const double omega = model.ForcingFrequency(params);
  const int total = options.transient_periods + options.sample_periods;
  const int n_measures = static_cast<int>(model.measure_names().size());
  MeasureVector sums = MeasureVector::Zero(n_measures);

  StateVector x = x0;
  x[ps] = WrapPhase(x0[ps]);
  const double s_start = x[ps];
  int mode = model.ModeAt(x, params);
  int period = 0;  // sections passed
  int events_this_period = 0;
  const int progress_every = std::max(1, total / 200);
  if (out.modes && options.transient_periods == 0) r.period_modes.push_back({mode});
  // Time since the start, from the period index and the phase (no accumulated rounding).
  auto time_of = [&](int k, double s) { return (kTwoPi * k + s - s_start) / omega; };

  while (period < total) {
    const bool in_window = period >= options.transient_periods;
    AdvanceRequest req;
    req.mode = mode;
    req.x0 = x;
    req.t_max = (kTwoPi - x[ps]) / omega;
    req.measures = in_window && out.measures;
    req.sample_dt = in_window ? out.trajectory_dt : 0.0;
    AdvanceResult adv = propagator.Advance(req, params);
    ++r.segments;
    r.evaluations += adv.evaluations;
    if (adv.end == AdvanceEnd::kFailed) {
      return Fail(std::move(r), Status(adv.status.code(), adv.status.message() + " (period " +
                                                              std::to_string(period) + ")"));
    }
    if (req.measures) sums += adv.measures;
    if (req.sample_dt > 0.0) {
      for (const TrajectorySample& smp : adv.samples) {
        TrajectoryPoint tp{time_of(period, x[ps] + omega * smp.t), mode, smp.x};
        tp.x[ps] = WrapPhase(smp.x[ps]);
        r.trajectory.push_back(std::move(tp));
      }
    }
    x = adv.x;
    // The section is reached when the segment ran to its limit, or an event fell on it.
    const bool at_section = adv.end == AdvanceEnd::kTimeLimit || x[ps] >= kTwoPi;
    if (adv.end == AdvanceEnd::kEvent) {
      const double s_event = std::min(x[ps], std::nextafter(kTwoPi, 0.0));
      Transition tr = model.Jump(mode, adv.guard, x, params);
      ++r.events_total;
      if (in_window && out.events) {
        EventRecord e;
        e.period = period, e.s = s_event, e.t = time_of(period, s_event);
        e.guard = adv.guard, e.from_mode = mode, e.to_mode = tr.next_mode;
        e.tangential = adv.tangential, e.x = x;
        e.x[ps] = s_event;
        r.events.push_back(std::move(e));
      }
      if (in_window && out.modes && tr.next_mode != mode)
        r.period_modes.back().push_back(tr.next_mode);
      mode = tr.next_mode;
      x = tr.x;
      if (++events_this_period > options.max_events_per_period) {
        return Fail(std::move(r),
                    Status(StatusCode::kFailedPrecondition,
                           "more than " + std::to_string(options.max_events_per_period) +
                               " events in forcing period " + std::to_string(period) +
                               " (chattering or Zeno behaviour)"));
      }
    }
    if (at_section) {
      x[ps] = 0.0;  // exactly: the forcing phase never drifts
      ++period;
      events_this_period = 0;
      if (period > options.transient_periods && out.poincare) {
        r.poincare.push_back({period, mode, x});
      }
      if (out.modes && period >= options.transient_periods && period < total) {
        r.period_modes.push_back({mode});
      }
      if (progress && period % progress_every == 0 && !progress(double(period) / total)) {
        r.termination = Termination::kCancelled;
        r.status = Status(StatusCode::kCancelled, "cancelled at period " + std::to_string(period));
        r.final_state = x;
        r.final_mode = mode;
        return r;
      }
    } else {
      x[ps] = std::min(x[ps], std::nextafter(kTwoPi, 0.0));
    }
  }

  if (out.measures) {
    const double window = options.sample_periods * kTwoPi / omega;
    for (int k = 0; k < n_measures; ++k) r.measure_means.push_back(sums[k] / window);
    for (double v : r.measure_means) {
      if (!std::isfinite(v)) return Fail(std::move(r), Internal("a measure is not finite"));
    }
  }
  r.final_state = x;
  r.final_mode = mode;
  r.termination = Termination::kCompleted;
  return r;
}

}  // namespace drillbif
