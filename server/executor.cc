#include "server/executor.h"

#include <string>
#include <utility>

namespace drillbif::server {

Status ExecutorOptions::Validate() const {
  if (threads < 1 || threads > 256) {
    return InvalidArgument("threads: must be in [1, 256], got " + std::to_string(threads));
  }
  if (max_queued < 1) {
    return InvalidArgument("max_queued: must be >= 1, got " + std::to_string(max_queued));
  }
  return Status::Ok();
}

BoundedExecutor::BoundedExecutor(const ExecutorOptions& options) : options_(options) {
  threads_.reserve(options_.threads);
  for (int i = 0; i < options_.threads; ++i) threads_.emplace_back([this] { Loop(); });
}

BoundedExecutor::~BoundedExecutor() { Stop(); }

bool BoundedExecutor::TrySubmit(std::function<void()> task) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_ || static_cast<int>(tasks_.size()) >= options_.max_queued) return false;
    tasks_.push_back(std::move(task));
  }
  cv_.notify_one();
  return true;
}

void BoundedExecutor::Stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
  }
  cv_.notify_all();
  for (std::thread& t : threads_) {
    if (t.joinable()) t.join();
  }
}

void BoundedExecutor::Loop() {
  for (;;) {
    std::function<void()> task;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      cv_.wait(lock, [this] { return stopping_ || !tasks_.empty(); });
      // Drain before exiting: a queued task finishes an RPC.
      if (tasks_.empty()) return;
      task = std::move(tasks_.front());
      tasks_.pop_front();
    }
    task();
  }
}

}  // namespace drillbif::server
