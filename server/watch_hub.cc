#include "server/watch_hub.h"

#include <algorithm>
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
      const auto deadline = watcher->deadline();
      if (deadline != std::chrono::steady_clock::time_point::max())
        deadlines_.emplace(deadline, std::make_pair(id, watcher.get()));
      watchers_.emplace(id, std::move(watcher));
      dirty_.insert(id);
      cv_.notify_one();
      return;
    }
  }
  watcher->OnShutdown();
}

void WatchHub::Notify() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    notify_all_ = true;
  }
  cv_.notify_one();
}

void WatchHub::NotifyJob(const std::string& id) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_ || watchers_.find(id) == watchers_.end()) return;
    dirty_.insert(id);
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

void WatchHub::EraseDeadline(const JobWatcher& watcher) {
  const auto deadline = watcher.deadline();
  if (deadline == std::chrono::steady_clock::time_point::max()) return;
  const auto [first, last] = deadlines_.equal_range(deadline);
  for (auto it = first; it != last; ++it) {
    if (it->second.second == &watcher) {
      deadlines_.erase(it);
      return;
    }
  }
}

void WatchHub::Loop() {
  // The next time every watched job is read, whatever was notified meanwhile: a steady stream of
  // NotifyJob (progress of other jobs) must not keep the poll from ever coming.
  auto next_poll = std::chrono::steady_clock::now() + poll_interval_;
  for (;;) {
    std::multimap<std::string, std::shared_ptr<JobWatcher>> round;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      const auto wake_at =
          deadlines_.empty() ? next_poll : std::min(next_poll, deadlines_.begin()->first);
      cv_.wait_until(lock, wake_at, [this] { return notify_all_ || !dirty_.empty() || stopping_; });
      if (stopping_) return;
      const auto woke = std::chrono::steady_clock::now();
      // Jobs whose watcher's deadline came.
      while (!deadlines_.empty() && deadlines_.begin()->first <= woke) {
        dirty_.insert(deadlines_.begin()->second.first);
        deadlines_.erase(deadlines_.begin());
      }
      if (notify_all_ || woke >= next_poll) {
        round = watchers_;
        next_poll = woke + poll_interval_;
      } else {
        for (const std::string& id : dirty_) {
          const auto [first, last] = watchers_.equal_range(id);
          round.insert(first, last);
        }
      }
      notify_all_ = false;
      dirty_.clear();
    }
    if (round.empty()) continue;
    const auto now = std::chrono::steady_clock::now();
    std::vector<std::shared_ptr<JobWatcher>> done;
    // One read per job, whatever the number of its watchers.
    for (auto it = round.begin(); it != round.end();) {
      const std::string& id = it->first;
      // Watchers read state and progress, not the request (up to max_request_bytes).
      const StatusOr<JobRecord> record = store_->Get(id, /*include_request=*/false);
      reads_.fetch_add(1);
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
      if (remove) EraseDeadline(*it->second);
      it = remove ? watchers_.erase(it) : std::next(it);
    }
  }
}

}  // namespace drillbif::server
