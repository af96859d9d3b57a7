// Progress reports and cancellation of long computations.
//
// A computation reports the fraction of its work done to a ProgressCallback, which can stop it by
// returning false. The callback is called from the computation's own thread, through a
// ProgressThrottle: often enough that a stop is seen within a few milliseconds (the service
// promises 100 ms from a cancel to a job's end), rarely enough that the callback costs nothing
// measurable (a progress record, an atomic load).
#ifndef DRILLBIF_COMMON_PROGRESS_H_
#define DRILLBIF_COMMON_PROGRESS_H_

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <functional>
#include <utility>

namespace drillbif {

// Receives the fraction of work done in [0, 1]; returns false to stop the computation.
using ProgressCallback = std::function<bool(double fraction)>;

// Calls a ProgressCallback at a bounded rate from a computation's loops, and remembers a stop.
//
// The callback is called when `interval` has passed since its last call (or since construction),
// and also whenever the fraction reaches the next multiple of `fraction_step` (so that a run
// shorter than the interval still reports, at most 1 / fraction_step times). Once it has returned
// false the throttle is stopped for good: it is not called again and every poll returns false.
//
// Continue() reads the clock at every call (~25 ns): for loops whose iterations take ~10 us or
// more. Tick() reads it every kTickStride-th call only: for loops of ~1 us iterations (a
// propagator's segments, an integrator's right-hand sides). Not thread-safe: one thread polls.
class ProgressThrottle {
 public:
  using Clock = std::chrono::steady_clock;
  // 5 ms: well inside the 10-20 ms a caller may wait for a poll, so that a stop is seen within
  // ~5 ms (plus one iteration), and over the ~1 ms below which calls would start to cost.
  static constexpr Clock::duration kDefaultInterval = std::chrono::milliseconds(5);
  // One percent: a progress bar moves smoothly on short runs; at most 100 extra calls per run.
  static constexpr double kDefaultFractionStep = 0.01;
  // Tick() reads the clock every 16 calls: 16 iterations of ~1 us between reads, ~0.1% of them.
  static constexpr int kTickStride = 16;

  // An empty callback: never stopped unless Stop() is called, and the clock is never read.
  explicit ProgressThrottle(ProgressCallback callback = {},
                            Clock::duration interval = kDefaultInterval,
                            double fraction_step = kDefaultFractionStep)
      : callback_(std::move(callback)),
        interval_(interval),
        fraction_step_(fraction_step > 0.0 ? fraction_step : 0.0),
        next_step_(fraction_step_ > 0.0 ? fraction_step_ : 2.0),
        last_call_(callback_ ? Clock::now() : Clock::time_point()) {}
  ProgressThrottle(const ProgressThrottle&) = delete;
  ProgressThrottle& operator=(const ProgressThrottle&) = delete;

  // Records `fraction` (clamped to [0, 1]; a NaN or a value below the last is ignored, so the
  // reported fraction never goes back) and calls the callback when it is due. False once stopped.
  bool Continue(double fraction) {
    Record(fraction);
    return Poll(/*read_clock=*/true);
  }
  // Continue() with the fraction last recorded, for inner loops that do not know it.
  bool Continue() { return Poll(/*read_clock=*/true); }

  // As Continue(), reading the clock only every kTickStride-th call.
  bool Tick(double fraction) {
    Record(fraction);
    return Poll(++ticks_ % kTickStride == 0);
  }
  bool Tick() { return Poll(++ticks_ % kTickStride == 0); }

  // Stops without calling the callback (e.g. a consumer of streamed results asked to stop).
  void Stop() { stopped_ = true; }
  // Whether a stop was seen: the callback returned false, or Stop() was called.
  bool stopped() const { return stopped_; }
  // The fraction last recorded, in [0, 1].
  double fraction() const { return fraction_; }
  // How often the callback has been called.
  int64_t calls() const { return calls_; }
  Clock::duration interval() const { return interval_; }

 private:
  void Record(double fraction) {
    if (fraction > fraction_) fraction_ = std::min(fraction, 1.0);  // false for NaN
  }

  bool Poll(bool read_clock) {
    if (stopped_) return false;
    if (!callback_) return true;
    // (The steps are compared to 1e-12, so that i / n reaches the multiples of 1 / n.)
    const bool due =
        fraction_ >= next_step_ - 1e-12 || (read_clock && Clock::now() - last_call_ >= interval_);
    if (!due) return true;
    ++calls_;
    stopped_ = !callback_(fraction_);
    // From the call's end: a slow callback does not make the next one due at once.
    last_call_ = Clock::now();
    if (fraction_step_ > 0.0) {
      next_step_ = (std::floor(fraction_ / fraction_step_ + 1e-9) + 1.0) * fraction_step_;
    }
    return !stopped_;
  }

  ProgressCallback callback_;
  Clock::duration interval_;
  double fraction_step_;
  double next_step_;  // the fraction at which the next call is due regardless of the clock
  Clock::time_point last_call_;
  double fraction_ = 0.0;
  int64_t calls_ = 0;
  uint32_t ticks_ = 0;
  bool stopped_ = false;
};

}  // namespace drillbif

#endif  // DRILLBIF_COMMON_PROGRESS_H_
