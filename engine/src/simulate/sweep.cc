#include "drillbif/simulate/sweep.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <thread>
#include <utility>

#include "drillbif/common/checked.h"
#include "drillbif/common/threads.h"

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
  if (transient_periods < 0) {
    return InvalidArgument("transient_periods must be >= 0, got " +
                           std::to_string(transient_periods));
  }
  if (sample_periods < 1) {
    return InvalidArgument("sample_periods must be >= 1, got " + std::to_string(sample_periods));
  }
  if (threads < 0) return InvalidArgument("threads must be >= 0 (0: number of cores)");
  if (chunks < 1 || chunks > steps) {
    return InvalidArgument(
        "chunks must be >= 1 (1: every value from the previous one) and <= "
        "steps, got " +
        std::to_string(chunks));
  }
  if (chunk_start_transient_factor < 1) {
    return InvalidArgument("chunk_start_transient_factor must be >= 1");
  }
  // An upper bound of the periods simulated in all, which the 64-bit counters must hold.
  const int directions = direction == SweepDirection::kBoth ? 2 : 1;
  const std::optional<int64_t> per_value =
      CheckedAdd(CheckedMul(int64_t{transient_periods}, int64_t{chunk_start_transient_factor}),
                 std::optional<int64_t>(sample_periods));
  if (!CheckedMul(CheckedMul(per_value, std::optional<int64_t>(steps)),
                  std::optional<int64_t>(directions))) {
    return InvalidArgument(
        "steps, transient_periods, sample_periods, chunk_start_transient_factor: the sweep's "
        "forcing periods in all (steps x directions x (transient x factor + samples)) exceed "
        "2^63 - 1");
  }
  // SweepPieces' count, directions x chunks, without making the pieces: a request's checks stay
  // O(1) whatever its chunks (a fuzzed sweep with 9.7e7 chunks took 22 s and 1.7 GB to be
  // checked).
  const int64_t pieces = int64_t{directions} * chunks;
  if (piece < -1 || piece >= pieces) {
    return InvalidArgument("piece must be -1 (the whole sweep) or in 0 .. " +
                           std::to_string(pieces - 1) + " (directions x chunks pieces), got " +
                           std::to_string(piece));
  }
  return Status::Ok();
}

std::vector<SweepPiece> SweepPieces(const SweepOptions& options) {
  std::vector<SweepPiece> pieces;
  const int n = options.steps;
  const int chunks = options.chunks;
  if (n < 2 || chunks < 1 || chunks > n) return pieces;
  auto add_direction = [&](SweepDirection direction) {
    for (int c = 0; c < chunks; ++c) {
      // 64-bit: c * n overflows int for grids of more than ~46000 values split finely.
      pieces.push_back({direction, static_cast<int>(int64_t{c} * n / chunks),
                        static_cast<int>(int64_t{c + 1} * n / chunks - 1)});
    }
  };
  switch (options.direction) {
    case SweepDirection::kUp:
      add_direction(SweepDirection::kUp);
      break;
    case SweepDirection::kDown:
      add_direction(SweepDirection::kDown);
      break;
    case SweepDirection::kBoth:
      add_direction(SweepDirection::kUp);
      add_direction(SweepDirection::kDown);
      break;
  }
  return pieces;
}

namespace {

// A contiguous run of grid indices swept in one direction by one thread.
struct Piece {
  int direction;    // 0: up, 1: down
  int first, last;  // positions in the direction's list, inclusive
};

// Streaming: hands the values finished by the workers to the calling thread in grid order per
// direction. A value whose predecessors have all been added is ready; the others wait ahead.
// Add() waits while 2 x `capacity` values are held, or, for a value that is not ready, while
// `capacity` wait ahead; a value that becomes ready while its worker waits is admitted as such.
// No deadlock: the first value not yet added of each direction is always being computed or held
// by a worker (pieces are taken in grid order), and it waits only while `capacity` values are
// ready, which the calling thread takes.
class InOrderBuffer {
 public:
  struct Item {
    int direction = 0;
    int index = 0;
    SweepPoint point;
  };

  explicit InOrderBuffer(size_t capacity) : capacity_(capacity) {}

  // Adds a finished value; false (the value dropped) when the sweep was stopped meanwhile.
  bool Add(int direction, int index, SweepPoint&& point) {
    std::unique_lock<std::mutex> lock(mutex_);
    room_.wait(lock, [&] {
      if (stopped_) return true;
      const bool room = ready_ + ahead_ < 2 * capacity_;
      return index == added_[direction] ? room : room && ahead_ < capacity_;
    });
    if (stopped_) return false;
    held_.emplace(std::make_pair(direction, index), std::move(point));
    if (index != added_[direction]) {
      ++ahead_;
      return true;
    }
    // Ready, and every value after it that waited ahead.
    ++ready_;
    ++added_[direction];
    while (held_.count({direction, added_[direction]}) != 0) {
      --ahead_;
      ++ready_;
      ++added_[direction];
    }
    lock.unlock();
    ready_cv_.notify_one();
    room_.notify_all();  // a worker's value may have become ready
    return true;
  }

  // Waits up to `timeout` for ready values; moves them into *out, in order per direction.
  void Take(std::chrono::steady_clock::duration timeout, std::vector<Item>* out) {
    out->clear();
    std::unique_lock<std::mutex> lock(mutex_);
    ready_cv_.wait_for(lock, timeout, [&] { return ready_ > 0 || stopped_; });
    for (int d = 0; d < 2; ++d) {
      while (taken_[d] < added_[d]) {
        auto it = held_.find({d, taken_[d]});
        out->push_back({d, taken_[d], std::move(it->second)});
        held_.erase(it);
        --ready_;
        ++taken_[d];
      }
    }
    lock.unlock();
    if (!out->empty()) room_.notify_all();
  }

  // Before any Add(): the values of `direction` before `index` are not part of this run.
  void StartAt(int direction, int index) {
    std::lock_guard<std::mutex> lock(mutex_);
    added_[direction] = taken_[direction] = index;
  }

  // Wakes and refuses every waiting and later Add().
  void Stop() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      stopped_ = true;
    }
    room_.notify_all();
    ready_cv_.notify_all();
  }

 private:
  const size_t capacity_;
  std::mutex mutex_;
  std::condition_variable room_, ready_cv_;
  std::map<std::pair<int, int>, SweepPoint> held_;  // (direction, index) -> value
  int added_[2] = {0, 0};  // per direction: values 0 .. added_ - 1 are all added
  int taken_[2] = {0, 0};  // per direction: values handed to the calling thread
  size_t ready_ = 0;       // held values with index < added_ (not yet taken)
  size_t ahead_ = 0;       // held values waiting for a predecessor
  bool stopped_ = false;
};

}  // namespace

SweepResult Sweep(const HybridModel& model, const PropagatorFactory& make_propagator,
                  const Params& params, const StateVector& x0, const SweepOptions& options,
                  const ProgressCallback& progress,
                  const std::function<void(double value)>& on_value,
                  const SweepPointCallback& on_point) {
  SweepResult result;
  SweepSummary& sum = result.summary;
  if (Status s = options.Validate(); !s.ok()) {
    sum.Fail(s);
    return result;
  }
  StatusOr<int> index = model.ParamIndex(options.param);
  if (!index.ok()) {
    sum.Fail(Status(StatusCode::kInvalidArgument, index.status().message()));
    return result;
  }
  // Validate the range's ends so that a bad range fails at once, naming the parameter.
  for (double v : {options.min, options.max}) {
    Params p = params;
    p[*index] = v;
    if (Status s = model.ValidateParams(p); !s.ok()) {
      sum.Fail(s);
      return result;
    }
  }
  if (Status s = model.ValidateState(x0, params, SimulationOptions().state_tolerance); !s.ok()) {
    sum.Fail(s);
    return result;
  }

  const int n = options.steps;
  auto value_at = [&](int i) { return options.min + (options.max - options.min) * i / (n - 1); };
  const int threads = ThreadsOrCores(options.threads);
  const bool streaming = static_cast<bool>(on_point);

  std::vector<SweepPoint>* lists[2] = {&result.up, &result.down};
  std::vector<Piece> pieces;
  for (const SweepPiece& p : SweepPieces(options)) {
    pieces.push_back({p.direction == SweepDirection::kUp ? 0 : 1, p.first, p.last});
  }
  if (options.piece >= 0) pieces = {pieces[static_cast<size_t>(options.piece)]};
  // Non-streaming results are stored at (position - offset) of the direction's list.
  int offset[2] = {0, 0};
  if (!streaming) {
    int count[2] = {0, 0};
    for (const Piece& p : pieces) count[p.direction] += p.last - p.first + 1;
    if (options.piece >= 0) offset[pieces[0].direction] = pieces[0].first;
    for (int d = 0; d < 2; ++d) {
      std::vector<SweepPoint>& points = *lists[d];
      points.resize(static_cast<size_t>(count[d]));
      for (int i = 0; i < count[d]; ++i) {
        const int at = i + offset[d];
        points[static_cast<size_t>(i)].value = value_at(d == 0 ? at : n - 1 - at);
      }
    }
  }
  long long total = 0;  // the values to simulate
  for (const Piece& p : pieces) total += p.last - p.first + 1;

  const int n_threads = std::min<int>(threads, static_cast<int>(pieces.size()));
  InOrderBuffer buffer(static_cast<size_t>(n_threads));
  // A piece alone: its direction's values are handed over from its first one.
  if (options.piece >= 0) buffer.StartAt(pieces[0].direction, pieces[0].first);
  std::atomic<bool> cancel{false};
  std::atomic<long long> done{0}, events{0}, periods{0};
  std::atomic<double> last_value{0.0};  // the value of the grid point finished last
  std::atomic<size_t> next_piece{0};
  auto worker = [&] {
    std::unique_ptr<Propagator> prop = make_propagator();
    for (size_t k; (k = next_piece.fetch_add(1)) < pieces.size();) {
      const Piece& piece = pieces[k];
      StateVector x = x0;
      SweepStart start = SweepStart::kFromInitialState;
      for (int i = piece.first; i <= piece.last && !cancel.load(); ++i) {
        SweepPoint pt;
        pt.value = value_at(piece.direction == 0 ? i : n - 1 - i);
        pt.start = start;
        Params p = params;
        p[*index] = pt.value;
        SimulationOptions so;
        // A later chunk's first value stands in for a continued start: the longer transient
        // lets it settle. A direction's first value starts from x0 in the continued sweep too.
        const bool later_chunk_start = i == piece.first && piece.first > 0;
        so.transient_periods = int64_t{options.transient_periods} *
                               (later_chunk_start ? options.chunk_start_transient_factor : 1);
        pt.transient_periods = so.transient_periods;
        so.sample_periods = options.sample_periods;
        so.outputs.measures = false;
        so.outputs.poincare = true;
        // Polled through the simulation's own throttle (~5 ms): the stop flag set by the
        // calling thread ends this value's run there.
        SimulationResult sr =
            Simulate(model, *prop, p, x, so, [&](double) { return !cancel.load(); });
        pt.summary = sr.summary;
        pt.samples = std::move(sr.poincare);
        events += sr.summary.events;
        periods += so.transient_periods + so.sample_periods;
        // Continue from this value's final state; after a failure, from the last good state.
        if (sr.summary.completed()) {
          x = sr.final_state;
          start = SweepStart::kFromPreviousValue;
        } else if (start != SweepStart::kFromInitialState) {
          start = SweepStart::kFromEarlierValue;
        }
        last_value = pt.value;
        ++done;
        if (!streaming) {
          (*lists[piece.direction])[static_cast<size_t>(i - offset[piece.direction])] =
              std::move(pt);
        } else if (!buffer.Add(piece.direction, i, std::move(pt))) {
          break;
        }
      }
    }
  };

  std::vector<std::thread> pool;
  if (progress || streaming) {
    // The calling thread reports progress and hands over the streamed values; the work runs on
    // the pool.
    for (int t = 0; t < n_threads; ++t) pool.emplace_back(worker);
    ProgressThrottle throttle([&](double fraction) {
      if (on_value && done.load() > 0) on_value(last_value.load());
      return !progress || progress(fraction);
    });
    std::vector<InOrderBuffer::Item> ready;
    long long delivered = 0;
    const auto wait = throttle.interval() / 2;
    while ((streaming ? delivered : done.load()) < total) {
      if (streaming) {
        buffer.Take(wait, &ready);
        for (InOrderBuffer::Item& item : ready) {
          ++delivered;
          const SweepDirection d =
              item.direction == 0 ? SweepDirection::kUp : SweepDirection::kDown;
          if (!on_point(d, item.index, std::move(item.point))) {
            throttle.Stop();
            break;
          }
        }
      } else {
        std::this_thread::sleep_for(wait);
      }
      if (!throttle.Continue(static_cast<double>(done.load()) / static_cast<double>(total))) {
        cancel = true;
        buffer.Stop();
        break;
      }
    }
    if (progress && on_value && done.load() > 0) on_value(last_value.load());  // the last one
  } else {
    for (int t = 1; t < n_threads; ++t) pool.emplace_back(worker);
    worker();
  }
  for (std::thread& t : pool) t.join();

  sum.values = done.load();
  sum.events = events.load();
  sum.periods = periods.load();
  if (cancel.load()) {
    sum.Cancel("sweep cancelled");
  } else {
    sum.Complete();
  }
  return result;
}

std::string SweepSummary::BriefReport() const {
  return RunSummary::BriefReport(CountOf(values, "value") + ", " + CountOf(periods, "period") +
                                 ", " + CountOf(events, "event"));
}

}  // namespace drillbif
