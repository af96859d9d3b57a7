#include "server/worker_pool.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <utility>

#include "jobs/registry.h"

namespace drillbif::server {

Status WorkerPoolOptions::Validate() const {
  if (workers < 1 || workers > 1024) {
    return InvalidArgument("workers: must be in [1, 1024], got " + std::to_string(workers));
  }
  if (progress_interval_ms < 1) {
    return InvalidArgument("progress_interval_ms: must be >= 1, got " +
                           std::to_string(progress_interval_ms));
  }
  if (idle_poll_ms < 1) {
    return InvalidArgument("idle_poll_ms: must be >= 1, got " + std::to_string(idle_poll_ms));
  }
  return Status::Ok();
}

WorkerPool::WorkerPool(JobStore* store, WatchHub* hub, const WorkerPoolOptions& options,
                       OptimumDoneCallback optimum_done, JobRunCallback run_done)
    : store_(store),
      hub_(hub),
      options_(options),
      optimum_done_(std::move(optimum_done)),
      run_done_(std::move(run_done)) {}

WorkerPool::~WorkerPool() { Shutdown(); }

void WorkerPool::Start() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!threads_.empty() || stopping_) return;
  for (int i = 0; i < options_.workers; ++i) threads_.emplace_back([this, i] { Loop(i); });
}

void WorkerPool::Wake() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++wakeups_;
  }
  cv_.notify_one();
}

void WorkerPool::Cancel(const std::string& id) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = running_.find(id);
  if (it != running_.end()) it->second->cancel = true;
}

void WorkerPool::Shutdown() {
  std::vector<std::thread> threads;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
    for (auto& [id, running] : running_) running->shutdown = true;
    threads.swap(threads_);
  }
  cv_.notify_all();
  for (std::thread& t : threads) t.join();
}

void WorkerPool::Loop(int index) {
  const std::string worker_id = options_.worker_prefix + "-" + std::to_string(index);
  for (;;) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stopping_) return;
    }
    StatusOr<std::optional<JobRecord>> claimed = store_->ClaimNext(worker_id);
    if (claimed.ok() && claimed->has_value()) {
      RunOne(**claimed);
      continue;
    }
    if (!claimed.ok())
      spdlog::error("{}: claim failed: {}", worker_id, claimed.status().ToString());
    std::unique_lock<std::mutex> lock(mutex_);
    // Sleep until a submit wakes us (wakeups_ counts the unconsumed ones) or the poll interval.
    cv_.wait_for(lock, std::chrono::milliseconds(options_.idle_poll_ms),
                 [this] { return stopping_ || wakeups_ > 0; });
    if (wakeups_ > 0) --wakeups_;
  }
}

void WorkerPool::RunOne(const JobRecord& job) {
  using Clock = std::chrono::steady_clock;
  auto running = std::make_shared<Running>();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    // A shutdown that began between the claim and now still requeues this job.
    running->shutdown = stopping_;
    running_[job.id] = running;
  }
  hub_->Notify();  // QUEUED -> RUNNING
  const jobs::JobKindSpec* kind = jobs::FindKind(job.kind);
  const auto interval = std::chrono::milliseconds(options_.progress_interval_ms);
  Clock::time_point last_write = Clock::now();
  const auto started = last_write;

  // The current parameter value, where the kind has one (continue), for the job's metadata.
  std::optional<double> current, recorded_current;
  const std::function<void(double)> value = [&](double v) {
    if (std::isfinite(v)) current = v;
  };
  // Called by the engine on this thread.
  const ProgressCallback progress = [&](double fraction) {
    if (running->cancel.load() || running->shutdown.load()) return false;
    const Clock::time_point now = Clock::now();
    if (now - last_write < interval) return true;
    last_write = now;
    const double f = std::isfinite(fraction) ? std::clamp(fraction, 0.0, 1.0) : 0.0;
    recorded_current = current;
    if (Status s = store_->UpdateProgress(job.id, f, current, 0); !s.ok()) {
      spdlog::warn("job {}: progress not recorded: {}", job.id, s.ToString());
    }
    // A cancel recorded in the store by someone other than this process's CancelOperation.
    StatusOr<bool> requested = store_->IsCancelRequested(job.id);
    if (requested.ok() && *requested) running->cancel = true;
    hub_->Notify();
    return !running->cancel.load();
  };

  spdlog::info("job {} ({}) started, attempt {}", job.id, job.kind, job.attempts);
  engine_runs_.fetch_add(1);
  StatusOr<jobs::JobOutput> output =
      kind == nullptr
          ? StatusOr<jobs::JobOutput>(Internal("unknown job kind '" + job.kind + "'"))
          : jobs::RunJob(
                *kind, job.request,
                {.progress = progress, .on_value = value, .optimum_cache = &optimum_cache_});
  const double seconds = std::chrono::duration<double>(Clock::now() - started).count();

  // How the run ended, decided before anything is recorded: run_done_ (the duration histogram)
  // sees the run before the store makes its outcome visible, so a client that sees the job done
  // also sees it in the metrics.
  const bool cancelled = output.ok() && output->status == "CANCELLED";
  const bool shutdown_requeue = cancelled && running->shutdown.load() && !running->cancel.load();
  const char* outcome_label = !output.ok()       ? "failed"  // one word per way a run ends
                              : shutdown_requeue ? "requeued"
                              : cancelled        ? "cancelled"
                                                 : "succeeded";
  if (run_done_) run_done_(job, outcome_label, seconds);

  Status recorded;
  std::string outcome;
  if (!output.ok()) {
    recorded = store_->Fail(job.id, output.status().code(), output.status().message());
    outcome = "failed: " + output.status().ToString();
  } else if (shutdown_requeue) {
    recorded = store_->Requeue(job.id);
    outcome = "interrupted by shutdown, requeued";
  } else if (cancelled) {
    recorded = store_->MarkCancelled(job.id);
    outcome = "cancelled";
  } else {
    // The last value reached, when no progress record carried it (a short run): one more write.
    if (current && current != recorded_current) {
      if (Status s = store_->UpdateProgress(job.id, 1.0, current, output->items); !s.ok()) {
        spdlog::warn("job {}: final value not recorded: {}", job.id, s.ToString());
      }
    }
    recorded = store_->Complete(job.id, output->result, output->items);
    outcome = "succeeded";
    if (recorded.ok() && kind->kind == v1::OPTIMUM && optimum_done_) {
      optimum_done_(job.id, job.cache_key);
    }
  }
  if (recorded.ok()) {
    spdlog::info("job {} ({}) {} in {:.3f} s", job.id, job.kind, outcome, seconds);
  } else {
    // FAILED_PRECONDITION: the job is no longer RUNNING here (a stale run after a requeue that
    // another run completed first); the store kept exactly one outcome.
    spdlog::warn("job {} ({}) {} in {:.3f} s, not recorded: {}", job.id, job.kind, outcome, seconds,
                 recorded.ToString());
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    running_.erase(job.id);
  }
  hub_->Notify();
}

}  // namespace drillbif::server
