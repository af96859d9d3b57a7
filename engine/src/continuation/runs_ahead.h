// The curves that a switching round's runs (SwitchAtCodim2, continuation/codim2_switch.cc) have
// traced and the round has not applied yet, which later tasks check their candidates against.
#ifndef DRILLBIF_CONTINUATION_RUNS_AHEAD_H_
#define DRILLBIF_CONTINUATION_RUNS_AHEAD_H_

#include <algorithm>
#include <atomic>
#include <cstddef>
#include <mutex>
#include <utility>
#include <vector>

#include "continuation/trace_internal.h"
#include "drillbif/continuation/trace_tasks.h"

namespace drillbif::internal {

// The curves traced by the runs of a switching round's tasks whose items are not applied yet,
// each with its item's place in the queue. A task skips a candidate whose curve an earlier item's
// run traced already: when applied, that candidate is known (the earlier curve appended), or its
// run is computed then, on the calling thread; either way the result is the same as a plain
// loop's. In the reference box on two threads this skips ~70 of the ~100 runs that were traced
// twice, once from either end of a curve (the run from the later end is dropped when applied).
class RunsAhead {
 public:
  // The curves a run of item `item` traced (its tries that did not fail).
  void Add(size_t item, const CandidateRun& run) {
    for (const auto& [seed, curve] : run.tries) {
      if (curve.summary.termination == Termination::kFailed || curve.points.empty()) continue;
      TracedCurve outline;  // what switching's check reads: the kind, outline, codimension-2 points
      outline.curve.kind = curve.kind;
      outline.curve.codim2 = curve.codim2;
      outline.outline = OutlineOf(curve);
      std::lock_guard<std::mutex> lock(mutex_);
      curves_.emplace_back(item, std::move(outline));
      added_.fetch_add(1, std::memory_order_release);
    }
  }
  // How many curves were recorded so far (a later look needs AnyBefore again only if this grew).
  size_t added() const { return added_.load(std::memory_order_acquire); }
  // Whether `known` holds for a curve of an item before `item`.
  template <class Known>
  bool AnyBefore(size_t item, const Known& known) const {
    std::lock_guard<std::mutex> lock(mutex_);
    return std::any_of(curves_.begin(), curves_.end(),
                       [&](const auto& c) { return c.first < item && known(c.second); });
  }
  // Forgets the curves of the items up to `item`, applied now.
  void Applied(size_t item) {
    std::lock_guard<std::mutex> lock(mutex_);
    curves_.erase(std::remove_if(curves_.begin(), curves_.end(),
                                 [&](const auto& c) { return c.first <= item; }),
                  curves_.end());
  }

 private:
  mutable std::mutex mutex_;
  std::vector<std::pair<size_t, TracedCurve>> curves_;
  std::atomic<size_t> added_{0};
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_RUNS_AHEAD_H_
