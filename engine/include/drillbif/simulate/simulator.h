// Event-driven simulation of a hybrid model with harmonic forcing.
//
// Time is kept as (forcing period index, phase s in [0, 2 pi)): each segment flows at most to the
// next Poincare section s = 2 pi, where s is set to exactly 0 and the period index advances, so the
// forcing phase cannot drift however long the run. Between sections the propagator flows to the
// first guard event; the model's jump map gives the next mode. A run is N transient periods then a
// sampling window of M periods; everything reported (measures, Poincare samples, events, modes,
// trajectory) is of the sampling window, and only what SimulationOutputs asks for is computed.
#ifndef DRILLBIF_SIMULATE_SIMULATOR_H_
#define DRILLBIF_SIMULATE_SIMULATOR_H_

#include <functional>
#include <string>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/flow/propagator.h"
#include "drillbif/model/hybrid_model.h"

namespace drillbif {

// Receives the fraction of work done in [0, 1]; returns false to cancel the run.
using ProgressCallback = std::function<bool(double fraction)>;

// What a simulation reports. Everything is off unless asked, except as defaulted here.
struct SimulationOutputs {
  bool measures = true;        // means of the model's measures (ROP, Pc) over the window
  bool poincare = true;        // the state at each section s = 0 (mod 2 pi) in the window
  bool events = false;         // the event log of the window
  bool modes = false;          // the sequence of modes of each period of the window
  double trajectory_dt = 0.0;  // > 0: states every trajectory_dt in each segment of the window
};

struct SimulationOptions {
  int transient_periods = 500;  // forcing periods simulated and discarded first
  int sample_periods = 100;     // forcing periods of the sampling window
  SimulationOutputs outputs;
  // Tolerance (absolute) of the invariant-set check of the initial state.
  double state_tolerance = 1e-9;
  // More events than this in one forcing period fails the run (chattering, Zeno behaviour).
  int max_events_per_period = 10000;

  Status Validate() const;
};

enum class Termination { kCompleted, kCancelled, kFailed };
const char* TerminationName(Termination t);

struct PoincareSample {
  int period = 0;  // index of the section since the start (1 = the end of the first period)
  int mode = 0;    // the mode the flow is in at the section
  StateVector x;   // state with s = 0
};

struct EventRecord {
  int period = 0;  // forcing period (0-based) in which the event happened
  double s = 0.0;  // forcing phase at the event, in [0, 2 pi)
  double t = 0.0;  // time since the start of the run
  int guard = 0;   // index in the from-mode's guard list
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

struct SimulationResult {
  Termination termination = Termination::kFailed;
  Status status;  // why, when not completed
  // Means over the window: measures[k] / window length (k as in HybridModel::measure_names()).
  std::vector<double> measure_means;
  std::vector<PoincareSample> poincare;
  std::vector<EventRecord> events;
  std::vector<std::vector<int>> period_modes;  // one list per window period, from s = 0
  std::vector<TrajectoryPoint> trajectory;
  StateVector final_state;  // state at the end of the run (s = 0)
  int final_mode = 0;
  // Counters.
  long long segments = 0;
  long long events_total = 0;
  long long evaluations = 0;
};

// Runs a simulation from x0 (phase wrapped into [0, 2 pi)). Invalid parameters, options or an
// initial state outside the invariant set give termination kFailed with INVALID_ARGUMENT.
SimulationResult Simulate(const HybridModel& model, Propagator& propagator, const Params& params,
                          const StateVector& x0, const SimulationOptions& options,
                          const ProgressCallback& progress = {});

// The default initial state: at rest, touching nothing, s = 0 (all zeros for the drifting
// oscillator: the bit sits at the slider with the gap g open).
StateVector DefaultInitialState(const HybridModel& model);

}  // namespace drillbif

#endif  // DRILLBIF_SIMULATE_SIMULATOR_H_
