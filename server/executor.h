// BoundedExecutor: a fixed set of threads running short tasks from a bounded queue. The gRPC
// reactors hand their store work (a submit with its fsync, a result read and its paging) to it,
// so that gRPC's own threads never block on disk; a full queue is reported to the caller, who
// answers RESOURCE_EXHAUSTED instead of queueing without bound.
#ifndef DRILLBIF_SERVER_EXECUTOR_H_
#define DRILLBIF_SERVER_EXECUTOR_H_

#include <condition_variable>
#include <deque>
#include <functional>
#include <mutex>
#include <thread>
#include <vector>

#include "drillbif/common/status.h"

namespace drillbif::server {

// How many threads and how deep a queue.
struct ExecutorOptions {
  // Threads running tasks. 2: store operations serialize on the store's lock anyway, and one
  // more thread overlaps result paging with a submit's fsync.
  int threads = 2;
  // Tasks waiting beyond those running; TrySubmit refuses more. 1024: far above what 2 threads
  // clear in the time of one client deadline, so only an overload fills it.
  int max_queued = 1024;

  // INVALID_ARGUMENT naming the field when a value is out of range.
  Status Validate() const;
};

// Runs tasks on its threads, oldest first. Thread-safe.
class BoundedExecutor {
 public:
  // Starts the threads. Options must be valid (checked by the caller with Validate()).
  explicit BoundedExecutor(const ExecutorOptions& options);
  // Stop().
  ~BoundedExecutor();

  BoundedExecutor(const BoundedExecutor&) = delete;
  BoundedExecutor& operator=(const BoundedExecutor&) = delete;

  // Queues `task`; false (and the task is dropped) when the queue is full or Stop was called.
  bool TrySubmit(std::function<void()> task);

  // Refuses new tasks, runs every task already queued (each finishes an RPC that gRPC's shutdown
  // waits for), then joins the threads. Idempotent.
  void Stop();

 private:
  void Loop();

  const ExecutorOptions options_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<std::function<void()>> tasks_;
  bool stopping_ = false;
  std::vector<std::thread> threads_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_EXECUTOR_H_
