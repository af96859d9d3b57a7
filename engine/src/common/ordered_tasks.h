// Tasks run on a pool of threads, their results taken in the order the tasks were queued.
//
// For computations whose result must not depend on the number of threads or the schedule: the
// caller queues independent tasks (each a pure function of its inputs, run on a worker with that
// worker's own resources, e.g. a propagator), takes each result in queue order on its own thread
// and applies it there (the commit: checks against what is known so far, appends). The outcome is
// that of running the tasks one after the other in queue order, whatever the threads.
//
// With one thread no thread is started: a task runs on the calling thread when its result is
// taken, so a caller that queues one task at a time computes exactly what a plain loop would.
// With more, workers take the first task in queue order that no worker has started.
#ifndef DRILLBIF_COMMON_ORDERED_TASKS_H_
#define DRILLBIF_COMMON_ORDERED_TASKS_H_

#include <chrono>
#include <condition_variable>
#include <deque>
#include <exception>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <utility>
#include <vector>

namespace drillbif::internal {

template <class Result>
class OrderedTasks {
 public:
  // A task: computes its result on worker `worker` (0 .. threads - 1).
  using Task = std::function<Result(int worker)>;

  // `threads` >= 1 workers (values below 1 count as 1).
  explicit OrderedTasks(int threads) : threads_(threads < 1 ? 1 : threads) {
    if (threads_ == 1) return;
    for (int w = 0; w < threads_; ++w) pool_.emplace_back([this, w] { Work(w); });
  }
  // Tasks not started are dropped; those running are waited for (a stopped computation's end
  // quickly: the caller stops their resources first).
  ~OrderedTasks() {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      closing_ = true;
      queue_.clear();
    }
    work_.notify_all();
    for (std::thread& t : pool_) t.join();
  }
  OrderedTasks(const OrderedTasks&) = delete;
  OrderedTasks& operator=(const OrderedTasks&) = delete;

  // Tasks queued and not taken yet.
  size_t pending() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return queue_.size();
  }

  // Queues a task behind the others.
  void Push(Task task) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      queue_.push_back(std::make_shared<Slot>(std::move(task)));
    }
    work_.notify_one();
  }
  // Removes the first task queued without its result (not run if it has not started; if it runs,
  // its result is dropped when it ends).
  void DropFront() {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!queue_.empty()) queue_.pop_front();
  }

  // The result of the first task queued, waiting for it; `wait` is called about every `interval`
  // meanwhile (e.g. to poll for a stop and stop the workers' resources). Nullopt when there is
  // none. A task's exception is rethrown here.
  std::optional<Result> TakeFront(
      const std::function<void()>& wait = {},
      std::chrono::microseconds interval = std::chrono::milliseconds(2)) {
    std::unique_lock<std::mutex> lock(mutex_);
    if (queue_.empty()) return std::nullopt;
    // Only the caller queues and takes: the front stays the front while it waits.
    const std::shared_ptr<Slot> slot = queue_.front();
    if (threads_ == 1) {
      queue_.pop_front();
      lock.unlock();
      return slot->task(0);
    }
    while (!slot->done) {
      if (wait) {
        lock.unlock();
        wait();
        lock.lock();
        if (slot->done) break;
      }
      done_.wait_for(lock, interval);
    }
    queue_.pop_front();
    if (slot->error) std::rethrow_exception(slot->error);
    return std::move(slot->result);
  }

 private:
  struct Slot {
    explicit Slot(Task t) : task(std::move(t)) {}
    Task task;
    bool started = false;
    bool done = false;
    std::optional<Result> result;
    std::exception_ptr error;
  };

  // The first task in queue order that no worker has started, or null. Under the lock.
  std::shared_ptr<Slot> FirstNotStarted() const {
    for (const std::shared_ptr<Slot>& s : queue_) {
      if (!s->started) return s;
    }
    return nullptr;
  }

  void Work(int worker) {
    std::unique_lock<std::mutex> lock(mutex_);
    for (;;) {
      std::shared_ptr<Slot> slot;
      work_.wait(lock, [&] { return closing_ || (slot = FirstNotStarted()) != nullptr; });
      if (closing_) return;
      slot->started = true;
      lock.unlock();
      try {
        slot->result = slot->task(worker);
      } catch (...) {
        slot->error = std::current_exception();
      }
      lock.lock();
      slot->done = true;
      // Only the caller waits, and only for the front: a task behind it wakes no one.
      if (!queue_.empty() && queue_.front() == slot) done_.notify_all();
    }
  }

  const int threads_;
  mutable std::mutex mutex_;
  std::condition_variable work_;  // a task was queued, or closing
  std::condition_variable done_;  // the front task is done
  std::deque<std::shared_ptr<Slot>> queue_;
  std::vector<std::thread> pool_;
  bool closing_ = false;
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_COMMON_ORDERED_TASKS_H_
