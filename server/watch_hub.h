// WatchHub: delivers job changes to the RPCs that wait on them (Watch streams, WaitOperation,
// QueryOptimum computing on demand) without blocking any RPC thread.
//
// One thread reads each watched job from the store and hands the record to its watchers, when
// told that something changed (Notify: workers call it after each progress update and state
// change, the services after submit and cancel) and at least every `poll_interval_ms`. Polling
// the store rather than passing events keeps it right for changes no event names: jobs that
// follow a shared run change with it, and a timeout needs a clock anyway. A read is a
// microsecond-scale indexed SELECT and progress is written at most a few times per second per
// job, so the cost is a few reads per watcher per change.
#ifndef DRILLBIF_SERVER_WATCH_HUB_H_
#define DRILLBIF_SERVER_WATCH_HUB_H_

#include <chrono>
#include <condition_variable>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/common/status.h"
#include "server/store/job_store.h"

namespace drillbif::server {

// Something waiting on one job. Called on the hub's thread only, never concurrently.
class JobWatcher {
 public:
  virtual ~JobWatcher() = default;
  // The job's current record (or the error reading it, e.g. NOT_FOUND after a delete) at time
  // `now`. Returns true when the watcher is done and must not be called again.
  virtual bool OnRecord(const StatusOr<JobRecord>& record,
                        std::chrono::steady_clock::time_point now) = 0;
  // The hub stops (server shutdown): finish now. Not called for a watcher that returned true.
  virtual void OnShutdown() = 0;
};

// The hub. Thread-safe.
class WatchHub {
 public:
  // Starts the thread. `store` must outlive the hub. poll_interval_ms >= 1.
  WatchHub(JobStore* store, int poll_interval_ms);
  // Stop().
  ~WatchHub();

  WatchHub(const WatchHub&) = delete;
  WatchHub& operator=(const WatchHub&) = delete;

  // Starts delivering job `id` to `watcher` (the first delivery comes at once). After Stop, the
  // watcher gets OnShutdown immediately instead.
  void Add(const std::string& id, std::shared_ptr<JobWatcher> watcher);

  // Something may have changed: deliver without waiting for the poll interval.
  void Notify();

  // Number of watchers (for tests and metrics).
  int size();

  // Calls OnShutdown on every watcher, drops them and joins the thread. Idempotent.
  void Stop();

 private:
  void Loop();

  JobStore* const store_;
  const std::chrono::milliseconds poll_interval_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool notified_ = false;
  bool stopping_ = false;
  std::multimap<std::string, std::shared_ptr<JobWatcher>> watchers_;
  std::thread thread_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_WATCH_HUB_H_
