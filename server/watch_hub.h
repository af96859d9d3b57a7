// WatchHub: delivers job changes to the RPCs that wait on them (Watch streams, WaitOperation,
// QueryOptimum computing on demand) without blocking any RPC thread.
//
// One thread reads watched jobs from the store and hands each record to the job's watchers:
// - a job named by NotifyJob (the store's change feed: another process changed it), or just
//   added, is read alone, at once;
// - every watched job when told that something may have changed (Notify: workers call it after
//   each progress update and state change, the services after submit and cancel; the feed
//   after it reconnected), and at least every `poll_interval_ms`.
// - a job whose watcher's deadline (a wait's timeout) has come.
// The poll keeps it right for changes no event names (without a change feed, another process's
// changes are seen only by it). A read is a small indexed
// SELECT and progress is written at most a few times per second per job, so the cost is a few
// reads per watched job per change, plus one per watched job per poll interval.
#ifndef DRILLBIF_SERVER_WATCH_HUB_H_
#define DRILLBIF_SERVER_WATCH_HUB_H_

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <set>
#include <string>
#include <thread>
#include <utility>
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
  // When the watcher wants a record whether or not the job changed (a wait's timeout): the hub
  // reads its job then, not at the next poll, which may be seconds later. Must not change.
  virtual std::chrono::steady_clock::time_point deadline() const {
    return std::chrono::steady_clock::time_point::max();
  }
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

  // Something may have changed: read every watched job without waiting for the poll interval.
  void Notify();

  // Job `id` changed: read it (alone) without waiting for the poll interval. No effect when
  // nothing watches it, so that a feed of every job's changes costs nothing for the others.
  void NotifyJob(const std::string& id);

  // Store reads made so far (one per watched job per round, whatever its number of watchers):
  // what the hub costs the store.
  int64_t reads() const { return reads_.load(); }

  // Number of watchers (for tests and metrics).
  int size();

  // Calls OnShutdown on every watcher, drops them and joins the thread. Idempotent.
  void Stop();

 private:
  void Loop();
  // Drops `watcher`'s entry of deadlines_ (mutex_ held).
  void EraseDeadline(const JobWatcher& watcher);

  JobStore* const store_;
  const std::chrono::milliseconds poll_interval_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool notify_all_ = false;      // Notify() called: read every watched job.
  std::set<std::string> dirty_;  // Watched jobs to read (NotifyJob, Add) when not reading all.
  std::atomic<int64_t> reads_{0};
  bool stopping_ = false;
  std::multimap<std::string, std::shared_ptr<JobWatcher>> watchers_;
  // The deadlines of the watchers that have one (JobWatcher::deadline), with their job and the
  // watcher (to drop the entry with it: a wait that ends early must not leave its entry for up
  // to its timeout).
  std::multimap<std::chrono::steady_clock::time_point, std::pair<std::string, const JobWatcher*>>
      deadlines_;
  std::thread thread_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_WATCH_HUB_H_
