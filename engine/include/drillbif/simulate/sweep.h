// Brute-force bifurcation diagrams: sweep one parameter over a grid, each value starting from the
// last state of the previous one (so coexisting attractors show up as hysteresis between the up and
// down sweeps), N transient periods then M Poincare samples per value.
//
// Parallelism: the up and down sweeps are independent and run on separate threads; a single
// direction is split into `chunks` contiguous pieces, each starting from the initial state at its
// first value with `chunk_start_transient_factor` times the transient (continuity is only broken
// at chunk boundaries, where the longer transient settles the start).
#ifndef DRILLBIF_SIMULATE_SWEEP_H_
#define DRILLBIF_SIMULATE_SWEEP_H_

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "drillbif/simulate/simulator.h"

namespace drillbif {

enum class SweepDirection { kUp, kDown, kBoth };

struct SweepOptions {
  std::string param;  // name of the swept parameter
  double min = 0.0;   // first value (up sweep)
  double max = 0.0;   // last value (up sweep); > min
  int steps = 1000;   // number of values, endpoints included (>= 2)
  SweepDirection direction = SweepDirection::kUp;
  int transient_periods = 500;  // per value
  int sample_periods = 100;     // Poincare samples per value
  int threads = 0;              // worker threads; 0: the number of cores
  int chunks = 0;               // pieces per direction; 0: threads / directions (at least 1)
  int chunk_start_transient_factor = 4;  // transient multiplier at a chunk's first value

  Status Validate() const;
};

struct SweepPoint {
  double value = 0.0;
  Termination termination = Termination::kFailed;
  std::string message;  // why, when not completed
  std::vector<PoincareSample> samples;
};

struct SweepResult {
  Termination termination = Termination::kFailed;
  Status status;
  std::vector<SweepPoint> up;    // ascending values, when swept up
  std::vector<SweepPoint> down;  // descending values, when swept down
  long long events_total = 0;
  long long periods_total = 0;
};

using PropagatorFactory = std::function<std::unique_ptr<Propagator>()>;

// Runs the sweep. `make_propagator` is called once per worker thread. `progress` is called from
// the calling thread only (about every 10 ms) and may cancel; just before each such call,
// `on_value` (optional) receives the parameter value of the grid point finished last (by any
// worker; none before the first).
SweepResult Sweep(const HybridModel& model, const PropagatorFactory& make_propagator,
                  const Params& params, const StateVector& x0, const SweepOptions& options,
                  const ProgressCallback& progress = {},
                  const std::function<void(double value)>& on_value = {});

}  // namespace drillbif

#endif  // DRILLBIF_SIMULATE_SWEEP_H_
