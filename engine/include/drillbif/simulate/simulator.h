// Event-driven simulation of a hybrid model with harmonic forcing.
//
// Time is kept as (forcing period index, phase s in [0, 2 pi)): each segment flows at most to the
// next Poincare section s = 2 pi, where s is set to exactly 0 and the period index advances, so the
// forcing phase cannot drift however long the run. Between sections the propagator flows to the
// first guard event; the model's jump map gives the next mode. A run is N transient periods then a
// sampling window of M periods; everything reported (measures, Poincare samples, events, modes,
// trajectory) is of the sampling window, and only what SimulationOutputs asks for is computed.
// Outputs are accumulated in the SimulationResult, or streamed to a SimulationSink.
//
// Cancellation: the progress callback (common/progress.h) is called through a ProgressThrottle
// (about every 5 ms, and at every percent of the periods); returning false ends the run
// CANCELLED within one segment. Without a callback the run polls the throttle its propagator
// carries (an outer computation's, see flow/propagator.h), if any.
#ifndef DRILLBIF_SIMULATE_SIMULATOR_H_
#define DRILLBIF_SIMULATE_SIMULATOR_H_

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "drillbif/common/progress.h"
#include "drillbif/common/status.h"
#include "drillbif/common/termination.h"
#include "drillbif/flow/propagator.h"
#include "drillbif/model/hybrid_model.h"

namespace drillbif {

class SimulationSink;

// What a simulation reports. Everything is off unless asked, except as defaulted here.
struct SimulationOutputs {
  bool measures = true;        // means of the model's measures (ROP, Pc) over the window
  bool poincare = true;        // the state at each section s = 0 (mod 2 pi) in the window
  bool events = false;         // the event log of the window
  bool modes = false;          // the sequence of modes of each period of the window
  double trajectory_dt = 0.0;  // > 0: states every trajectory_dt in each segment of the window
};

struct SimulationOptions {
  // Forcing periods simulated and discarded first (>= 0). 64-bit, as every period count here:
  // a run of 2^31 periods and more is honoured (cancel it through the progress callback).
  int64_t transient_periods = 500;
  int64_t sample_periods = 100;  // forcing periods of the sampling window (>= 1)
  SimulationOutputs outputs;
  // Tolerance (absolute) of the invariant-set check of the initial state.
  double state_tolerance = 1e-9;
  // More events than this in one forcing period fails the run (chattering, Zeno behaviour).
  int max_events_per_period = 10000;
  // Not null: the outputs go to this sink as they are produced, and SimulationResult's
  // poincare, events, period_modes and trajectory stay empty. Not owned; outlives the run.
  SimulationSink* sink = nullptr;

  // INVALID_ARGUMENT naming the field: negative counts, transient_periods + sample_periods
  // beyond 2^63 - 1, a trajectory_dt or state_tolerance that is not a finite value >= 0.
  Status Validate() const;
};

struct PoincareSample {
  int64_t period = 0;  // index of the section since the start (1 = the end of the first period)
  int mode = 0;        // the mode the flow is in at the section
  StateVector x;       // state with s = 0
};

struct EventRecord {
  int64_t period = 0;  // forcing period (0-based) in which the event happened
  double s = 0.0;      // forcing phase at the event, in [0, 2 pi)
  double t = 0.0;      // time since the start of the run
  int guard = 0;       // index in the from-mode's guard list
  int from_mode = 0;
  int to_mode = 0;
  bool tangential = false;  // a grazing contact rather than a transversal crossing
  StateVector x;
};

struct TrajectoryPoint {
  double t = 0.0;  // time since the start of the run
  int mode = 0;
  StateVector x;  // s wrapped to [0, 2 pi)
};

// How a simulation ended (common/termination.h) and its work, transient included.
struct SimulationSummary : RunSummary {
  int64_t segments = 0;     // flows to the next guard event or Poincare section
  int64_t events = 0;       // guard events crossed
  int64_t evaluations = 0;  // right-hand-side evaluations by the propagator
  // "completed: 1200 segments, 800 events, 96000 evaluations" (RunSummary::BriefReport).
  std::string BriefReport() const;
};

struct SimulationResult {
  // Completed, cancelled (the outputs up to the stop) or failed (the message says why).
  SimulationSummary summary;
  // Means over the window: measures[k] / window length (k as in HybridModel::measure_names()).
  std::vector<double> measure_means;
  std::vector<PoincareSample> poincare;
  std::vector<EventRecord> events;
  std::vector<std::vector<int>> period_modes;  // one list per window period, from s = 0
  std::vector<TrajectoryPoint> trajectory;
  StateVector final_state;  // state at the end of the run (s = 0)
  int final_mode = 0;
};

// Receives a simulation's outputs as they are produced (SimulationOptions::sink), instead of
// SimulationResult's vectors: a run's memory then does not grow with its periods. Only the
// outputs SimulationOutputs asks for are produced, in the order the accumulating run stores them,
// equal to its entries bit for bit. Every method returns false to stop the run, which then ends
// CANCELLED (as when the progress callback returns false) and calls the sink no more. Called on
// the simulating thread.
class SimulationSink {
 public:
  virtual ~SimulationSink() = default;
  // The state at a Poincare section of the window (SimulationResult::poincare).
  virtual bool OnPoincare(const PoincareSample& /*sample*/) { return true; }
  // An event of the window (SimulationResult::events).
  virtual bool OnEvent(const EventRecord& /*event*/) { return true; }
  // The modes of forcing period `period` (0-based from the run's start, as EventRecord::period)
  // of the window, from s = 0 (an entry of SimulationResult::period_modes): called when the
  // period ends (before the Poincare sample at its end), and at the end of a run that stops or
  // fails inside a period with the modes so far (as period_modes holds them then; not after the
  // sink itself asked to stop).
  virtual bool OnPeriodModes(int64_t /*period*/, const std::vector<int>& /*modes*/) { return true; }
  // A trajectory sample of the window (SimulationResult::trajectory).
  virtual bool OnTrajectoryPoint(const TrajectoryPoint& /*point*/) { return true; }
};

// Runs a simulation from x0 (phase wrapped into [0, 2 pi)). Invalid parameters, options or an
// initial state outside the invariant set give summary.termination kFailed with INVALID_ARGUMENT.
// `progress` (may be empty) can stop the run: termination kCancelled, status CANCELLED, the
// outputs up to there, final_state / final_mode where it stopped (at a section or a segment's
// start), no measure_means.
SimulationResult Simulate(const HybridModel& model, Propagator& propagator, const Params& params,
                          const StateVector& x0, const SimulationOptions& options,
                          const ProgressCallback& progress = {});

// The default initial state: at rest, touching nothing, s = 0 (all zeros for the drifting
// oscillator: the bit sits at the slider with the gap g open).
StateVector DefaultInitialState(const HybridModel& model);

}  // namespace drillbif

#endif  // DRILLBIF_SIMULATE_SIMULATOR_H_
