// WorkerPool: the threads that run jobs. Each worker claims the oldest queued job from the store
// (the store is the queue: jobs survive restarts there), runs the job runner of its kind, and
// records progress, the result, the failure or the cancellation in the store.
//
// Cancellation reaches the engine through the runner's progress callback, which the engine calls
// often (a sweep every 50 ms, a simulation every 1/200 of its periods, a continuation at every
// point): it returns false once the job's in-memory stop flag is set, by Cancel (from the
// CancelOperation rpc, at once) or by a poll of the store's cancel flag (at most every
// `progress_interval_ms`, for a cancel that did not come through this process). Progress is
// written to the store at most every `progress_interval_ms` per job, since each write is a
// committed (fsynced) transaction.
#ifndef DRILLBIF_SERVER_WORKER_POOL_H_
#define DRILLBIF_SERVER_WORKER_POOL_H_

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <thread>
#include <vector>

#include "drillbif/common/status.h"
#include "jobs/optimum_cache.h"
#include "server/store/job_store.h"
#include "server/watch_hub.h"

namespace drillbif::server {

// How the pool runs.
struct WorkerPoolOptions {
  // Worker threads, each running one job at a time. >= 1.
  int workers = 1;
  // Shortest time between two progress writes of one job, and between two polls of its store
  // cancel flag. Milliseconds. 250: "a few per second", cheap for the store's fsync, while a
  // Watch still sees the progress move.
  int progress_interval_ms = 250;
  // How long an idle worker sleeps before it looks at the store again without being woken (it is
  // woken by Wake() on every submit; the poll catches jobs requeued by other means). Milliseconds.
  int idle_poll_ms = 500;
  // Prefix of the worker ids recorded in the store ("<prefix>-<n>").
  std::string worker_prefix = "worker";

  // INVALID_ARGUMENT naming the field when a value is out of range.
  Status Validate() const;
};

// Called after a job of kind "optimum" succeeded in this process, with its id and cache key (for
// the service's index of stored optima).
using OptimumDoneCallback = std::function<void(const std::string& id, const std::string& key)>;

// Called on the worker's thread after each run of a job, with the job, how the run ended
// ("succeeded", "failed", "cancelled", "requeued") and its wall time in seconds (for metrics).
using JobRunCallback =
    std::function<void(const JobRecord& job, std::string_view outcome, double seconds)>;

// The pool. Thread-safe.
class WorkerPool {
 public:
  // `store` and `hub` must outlive the pool. Does not start the workers (Start does).
  WorkerPool(JobStore* store, WatchHub* hub, const WorkerPoolOptions& options,
             OptimumDoneCallback optimum_done = {}, JobRunCallback run_done = {});
  // Shutdown().
  ~WorkerPool();

  WorkerPool(const WorkerPool&) = delete;
  WorkerPool& operator=(const WorkerPool&) = delete;

  // Starts the workers. Call once, after the store's RecoverAfterRestart.
  void Start();

  // A job was queued: wake an idle worker.
  void Wake();

  // Stops the engine of job `id` if it runs in this pool (the store's Cancel has set its flag;
  // the worker then records CANCELLED). No effect otherwise.
  void Cancel(const std::string& id);

  // Graceful stop: no more claims; running jobs are interrupted through their progress callback
  // and requeued in the store (they run again at the next start); joins the workers. A job whose
  // runner finishes before it notices is recorded normally. Idempotent.
  void Shutdown();

  // Job runs started by this pool (each call of a job runner). Cache hits and jobs that follow
  // another never run, so a test can check that a cache hit did not reach the engine.
  int64_t engine_runs() const { return engine_runs_.load(); }

 private:
  // A job running on a worker.
  struct Running {
    std::atomic<bool> cancel{false};    // Stop it and record CANCELLED.
    std::atomic<bool> shutdown{false};  // Stop it and requeue it.
  };

  void Loop(int index);
  void RunOne(const JobRecord& job);

  JobStore* const store_;
  WatchHub* const hub_;
  const WorkerPoolOptions options_;
  const OptimumDoneCallback optimum_done_;
  const JobRunCallback run_done_;
  std::atomic<int64_t> engine_runs_{0};
  // Curves and regions of optimum jobs, for later optimum jobs over the same curves.
  jobs::OptimumCache optimum_cache_;

  std::mutex mutex_;
  std::condition_variable cv_;
  bool stopping_ = false;
  int wakeups_ = 0;
  std::map<std::string, std::shared_ptr<Running>> running_;
  std::vector<std::thread> threads_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_WORKER_POOL_H_
