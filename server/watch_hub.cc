#include "server/watch_hub.h"

#include <utility>

namespace drillbif::server {

WatchHub::WatchHub(JobStore* store, int poll_interval_ms)
    : store_(store), poll_interval_(poll_interval_ms) {
  thread_ = std::thread([this] { Loop(); });
}

WatchHub::~WatchHub() { Stop(); }

void WatchHub::Add(const std::string& id, std::shared_ptr<JobWatcher> watcher) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!stopping_) {
      watchers_.emplace(id, std::move(watcher));
      notified_ = true;
      cv_.notify_one();
      return;
    }
  }
  watcher->OnShutdown();
}

void WatchHub::Notify() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    notified_ = true;
  }
  cv_.notify_one();
}

int WatchHub::size() {
  std::lock_guard<std::mutex> lock(mutex_);
  return static_cast<int>(watchers_.size());
}

void WatchHub::Stop() {
  std::multimap<std::string, std::shared_ptr<JobWatcher>> left;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_) return;
    stopping_ = true;
  }
  cv_.notify_one();
  if (thread_.joinable()) thread_.join();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    left.swap(watchers_);
  }
  for (auto& [id, watcher] : left) watcher->OnShutdown();
}

void WatchHub::Loop() {
  for (;;) {
    std::multimap<std::string, std::shared_ptr<JobWatcher>> round;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      cv_.wait_for(lock, poll_interval_, [this] { return notified_ || stopping_; });
      if (stopping_) return;
      notified_ = false;
      round = watchers_;
    }
    if (round.empty()) continue;
    const auto now = std::chrono::steady_clock::now();
    std::vector<std::shared_ptr<JobWatcher>> done;
    // One read per job, whatever the number of its watchers.
    for (auto it = round.begin(); it != round.end();) {
      const std::string& id = it->first;
      // Watchers read state and progress, not the request (up to max_request_bytes).
      const StatusOr<JobRecord> record = store_->Get(id, /*include_request=*/false);
      auto end = round.upper_bound(id);
      for (; it != end; ++it) {
        if (it->second->OnRecord(record, now)) done.push_back(it->second);
      }
    }
    if (done.empty()) continue;
    std::lock_guard<std::mutex> lock(mutex_);
    for (auto it = watchers_.begin(); it != watchers_.end();) {
      bool remove = false;
      for (const auto& d : done) remove = remove || d == it->second;
      it = remove ? watchers_.erase(it) : std::next(it);
    }
  }
}

}  // namespace drillbif::server
