#include "drillbif/simulate/sweep.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <functional>
#include <thread>

namespace drillbif {

Status SweepOptions::Validate() const {
  if (param.empty()) return InvalidArgument("param: the swept parameter must be named");
  if (!std::isfinite(min) || !std::isfinite(max)) {
    return InvalidArgument("min and max must be finite");
  }
  if (!(max > min)) {
    return InvalidArgument("max must be > min (got min = " + std::to_string(min) +
                           ", max = " + std::to_string(max) + ")");
  }
  if (steps < 2) return InvalidArgument("steps must be >= 2, got " + std::to_string(steps));
  if (transient_periods < 0) return InvalidArgument("transient must be >= 0");
  if (sample_periods < 1) return InvalidArgument("samples must be >= 1");
  if (threads < 0) return InvalidArgument("threads must be >= 0 (0: number of cores)");
  if (chunks < 0) return InvalidArgument("chunks must be >= 0 (0: automatic)");
  if (chunk_start_transient_factor < 1) {
    return InvalidArgument("chunk_start_transient_factor must be >= 1");
  }
  return Status::Ok();
}

namespace {

// A contiguous run of grid indices swept in one direction by one thread.
struct Piece {
  std::vector<SweepPoint>* points;  // the direction's result, pre-sized
  int first, last;                  // positions in `points`, inclusive
};

}  // namespace

SweepResult Sweep(const HybridModel& model, const PropagatorFactory& make_propagator,
                  const Params& params, const StateVector& x0, const SweepOptions& options,
                  const ProgressCallback& progress,
                  const std::function<void(double value)>& on_value) {
  SweepResult result;
  if (Status s = options.Validate(); !s.ok()) {
    result.status = s;
    return result;
  }
  StatusOr<int> index = model.ParamIndex(options.param);
  if (!index.ok()) {
    result.status = Status(StatusCode::kInvalidArgument, index.status().message());
    return result;
  }
  // Validate the range's ends so that a bad range fails at once, naming the parameter.
  for (double v : {options.min, options.max}) {
    Params p = params;
    p[*index] = v;
    if (Status s = model.ValidateParams(p); !s.ok()) {
      result.status = s;
      return result;
    }
  }
  if (Status s = model.ValidateState(x0, params, SimulationOptions().state_tolerance); !s.ok()) {
    result.status = s;
    return result;
  }

  const int n = options.steps;
  auto value_at = [&](int i) { return options.min + (options.max - options.min) * i / (n - 1); };
  const bool up = options.direction != SweepDirection::kDown;
  const bool down = options.direction != SweepDirection::kUp;
  const int directions = (up ? 1 : 0) + (down ? 1 : 0);
  const int threads =
      options.threads > 0 ? options.threads : std::max(1u, std::thread::hardware_concurrency());
  const int chunks =
      std::clamp(options.chunks > 0 ? options.chunks : std::max(1, threads / directions), 1, n);

  std::vector<Piece> pieces;
  auto add_direction = [&](std::vector<SweepPoint>* points, bool ascending) {
    points->resize(n);
    for (int i = 0; i < n; ++i) (*points)[i].value = value_at(ascending ? i : n - 1 - i);
    for (int c = 0; c < chunks; ++c) {
      pieces.push_back({points, c * n / chunks, (c + 1) * n / chunks - 1});
    }
  };
  if (up) add_direction(&result.up, true);
  if (down) add_direction(&result.down, false);

  std::atomic<bool> cancel{false};
  std::atomic<long long> done{0}, events{0}, periods{0};
  std::atomic<double> last_value{0.0};  // the value of the grid point finished last
  std::atomic<size_t> next_piece{0};
  auto worker = [&] {
    std::unique_ptr<Propagator> prop = make_propagator();
    for (size_t k; (k = next_piece.fetch_add(1)) < pieces.size();) {
      const Piece& piece = pieces[k];
      StateVector x = x0;
      for (int i = piece.first; i <= piece.last && !cancel.load(); ++i) {
        SweepPoint& pt = (*piece.points)[i];
        Params p = params;
        p[*index] = pt.value;
        SimulationOptions so;
        so.transient_periods = options.transient_periods *
                               (i == piece.first ? options.chunk_start_transient_factor : 1);
        so.sample_periods = options.sample_periods;
        so.outputs.measures = false;
        so.outputs.poincare = true;
        SimulationResult sr =
            Simulate(model, *prop, p, x, so, [&](double) { return !cancel.load(); });
        pt.termination = sr.termination;
        pt.message = sr.status.ok() ? "" : sr.status.message();
        pt.samples = std::move(sr.poincare);
        events += sr.events_total;
        periods += so.transient_periods + so.sample_periods;
        // Continue from this value's final state; after a failure, from the last good state.
        if (sr.termination == Termination::kCompleted) x = sr.final_state;
        last_value = pt.value;
        ++done;
      }
    }
  };

  const int n_threads = std::min<int>(threads, static_cast<int>(pieces.size()));
  std::vector<std::thread> pool;
  for (int t = 1; t < n_threads; ++t) pool.emplace_back(worker);
  if (progress) {
    // The calling thread reports progress; the work runs on the pool plus one more thread. It
    // asks every 10 ms, so that a cancel reaches the workers within that (the service promises
    // 100 ms from the cancel to the job's end; the callback itself is cheap, and whoever shows
    // progress throttles its own output).
    pool.emplace_back(worker);
    const double total = static_cast<double>(n) * directions;
    while (done.load() < total) {
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
      if (on_value && done.load() > 0) on_value(last_value.load());
      if (!progress(done.load() / total)) {
        cancel = true;
        break;
      }
    }
    if (on_value && done.load() > 0) on_value(last_value.load());  // the last one, too
  } else {
    worker();
  }
  for (std::thread& t : pool) t.join();

  result.events_total = events.load();
  result.periods_total = periods.load();
  if (cancel.load()) {
    result.termination = Termination::kCancelled;
    result.status = Status(StatusCode::kCancelled, "sweep cancelled");
  } else {
    result.termination = Termination::kCompleted;
  }
  return result;
}

}  // namespace drillbif
