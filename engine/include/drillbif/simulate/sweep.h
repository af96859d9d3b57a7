// Brute-force bifurcation diagrams: sweep one parameter over a grid, each value starting from the
// last state of the previous one (so coexisting attractors show up as hysteresis between the up and
// down sweeps), N transient periods then M Poincare samples per value.
//
// Parallelism: the up and down sweeps are independent and run on separate threads; within a
// direction every value starts from the previous value's final state, whatever the number of
// threads (a sweep of one direction runs on one thread). Only when asked for (`chunks` > 1) is
// each direction split into contiguous pieces run in parallel, each piece after the first
// starting from the initial state with `chunk_start_transient_factor` times the transient:
// continuity is then broken at the piece boundaries, and a branch that the continued sweep would
// have followed there may be lost. SweepPoint::start says how each value was started.
//
// Pieces: a sweep is a list of independent pieces, direction-major (the up direction's chunks in
// grid order, then the down direction's), each a contiguous run of one direction's grid values
// that starts from x0 (SweepPieces). `piece` >= 0 runs only that piece, with results bit for bit
// those of the same values in the whole sweep: a piece needs nothing from the others, so that
// another process can run it.
//
// Cancellation: the progress callback is called on the calling thread only (about every 5 ms,
// and at every percent of the grid values); when it returns false a shared stop flag ends every
// worker's simulation within its own poll (~5 ms) and the sweep returns CANCELLED with the values
// done so far.
//
// Streaming: with on_point, each grid value's result goes to that callback, on the calling
// thread, in grid order per direction, instead of into SweepResult::up / down (which stay
// empty). Values finished ahead of their turn (another chunk's) wait in a buffer of at most
// 2 x threads values, at most `threads` of them ahead of their turn; a worker whose value does
// not fit waits for room, so at most 3 x threads values are held at any time (one more in each
// worker's hand). A direction split into several chunks then runs them nearly one after another
// (a chunk's values are handed over only after the previous chunk's last): the parallelism left
// is across the two directions.
#ifndef DRILLBIF_SIMULATE_SWEEP_H_
#define DRILLBIF_SIMULATE_SWEEP_H_

#include <cstdint>
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
  int threads = 0;              // worker threads (at most directions x chunks used); 0: cores
  // Pieces each direction is split into, run in parallel, each from x0 (1..steps); 1: continuity.
  int chunks = 1;
  int chunk_start_transient_factor = 4;  // transient multiplier at each later chunk's first value
  int piece = -1;  // -1: the whole sweep; else only SweepPieces(*this)[piece] (0 .. pieces - 1)

  // INVALID_ARGUMENT naming the field; also when the sweep's forcing periods in all (steps x
  // directions x (transient x factor + samples)) do not fit 64 bits.
  Status Validate() const;
};

// One independent piece of a sweep: a contiguous run of one direction's grid values, the first of
// them started from x0.
struct SweepPiece {
  SweepDirection direction = SweepDirection::kUp;  // kUp or kDown
  int first = 0;  // the first value's position in the direction's list (as SweepResult::up/down)
  int last = 0;   // the last value's position, inclusive
};

// The pieces of the whole sweep `options` describes (its `piece` ignored), direction-major: for
// each direction swept (up first), its `chunks` pieces in grid order. Empty when the options'
// steps, chunks or direction are invalid.
std::vector<SweepPiece> SweepPieces(const SweepOptions& options);

// The state a grid value's simulation started from.
enum class SweepStart {
  kNotStarted,         // never reached (the sweep was cancelled before it)
  kFromInitialState,   // x0: a direction's first value, a chunk's first value (or the values
                       // after it while every value of the chunk so far failed)
  kFromPreviousValue,  // the final state of the previous value in the sweep's direction
  kFromEarlierValue,   // the final state of the last earlier value that completed (the values
                       // between it and this one failed)
};

struct SweepPoint {
  double value = 0.0;
  // How this value's simulation ended, and its work; never run (start kNotStarted): kFailed
  // with no message.
  SimulationSummary summary;
  SweepStart start = SweepStart::kNotStarted;  // the state the simulation started from
  int64_t transient_periods = 0;  // forcing periods simulated before the samples; 0 if not run
  std::vector<PoincareSample> samples;
};

// How a sweep ended (common/termination.h) and its work over every value and direction. A sweep
// that starts always completes or is cancelled: single values fail on their own (SweepPoint).
struct SweepSummary : RunSummary {
  int64_t values = 0;   // grid values simulated (each direction's counted)
  int64_t periods = 0;  // forcing periods simulated, transients included
  int64_t events = 0;   // guard events crossed
  // "completed: 2000 values, 1200000 periods, 50000 events" (RunSummary::BriefReport).
  std::string BriefReport() const;
};

// With SweepOptions::piece set, `up` or `down` holds only the piece's values (first .. last of
// its direction's list) and the summary counts only them.
struct SweepResult {
  SweepSummary summary;
  std::vector<SweepPoint> up;    // ascending values, when swept up
  std::vector<SweepPoint> down;  // descending values, when swept down
};

using PropagatorFactory = std::function<std::unique_ptr<Propagator>()>;

// Receives one grid value's result (streaming, see above): its direction (kUp or kDown), its
// position in that direction's list of the whole sweep (0-based; ascending values up, descending
// down, as SweepResult::up / down; a piece's values keep their positions), and the point (value,
// how it ended, its Poincare samples), to keep. Returns false to stop the sweep, which then ends
// CANCELLED.
using SweepPointCallback =
    std::function<bool(SweepDirection direction, int index, SweepPoint&& point)>;

// Runs the sweep. `make_propagator` is called once per worker thread. `progress` is called from
// the calling thread only (see above) and may cancel; just before each such call, `on_value`
// (optional) receives the parameter value of the grid point finished last (by any worker; none
// before the first). `on_point` (optional) streams the values (see above): those not handed
// over when the sweep stops are dropped.
SweepResult Sweep(const HybridModel& model, const PropagatorFactory& make_propagator,
                  const Params& params, const StateVector& x0, const SweepOptions& options,
                  const ProgressCallback& progress = {},
                  const std::function<void(double value)>& on_value = {},
                  const SweepPointCallback& on_point = {});

}  // namespace drillbif

#endif  // DRILLBIF_SIMULATE_SWEEP_H_
