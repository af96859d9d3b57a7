// WorkerPool: the threads that run jobs. Each worker claims a job from the store (the store is the
// queue: jobs survive restarts there; claims are fair across clients), runs it through the job
// registry (jobs/registry.h), streams its result into the store as it is produced
// (server/stored_results.h), and records how it ended.
//
// Lanes: every job was queued in a cost lane at submit (short or long, by its estimated time).
// `workers` threads take jobs of any lane; `short_workers` more take short jobs only, so that a
// short job never waits behind long ones however many long jobs are queued or running.
//
// A run stops, through its progress callback (which the engine calls every few milliseconds),
// when it is cancelled (CancelOperation, at once; or a cancel recorded in the store by another
// process, polled every `progress_interval_ms`), when the pool shuts down (the job is requeued),
// when it reaches its kind's time limit (FAILED, DEADLINE_EXCEEDED) or its result reaches its
// kind's size limit (FAILED, RESOURCE_EXHAUSTED). Progress is written to the store at most every
// `progress_interval_ms` per job, since each write is a committed (fsynced) transaction.
//
// Store faults: a worker whose outcome cannot be recorded (a full disk, an I/O error) fails the
// job instead where it can, and otherwise retries until the store's Probe succeeds, with a
// backoff; no worker claims a job while the store reports a fault (JobStore::Health).
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
#include "jobs/job_cost.h"
#include "jobs/optimum_cache.h"
#include "server/store/job_store.h"
#include "server/watch_hub.h"

namespace drillbif::server {

// The most trace tasks a trace may keep in the store ahead of the one it applies.
inline constexpr int kMaxTraceFanOut = 4096;

// How the pool runs.
struct WorkerPoolOptions {
  // Worker threads taking jobs of any lane, each running one job at a time. >= 1.
  int workers = 1;
  // Worker threads taking short jobs only. >= 0. 1: a short job starts at once even when every
  // other worker runs a long one; its run is short, so it competes for a core only briefly.
  int short_workers = 1;
  // Shortest time between two progress writes of one job, and between two polls of its store
  // cancel flag. Milliseconds. 250: "a few per second", cheap for the store's fsync, while a
  // Watch still sees the progress move.
  int progress_interval_ms = 250;
  // How long an idle worker sleeps before it looks at the store again without being woken (it is
  // woken by Wake() on every submit; the poll catches jobs requeued by other means). Milliseconds.
  int idle_poll_ms = 500;
  // Size of the result chunks written to the store while a job runs. Bytes. 1 MiB: large enough
  // that a chunk's transaction costs little beside its bytes, small enough that a run holds
  // little of its result in memory.
  int64_t chunk_bytes = 1 << 20;
  // First and longest wait between two attempts to record a job's outcome in a store that
  // failed (the wait doubles). Milliseconds.
  int store_retry_ms = 1000;
  int store_retry_max_ms = 30000;
  // Prefix of the worker ids recorded in the store ("<prefix>-<n>", short workers
  // "<prefix>-short-<n>").
  std::string worker_prefix = "worker";
  // The limits of each kind by name (jobs/job_cost.h); a kind not here runs unlimited.
  std::map<std::string, jobs::KindLimits> limits;
  // Claims are leases of this many milliseconds (ClaimOptions::lease_ms) for a store that
  // several processes share: a heartbeat thread renews the leases of the running jobs every
  // lease_ms / 3 and takes back the jobs of any process whose lease expired
  // (JobStore::ReclaimExpiredLeases); a run whose renewal is refused (its lease expired and the
  // job was taken back) is stopped and records nothing. 0: no leases (a store one process owns:
  // its restart recovers the jobs). >= 300 when set: three beats must fit in it.
  int64_t lease_ms = 0;
  // Trace jobs, and optimum jobs for their trace, offer their tasks to every worker as child jobs
  // of the store
  // (server/trace_fan_out.h), up to this many ahead of the one they apply; 0: a trace runs its
  // tasks on its own threads. For a store several processes share: in one process the threads
  // do the same work without the store's round trips.
  int trace_fan_out = 0;
  // The tasks of one such child job (FanOutOptions::batch), 1 .. jobs::kMaxTraceTaskBatch.
  int trace_fan_out_batch = 4;

  // INVALID_ARGUMENT naming the field when a value is out of range.
  Status Validate() const;
};

// Called after a job of kind "optimum" succeeded in this process, with its id and cache key (for
// the service's index of stored optima).
using OptimumDoneCallback = std::function<void(const std::string& id, const std::string& key)>;

// Called on the worker's thread after each run of a job, with the job, how the run ended
// ("succeeded", "failed", "cancelled", "requeued", "deadline_exceeded", "too_large",
// "lease_lost") and its wall time in seconds (for metrics).
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

  // A job was queued: wake the idle workers (one of them may take it).
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

  // Jobs running now.
  int running() const;

 private:
  // A job running on a worker.
  struct Running {
    int64_t run = 0;                    // Its run (JobRecord::run): the lease's fence.
    std::string parent;                 // A child's parent (JobRecord::parent), else empty.
    std::atomic<bool> cancel{false};    // Stop it and record CANCELLED.
    std::atomic<bool> shutdown{false};  // Stop it and requeue it.
    std::atomic<bool> lost{false};      // Its lease was lost: stop it and record nothing.
  };
  class Run;

  void Loop(const std::string& worker_id, const ClaimOptions& claim);
  // The lease heartbeat (lease_ms > 0): renews the running jobs' leases and takes back expired
  // ones, every lease_ms / 3, until the pool stops.
  void Heartbeat();
  void RenewLeases();
  // Runs a claimed job (or child) on the calling thread, `worker_id`'s. With `kept`, a success
  // completes the job with an empty result and leaves the result's bytes in *kept (a trace's task
  // its parent ran: the parent reads it from memory, not the store). Whether it succeeded.
  bool RunOne(const JobRecord& job, const std::string& worker_id, std::string* kept = nullptr);
  // Records an outcome with `record`, retrying while the store is faulty (see the header) until
  // it succeeds or answers for good (FAILED_PRECONDITION, NOT_FOUND, INVALID_ARGUMENT), or the
  // pool shuts down.
  Status Record(const JobRecord& job, const char* what, const std::function<Status()>& record);
  // Sleeps `ms` unless the pool stops first; false when it stopped.
  bool Sleep(int ms);

  JobStore* const store_;
  WatchHub* const hub_;
  const WorkerPoolOptions options_;
  const OptimumDoneCallback optimum_done_;
  const JobRunCallback run_done_;
  std::atomic<int64_t> engine_runs_{0};
  // Curves and regions of optimum jobs, for later optimum jobs over the same curves.
  jobs::OptimumCache optimum_cache_;

  mutable std::mutex mutex_;
  std::condition_variable cv_;
  bool stopping_ = false;
  int64_t wakeups_ = 0;  // submits since start: idle workers look again when it changes
  std::map<std::string, std::shared_ptr<Running>> running_;
  std::vector<std::thread> threads_;
  std::thread heartbeat_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_WORKER_POOL_H_
