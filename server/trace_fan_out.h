// StoreTaskRunner: a trace job's tasks (continuation/trace_tasks.h) offered to every worker of
// every process sharing the store, as child jobs.
//
// Each child job costs ~3 ms of store calls (its submit, a claim, the reads of its state and
// result, its delete), about half a task's engine time, so a child holds a batch of consecutive
// tasks (FanOutOptions::batch; jobs/trace_task_job.h) and the trace offers only as many batches
// as other workers take: tasks are gathered into a batch, stored as a QUEUED child of kind
// "trace_task" (in the parent's client and lane, fenced by its run) once it is full, while fewer
// than `budget` batches are open; other tasks are kept and run by the trace itself
// (jobs::LocalTraceTasks, the same results) when it needs them or while it waits. The budget
// grows by one each time another worker ran a stored batch, and shrinks by one each time the
// trace had to claim one itself (no worker took it before the trace needed it): alone, the trace
// stores about one batch in a window; with idle workers, up to window / batch. A task the trace
// needs while its batch is still being gathered is run here, and the batch's others with it
// become kept.
//
// Workers claim children before new top-level jobs (docs/store.md, "Child jobs"). A stored batch
// the trace needs while it is still queued is claimed and run by the trace (its results kept in
// memory: the child completes with an empty result), so a pool whose every worker runs a parent
// still makes progress; a child lost with its worker is taken back by its lease like any job. A
// batch whose tasks were all taken is deleted; one whose tasks were all dropped is cancelled (and
// deleted when that ends it). The parent's end cancels the children still queued or running
// (the store does it).
#ifndef DRILLBIF_SERVER_TRACE_FAN_OUT_H_
#define DRILLBIF_SERVER_TRACE_FAN_OUT_H_

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "drillbif/continuation/trace_tasks.h"
#include "jobs/trace_task_job.h"
#include "server/store/job_store.h"

namespace drillbif::server {

// How a trace fans out.
struct FanOutOptions {
  // Tasks the trace keeps ahead of the one it applies (TraceTaskRunner::window), and the most it
  // stores at once.
  size_t window = 32;
  // Tasks of one child job (1 .. jobs::kMaxTraceTaskBatch; at most the window).
  size_t batch = 4;
  // The lease of a child the parent claims itself (ClaimOptions::lease_ms; 0: none).
  int64_t lease_ms = 0;
  // How often a waiting parent looks at the store for its result or a child to run. 5 ms: a
  // curve task takes ~6 ms on average, and each look is one short read.
  std::chrono::milliseconds poll{5};
};

// Called to run a child the parent claimed, on the parent's thread (the worker pool's run of one
// job: its lease renewed, its outcome recorded): on success, the child is completed with an empty
// result and its result's bytes returned, for the parent to read from memory; else nullopt.
using RunClaimedChild = std::function<std::optional<std::string>(const JobRecord& child)>;

class StoreTaskRunner : public TraceTaskRunner {
 public:
  // `parent` (RUNNING, claimed by `worker_id`), `store` and `local` (the parent's request's
  // tasks) outlive the runner. `submitted` is called after each child is stored (to wake idle
  // workers).
  StoreTaskRunner(JobStore& store, const JobRecord& parent, std::string worker_id,
                  const jobs::LocalTraceTasks& local, const FanOutOptions& options,
                  RunClaimedChild run_child, std::function<void()> submitted);
  ~StoreTaskRunner() override;

  size_t window() const override { return options_.window; }
  StatusOr<int64_t> Submit(const TraceTask& task) override;
  bool Ready(int64_t ticket) override;
  StatusOr<TraceTaskResult> Take(int64_t ticket, const std::function<bool()>& keep_going) override;
  void Drop(int64_t ticket) override;

  // Tasks submitted by the trace; those stored (in batches_stored() child jobs); those of them the
  // trace claimed back itself; those stored that other workers ran.
  int64_t tasks() const { return next_; }
  int64_t stored() const { return stored_; }
  int64_t batches_stored() const { return batches_stored_; }
  int64_t claimed_here() const { return claimed_here_; }
  int64_t run_elsewhere() const { return run_elsewhere_; }
  // Where the trace's time in the runner went: the store's calls, the tasks it ran (kept or
  // claimed), the sleeps between looks. Seconds.
  double store_seconds() const { return store_seconds_; }
  double run_seconds() const { return run_seconds_; }
  double sleep_seconds() const { return sleep_seconds_; }

 private:
  struct Child {
    std::optional<TraceTask> task;          // not stored: kept, or gathered for the next batch
    int64_t batch = -1;                     // its stored batch (a key of batches_); -1: none
    int index = 0;                          // its place in that batch
    std::optional<TraceTaskResult> result;  // computed here, or its batch's result read
  };
  struct Batch {
    std::string id;                                  // the stored child
    std::vector<int64_t> tickets;                    // its tasks', in order
    size_t open = 0;                                 // of them not taken or dropped
    bool finished = false;                           // seen SUCCEEDED, FAILED or CANCELLED
    bool results_in = false;                         // its results handed to its children
    std::chrono::steady_clock::time_point looked{};  // the last look at its state (Ready)
  };
  // Stores the gathered tasks as one child job.
  Status StoreBatch();
  // Reads a stored batch's results once it finished elsewhere: false while it has not.
  StatusOr<bool> CollectResults(Batch& batch);
  // Hands a batch's results (run elsewhere, or claimed and run here) to its open tasks.
  Status HandOut(Batch& batch, std::string_view bytes, bool run_elsewhere);
  // While waiting for another worker: runs the first kept task not run yet, else claims one of
  // the parent's queued children and runs it here. Whether it ran one; an error stops the trace.
  StatusOr<bool> RunOneHere(const std::function<bool()>& keep_going);
  StatusOr<bool> ClaimOneHere();
  StatusOr<TraceTaskResult> TakeStored(int64_t ticket, const std::function<bool()>& keep_going);
  // The trace is done with a stored task: its batch is deleted (or cancelled) with its last.
  void Release(int64_t ticket);
  // A batch's results came in: its budget slot freed, the budget adjusted.
  void Closed(bool run_elsewhere);
  void Forget(const std::string& id);

  JobStore& store_;
  const JobRecord& parent_;
  const std::string worker_id_;
  const jobs::LocalTraceTasks& local_;
  const FanOutOptions options_;
  const size_t batch_size_;   // options_.batch, at most the window
  const size_t max_batches_;  // open at once: window / batch
  const RunClaimedChild run_child_;
  const std::function<void()> submitted_callback_;
  std::map<int64_t, Child> children_;
  std::map<int64_t, Batch> batches_;  // by the first ticket of each
  std::vector<int64_t> gathered_;     // the tasks of the next batch
  size_t budget_ = 2;                 // batches open at once (stored ones, and one gathered)
  size_t open_batches_ = 0;           // stored, results not in, not dropped whole
  int64_t next_ = 0;
  int64_t stored_ = 0, batches_stored_ = 0, claimed_here_ = 0, run_elsewhere_ = 0;
  double store_seconds_ = 0, run_seconds_ = 0, sleep_seconds_ = 0;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_TRACE_FAN_OUT_H_
