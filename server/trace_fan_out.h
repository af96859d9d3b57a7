// StoreTaskRunner: a trace job's tasks (continuation/trace_tasks.h) offered to every worker of
// every process sharing the store, as child jobs.
//
// Each task costs a child job ~3 ms of store calls, so the trace offers only as many as other
// workers take: a task is stored (a QUEUED child of kind "trace_task", its request the parent's
// TraceRequest and the task, jobs/trace_task_job.h; in the parent's client and lane, fenced by
// its run) while fewer than `budget` stored tasks are open, else kept and run by the trace itself
// (jobs::LocalTraceTasks, the same results) when it needs it or while it waits. The budget grows
// by one each time another worker ran a stored task, and shrinks by one each time the trace had
// to claim one itself (no worker took it before the trace needed it): alone, the trace stores
// about one task in a window; with idle workers, up to the window.
//
// Workers claim children before new top-level jobs (docs/store.md, "Child jobs"). A stored task
// the trace needs while it is still queued is claimed and run by the trace (its result kept in
// memory: the child completes with an empty result), so a pool whose every worker runs a parent
// still makes progress; a child lost with its worker is taken back by its lease like any job. A
// result taken deletes its child; a task dropped is cancelled (and deleted when that ends it).
// The parent's end cancels the children still queued or running (the store does it).
#ifndef DRILLBIF_SERVER_TRACE_FAN_OUT_H_
#define DRILLBIF_SERVER_TRACE_FAN_OUT_H_

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>

#include "drillbif/continuation/trace_tasks.h"
#include "jobs/trace_task_job.h"
#include "server/store/job_store.h"

namespace drillbif::server {

// How a trace fans out.
struct FanOutOptions {
  // Tasks the trace keeps ahead of the one it applies (TraceTaskRunner::window), and the most it
  // stores at once.
  size_t window = 32;
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

  // Tasks submitted by the trace; those stored; those of them the trace claimed itself; those
  // stored that other workers ran.
  int64_t tasks() const { return next_; }
  int64_t stored() const { return stored_; }
  int64_t claimed_here() const { return claimed_here_; }
  int64_t run_elsewhere() const { return run_elsewhere_; }
  // Where the trace's time in the runner went: the store's calls, the tasks it ran (kept or
  // claimed), the sleeps between looks. Seconds.
  double store_seconds() const { return store_seconds_; }
  double run_seconds() const { return run_seconds_; }
  double sleep_seconds() const { return sleep_seconds_; }

 private:
  struct Child {
    std::string id;                         // the stored child; empty for a kept task
    std::optional<TraceTask> task;          // a kept task until it runs
    std::optional<TraceTaskResult> result;  // computed here (kept, or claimed here)
    bool finished = false;                  // a stored one seen SUCCEEDED, FAILED or CANCELLED
    std::chrono::steady_clock::time_point looked{};  // the last look at its state (Ready)
  };
  // A stored child's result once it finished elsewhere; nullopt while it has not.
  StatusOr<std::optional<TraceTaskResult>> ResultOf(Child& child);
  // While waiting for another worker: runs the first kept task not run yet, else claims one of
  // the parent's queued children and runs it here. Whether it ran one; an error stops the trace.
  StatusOr<bool> RunOneHere(const std::function<bool()>& keep_going);
  StatusOr<bool> ClaimOneHere();
  StatusOr<TraceTaskResult> TakeStored(int64_t ticket, const std::function<bool()>& keep_going);
  // Done with a stored child: its budget slot freed, the budget adjusted.
  void Closed(bool run_elsewhere);
  void Forget(const std::string& id);

  JobStore& store_;
  const JobRecord& parent_;
  const std::string worker_id_;
  const jobs::LocalTraceTasks& local_;
  const FanOutOptions options_;
  const RunClaimedChild run_child_;
  const std::function<void()> submitted_callback_;
  std::map<int64_t, Child> children_;
  size_t budget_ = 2;       // stored tasks open at once
  size_t stored_open_ = 0;  // stored and not taken or dropped
  int64_t next_ = 0;
  int64_t stored_ = 0, claimed_here_ = 0, run_elsewhere_ = 0;
  double store_seconds_ = 0, run_seconds_ = 0, sleep_seconds_ = 0;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_TRACE_FAN_OUT_H_
