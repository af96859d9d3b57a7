// The threads on which TraceCurves (continuation/trace.h) runs its curve tasks, and their
// propagators.
//
// A stage of the trace (the curves from the located starts, switching at codimension-2 points)
// queues its tasks (a curve from one start; the candidates at one codimension-2 point; the
// step-offs and the curve of one candidate) in the order the trace would compute them one after
// the other, and applies each result in that order on the calling thread: the check against the
// curves known so far, the append, the notes. What a task computes depends only on its own
// inputs; a switching task may leave out a run whose curve it finds traced already (applied, or
// by an earlier task's run), which the application computes itself if the curve is still not
// known then. So the result is the same whatever the number of threads and the schedule. A task
// queued while an earlier one runs may turn out to be a duplicate of that one's curve when it is
// applied: it is dropped then (its work wasted, the result unchanged); with one thread each task
// is queued after the one before was applied, so nothing is wasted.
#ifndef DRILLBIF_CONTINUATION_CURVE_TASKS_H_
#define DRILLBIF_CONTINUATION_CURVE_TASKS_H_

#include <atomic>
#include <chrono>
#include <functional>
#include <memory>
#include <utility>
#include <vector>

#include "common/ordered_tasks.h"
#include "drillbif/common/progress.h"
#include "drillbif/flow/propagator.h"

namespace drillbif::internal {

// With one thread, the trace's own propagator (tasks run on the calling thread, under its
// throttle). With more, a clone of it per worker, each polling a throttle of its own that
// Abandon() stops: so that a stop of the trace, or the end of a stage, ends the tasks running
// within a poll interval (kPoll). A worker's computation can also be stopped on its own, once its
// result is no longer needed (UnlessMoot).
class WorkerPropagators {
 public:
  // `threads` (>= 1; the propagator's Clone() returning null means 1).
  WorkerPropagators(Propagator& own, int threads) : own_(own) {
    for (int w = 0; w < threads && threads > 1; ++w) {
      std::unique_ptr<Propagator> clone = own.Clone();
      if (clone == nullptr) {
        clones_.clear();
        break;
      }
      clones_.push_back(std::move(clone));
    }
    moot_.resize(clones_.size());
    mooted_.assign(clones_.size(), 0);
    Resume();
  }
  WorkerPropagators(const WorkerPropagators&) = delete;
  WorkerPropagators& operator=(const WorkerPropagators&) = delete;

  int threads() const { return clones_.empty() ? 1 : static_cast<int>(clones_.size()); }
  Propagator& at(int worker) { return clones_.empty() ? own_ : *clones_[worker]; }

  // Ends the workers' running tasks at their next poll (their results are not to be used).
  void Abandon() { abandon_ = true; }
  // Fresh throttles, not stopped, once no task runs.
  void Resume() {
    abandon_ = false;
    throttles_.resize(clones_.size());
    for (size_t w = 0; w < clones_.size(); ++w) Renew(w);
  }

  // Runs `compute` (on worker `worker`'s thread, on its propagator), whose result is wanted only
  // while `moot()` is false: the propagator's polls (every kPoll) also call `moot` and stop the
  // computation once it holds. False when so stopped: the computation's result is then not to be
  // used, and the propagator is ready for the next one (unless the workers were abandoned
  // meanwhile). With one thread `moot` is never called (the propagator is the trace's own).
  bool UnlessMoot(int worker, std::function<bool()> moot, const std::function<void()>& compute) {
    if (clones_.empty()) {
      compute();
      return true;
    }
    const size_t w = static_cast<size_t>(worker);
    moot_[w] = std::move(moot);
    mooted_[w] = 0;
    compute();
    moot_[w] = nullptr;
    if (mooted_[w] == 0) return true;
    if (!abandon_.load(std::memory_order_relaxed)) Renew(w);
    return false;
  }

 private:
  // The workers' poll interval: a run found moot (UnlessMoot) stops within it. Switching's test
  // costs a few atomic loads unless a curve was applied or recorded ahead since its last look.
  static constexpr std::chrono::milliseconds kPoll{1};

  // Worker w's throttle, fresh (on w's thread, or on the calling thread once no task runs).
  void Renew(size_t w) {
    auto fresh = std::make_unique<ProgressThrottle>(
        [this, w](double) {
          if (abandon_.load(std::memory_order_relaxed)) return false;
          if (moot_[w] && moot_[w]()) {
            mooted_[w] = 1;
            return false;
          }
          return true;
        },
        kPoll);
    clones_[w]->set_progress(fresh.get());
    throttles_[w] = std::move(fresh);
  }

  Propagator& own_;
  std::atomic<bool> abandon_{false};
  // Per worker, read and written on its thread only: the test of the computation running there
  // (UnlessMoot), and whether it stopped it.
  std::vector<std::function<bool()>> moot_;
  std::vector<char> mooted_;
  // Declared before the clones, so destroyed after them: a clone never points to a freed one.
  std::vector<std::unique_ptr<ProgressThrottle>> throttles_;
  std::vector<std::unique_ptr<Propagator>> clones_;
};

// One stage's queue of tasks on the workers. At its end (scope exit) the tasks still running are
// abandoned and waited for, and the workers made ready for the next stage.
template <class Result>
class TaskStage {
 public:
  explicit TaskStage(WorkerPropagators& workers)
      : workers_(workers), tasks_(std::make_unique<OrderedTasks<Result>>(workers.threads())) {}
  ~TaskStage() {
    workers_.Abandon();
    tasks_.reset();
    workers_.Resume();
  }
  TaskStage(const TaskStage&) = delete;
  TaskStage& operator=(const TaskStage&) = delete;

  OrderedTasks<Result>& tasks() { return *tasks_; }
  // How many tasks may be queued and not applied: one with one thread (each task queued after
  // the one before was applied, as a plain loop computes them), else sixteen per worker, so that
  // a long task at the front does not leave the other workers idle. Tasks queued further ahead
  // may find more of their work done by earlier ones, dropped when applied; switching stops such
  // runs early (WorkerPropagators::UnlessMoot). Measured in docs/performance.md, "Runs stopped
  // once known, sixteen tasks per worker, branches beside curves".
  size_t window() const { return workers_.threads() == 1 ? 1 : 16 * workers_.threads(); }

 private:
  WorkerPropagators& workers_;
  std::unique_ptr<OrderedTasks<Result>> tasks_;
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_CURVE_TASKS_H_
