// StoreTaskRunner: a trace job's tasks (continuation/trace_tasks.h) as child jobs in the store,
// so that any worker of any process sharing the store computes them.
//
// Each task the trace submits becomes a QUEUED child job of kind "trace_task" (its request the
// parent's TraceRequest and the task, jobs/trace_task_job.h), in the parent's client and lane,
// fenced by the parent's run. Workers claim children before new top-level jobs
// (docs/store.md, "Child jobs"). While the trace waits for a result it claims and runs its own
// children itself, so a pool whose every worker runs a parent still makes progress (their results
// stay in its memory: such a child completes with an empty result); a child lost with its worker
// is taken back by its lease like any job. A result taken is read and the child deleted; a task
// dropped is cancelled (and deleted when that ends it). The parent's end cancels the children still
// queued or running (the store does it).
#ifndef DRILLBIF_SERVER_TRACE_FAN_OUT_H_
#define DRILLBIF_SERVER_TRACE_FAN_OUT_H_

#include <chrono>
#include <cstdint>
#include <functional>
#include <map>
#include <optional>
#include <string>

#include "drillbif/continuation/trace_tasks.h"
#include "server/store/job_store.h"

namespace drillbif::server {

// How a trace fans out.
struct FanOutOptions {
  // Tasks the trace keeps ahead of the one it applies (TraceTaskRunner::window).
  size_t window = 32;
  // The lease of a child the parent claims itself (ClaimOptions::lease_ms; 0: none).
  int64_t lease_ms = 0;
  // How often a waiting parent looks at the store for its result or a child to run. 5 ms: a
  // curve task takes ~20 ms, and each look is one short read.
  std::chrono::milliseconds poll{5};
};

// Called to run a child the parent claimed, on the parent's thread (the worker pool's run of one
// job: its lease renewed, its outcome recorded): on success, the child is completed with an empty
// result and its result's bytes returned, for the parent to read from memory; else nullopt.
using RunClaimedChild = std::function<std::optional<std::string>(const JobRecord& child)>;

class StoreTaskRunner : public TraceTaskRunner {
 public:
  // `parent` (RUNNING, claimed by `worker_id`) and `store` outlive the runner. `submitted` is
  // called after each child is stored (to wake idle workers).
  StoreTaskRunner(JobStore& store, const JobRecord& parent, std::string worker_id,
                  const FanOutOptions& options, RunClaimedChild run_child,
                  std::function<void()> submitted);
  ~StoreTaskRunner() override;

  size_t window() const override { return options_.window; }
  StatusOr<int64_t> Submit(const TraceTask& task) override;
  bool Ready(int64_t ticket) override;
  StatusOr<TraceTaskResult> Take(int64_t ticket, const std::function<bool()>& keep_going) override;
  void Drop(int64_t ticket) override;

  // Children submitted, and those of them the parent ran itself.
  int64_t submitted() const { return submitted_; }
  int64_t ran_here() const { return ran_here_; }
  // Where the trace's waits went: the store's calls, the tasks run here, the sleeps between
  // looks. Seconds.
  double store_seconds() const { return store_seconds_; }
  double run_seconds() const { return run_seconds_; }
  double sleep_seconds() const { return sleep_seconds_; }

 private:
  struct Child {
    std::string id;
    bool finished = false;                           // seen SUCCEEDED, FAILED or CANCELLED
    std::chrono::steady_clock::time_point looked{};  // the last look at its state (Ready)
  };
  // The child's result once it finished; nullopt while it has not.
  StatusOr<std::optional<TraceTaskResult>> ResultOf(Child& child);
  // The child's result decoded from its bytes.
  StatusOr<std::optional<TraceTaskResult>> Decoded(Child& child, const std::string& bytes);
  // Claims one of the parent's queued children and runs it here; whether there was one.
  bool RunOneHere();
  void Forget(const std::string& id);

  JobStore& store_;
  const JobRecord& parent_;
  const std::string worker_id_;
  const FanOutOptions options_;
  const RunClaimedChild run_child_;
  const std::function<void()> submitted_callback_;
  std::map<int64_t, Child> children_;
  std::map<std::string, std::string> kept_;  // results of the children run here, by id
  int64_t next_ = 0;
  int64_t submitted_ = 0, ran_here_ = 0;
  double store_seconds_ = 0, run_seconds_ = 0, sleep_seconds_ = 0;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_TRACE_FAN_OUT_H_
