#include "server/worker_pool.h"

#include <malloc.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <optional>
#include <utility>

#include "jobs/registry.h"
#include "jobs/request_bytes.h"
#include "jobs/trace_task_codec.h"
#include "jobs/trace_task_job.h"
#include "server/map_fan_out.h"
#include "server/stored_results.h"
#include "server/sweep_fan_out.h"
#include "server/trace_fan_out.h"

namespace drillbif::server {
namespace {

using Clock = std::chrono::steady_clock;

// A store answer that retrying cannot change: the job moved on (another run finished it, it was
// deleted), or the call itself is wrong.
bool Final(const Status& s) {
  return s.ok() || s.code() == StatusCode::kFailedPrecondition ||
         s.code() == StatusCode::kNotFound || s.code() == StatusCode::kInvalidArgument;
}

}  // namespace

Status WorkerPoolOptions::Validate() const {
  if (workers < 1 || workers > 1024) {
    return InvalidArgument("workers: must be in [1, 1024], got " + std::to_string(workers));
  }
  if (short_workers < 0 || short_workers > 1024) {
    return InvalidArgument("short_workers: must be in [0, 1024], got " +
                           std::to_string(short_workers));
  }
  if (progress_interval_ms < 1) {
    return InvalidArgument("progress_interval_ms: must be >= 1, got " +
                           std::to_string(progress_interval_ms));
  }
  if (idle_poll_ms < 1) {
    return InvalidArgument("idle_poll_ms: must be >= 1, got " + std::to_string(idle_poll_ms));
  }
  if (chunk_bytes < 1024) {
    return InvalidArgument("chunk_bytes: must be >= 1024, got " + std::to_string(chunk_bytes));
  }
  if (store_retry_ms < 1 || store_retry_max_ms < store_retry_ms) {
    return InvalidArgument("store_retry_ms: must be >= 1 and <= store_retry_max_ms");
  }
  if (lease_ms != 0 && lease_ms < 300) {
    return InvalidArgument("lease_ms: must be 0 (no leases) or >= 300, got " +
                           std::to_string(lease_ms));
  }
  if (trace_fan_out < 0 || trace_fan_out > kMaxTraceFanOut) {
    return InvalidArgument("trace_fan_out: must be 0 (off) .. " + std::to_string(kMaxTraceFanOut) +
                           ", got " + std::to_string(trace_fan_out));
  }
  if (trace_fan_out_batch < 1 || trace_fan_out_batch > jobs::kMaxTraceTaskBatch) {
    return InvalidArgument("trace_fan_out_batch: must be 1 .. " +
                           std::to_string(jobs::kMaxTraceTaskBatch) + ", got " +
                           std::to_string(trace_fan_out_batch));
  }
  for (const auto& [name, kind_limits] : limits) {
    if (Status s = kind_limits.Validate(); !s.ok()) {
      return InvalidArgument(name + "." + s.message());
    }
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
  for (int i = 0; i < options_.workers; ++i) {
    const std::string id = options_.worker_prefix + "-" + std::to_string(i);
    threads_.emplace_back([this, id] { Loop(id, ClaimOptions{{}, options_.lease_ms}); });
  }
  for (int i = 0; i < options_.short_workers; ++i) {
    const std::string id = options_.worker_prefix + "-short-" + std::to_string(i);
    threads_.emplace_back([this, id] { Loop(id, ClaimOptions{{kLaneShort}, options_.lease_ms}); });
  }
  if (options_.lease_ms > 0) heartbeat_ = std::thread([this] { Heartbeat(); });
}

void WorkerPool::RenewLeases() {
  std::vector<std::pair<std::string, std::shared_ptr<Running>>> running;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    running.assign(running_.begin(), running_.end());
  }
  for (const auto& [id, job] : running) {
    const Status s = store_->RenewLease(id, job->run, options_.lease_ms);
    if (s.code() == StatusCode::kFailedPrecondition || s.code() == StatusCode::kNotFound) {
      // Taken back after its lease expired (this process stalled or lost the store): another
      // worker may run it now; this run stops and records nothing (the store would refuse it).
      spdlog::warn("job {}: lease lost ({}); stopping its run", id, s.message());
      job->lost = true;
    } else if (!s.ok()) {
      spdlog::warn("job {}: lease not renewed: {}", id, s.ToString());
    }
  }
}

void WorkerPool::Heartbeat() {
  const int beat_ms = static_cast<int>(std::min<int64_t>(options_.lease_ms / 3, 1 << 30));
  while (Sleep(beat_ms)) {
    RenewLeases();
    const int64_t now_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                               std::chrono::system_clock::now().time_since_epoch())
                               .count();
    StatusOr<RecoveryReport> taken = store_->ReclaimExpiredLeases(now_ms);
    if (!taken.ok()) {
      spdlog::warn("expired leases not reclaimed: {}", taken.status().ToString());
    } else if (taken->requeued + taken->cancelled + taken->failed > 0) {
      spdlog::warn("expired leases: {} jobs requeued, {} cancelled, {} failed", taken->requeued,
                   taken->cancelled, taken->failed);
      if (taken->requeued > 0) Wake();
      hub_->Notify();
    }
  }
}

void WorkerPool::Wake() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++wakeups_;
  }
  cv_.notify_all();
}

void WorkerPool::Cancel(const std::string& id) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = running_.find(id);
  if (it != running_.end()) it->second->cancel = true;
  // Its children running here stop at once too (the store asks those elsewhere).
  for (auto& [child, running] : running_) {
    if (running->parent == id) running->cancel = true;
  }
}

void WorkerPool::Shutdown() {
  std::vector<std::thread> threads;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stopping_ = true;
    for (auto& [id, running] : running_) running->shutdown = true;
    threads.swap(threads_);
    if (heartbeat_.joinable()) threads.push_back(std::move(heartbeat_));
  }
  cv_.notify_all();
  for (std::thread& t : threads) t.join();
}

int WorkerPool::running() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return static_cast<int>(running_.size());
}

bool WorkerPool::Sleep(int ms) {
  std::unique_lock<std::mutex> lock(mutex_);
  return !cv_.wait_for(lock, std::chrono::milliseconds(ms), [this] { return stopping_; });
}

void WorkerPool::Loop(const std::string& worker_id, const ClaimOptions& claim) {
  int64_t seen = -1;  // the wakeups_ value of the last look at the store
  for (;;) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stopping_) return;
      seen = wakeups_;
    }
    // Nothing is claimed from a store that cannot record what happens to it.
    StatusOr<std::optional<JobRecord>> claimed =
        store_->Health().ok() ? store_->ClaimNext(worker_id, claim)
                              : StatusOr<std::optional<JobRecord>>(std::nullopt);
    if (claimed.ok() && claimed->has_value()) {
      RunOne(**claimed, worker_id);
      continue;
    }
    if (!claimed.ok()) {
      spdlog::error("{}: claim failed: {}", worker_id, claimed.status().ToString());
    }
    std::unique_lock<std::mutex> lock(mutex_);
    // Sleep until a submit wakes the pool or the poll interval passes.
    cv_.wait_for(lock, std::chrono::milliseconds(options_.idle_poll_ms),
                 [&] { return stopping_ || wakeups_ != seen; });
  }
}

Status WorkerPool::Record(const JobRecord& job, const char* what,
                          const std::function<Status()>& record) {
  int wait_ms = options_.store_retry_ms;
  for (;;) {
    Status s = record();
    if (Final(s)) return s;
    spdlog::error("job {}: cannot record {} ({}); retrying in {} ms once the store recovers",
                  job.id, what, s.ToString(), wait_ms);
    if (!Sleep(wait_ms)) return s;  // Shutting down: the next start recovers the job.
    if (Status probe = store_->Probe(); !probe.ok()) {
      spdlog::warn("job {}: the store is still failing: {}", job.id, probe.ToString());
    }
    wait_ms = std::min(2 * wait_ms, options_.store_retry_max_ms);
  }
}

// One run of one claimed job.
class WorkerPool::Run {
 public:
  // `announce` is called once with the outcome's label just before the outcome is recorded (so
  // that metrics see a run before a client can see it finished).
  Run(WorkerPool* pool, const JobRecord& job, const std::string& worker_id,
      const jobs::JobKindSpec& kind, std::shared_ptr<Running> running,
      std::function<void(const char*, double)> announce, std::string* kept)
      : kept_(kept),
        pool_(pool),
        job_(job),
        worker_id_(worker_id),
        kind_(kind),
        running_(std::move(running)),
        limits_(LimitsOf(pool->options_, kind)),
        writer_(pool->store_, job, kind, limits_.max_result_bytes, pool->options_.chunk_bytes),
        announce_(std::move(announce)),
        started_(Clock::now()),
        last_write_(started_) {}

  // Runs the job and records its outcome; returns the outcome's label.
  const char* Execute() {
    // A trace's tasks, and an optimum's trace's, offered to every worker as child jobs
    // (WorkerPoolOptions::trace_fan_out).
    std::optional<jobs::LocalTraceTasks> local;
    std::optional<StoreTaskRunner> fan_out;
    if ((kind_.kind == v1::TRACE || kind_.kind == v1::OPTIMUM) &&
        pool_->options_.trace_fan_out > 0) {
      StatusOr<jobs::LocalTraceTasks> planned =
          jobs::LocalTraceTasks::ForJob(kind_.kind, job_.request);
      if (planned.ok()) local.emplace(*std::move(planned));  // else RunJob reports the error
    }
    // An optimum map's cells as child jobs: any worker computes them, a later run resumes them.
    std::optional<StoreMapCells> map_cells;
    if (kind_.kind == v1::OPTIMUM_MAP) {
      map_cells.emplace(
          *pool_->store_, job_, worker_id_, pool_->options_.lease_ms,
          [this](const JobRecord& child) { return pool_->RunOne(child, worker_id_); },
          [this] { pool_->Wake(); });
    }
    // A sweep's independent pieces as child jobs, likewise (a sweep of one piece runs here),
    // when another worker may take them: one worker over a store of its own would run them one
    // after the other, where the job's own threads run them at once.
    std::optional<StoreSweepParts> sweep_parts;
    if (kind_.kind == v1::SWEEP && (pool_->options_.workers > 1 || pool_->options_.lease_ms > 0)) {
      sweep_parts.emplace(
          *pool_->store_, job_, worker_id_, pool_->options_.lease_ms,
          [this](const JobRecord& child) { return pool_->RunOne(child, worker_id_); },
          [this] { pool_->Wake(); });
    }
    if (local) {
      FanOutOptions o;
      o.window = static_cast<size_t>(pool_->options_.trace_fan_out);
      o.batch = static_cast<size_t>(pool_->options_.trace_fan_out_batch);
      o.lease_ms = pool_->options_.lease_ms;
      fan_out.emplace(
          *pool_->store_, job_, worker_id_, *local, o,
          [this](const JobRecord& child) -> std::optional<std::string> {
            std::string kept;
            if (!pool_->RunOne(child, worker_id_, &kept)) return std::nullopt;
            return kept;
          },
          [this] { pool_->Wake(); });
    }
    StatusOr<jobs::JobOutput> output =
        jobs::RunJob(kind_, job_.request,
                     {.progress = [this](double f) { return Progress(f); },
                      .on_value = [this](double v) { OnValue(v); },
                      .optimum_cache = &pool_->optimum_cache_,
                      .sink = &writer_,
                      .trace_tasks = fan_out ? &*fan_out : nullptr,
                      .map_cells = map_cells ? &*map_cells : nullptr,
                      .sweep_parts = sweep_parts ? &*sweep_parts : nullptr});
    if (fan_out) {
      spdlog::info(
          "job {}: {} trace tasks, {} of them stored ({} run by other workers, {} claimed back "
          "by the trace) in {} child jobs; {:.2f} s running tasks, {:.2f} s in the store's "
          "calls, {:.2f} s waiting for other workers",
          job_.id, fan_out->tasks(), fan_out->stored(), fan_out->run_elsewhere(),
          fan_out->claimed_here(), fan_out->batches_stored(), fan_out->run_seconds(),
          fan_out->store_seconds(), fan_out->sleep_seconds());
    }
    if (map_cells) {
      spdlog::info("job {}: {} map cells from earlier runs, {} stored, {} of them run here",
                   job_.id, map_cells->resumed(), map_cells->stored(), map_cells->run_here());
    }
    if (sweep_parts && sweep_parts->resumed() + sweep_parts->stored() > 0) {
      spdlog::info("job {}: {} sweep parts from earlier runs, {} stored, {} of them run here",
                   job_.id, sweep_parts->resumed(), sweep_parts->stored(), sweep_parts->run_here());
    }
    return Finish(output);
  }

  double seconds() const { return std::chrono::duration<double>(Clock::now() - started_).count(); }

 private:
  static jobs::KindLimits LimitsOf(const WorkerPoolOptions& options,
                                   const jobs::JobKindSpec& kind) {
    auto it = options.limits.find(kind.name);
    return it != options.limits.end() ? it->second : jobs::KindLimits{};
  }

  void OnValue(double v) {
    if (std::isfinite(v)) current_ = v;
  }

  // Called by the engine on this thread: false stops the run.
  bool Progress(double fraction) {
    if (running_->cancel.load() || running_->shutdown.load() || running_->lost.load() ||
        !writer_.error().ok()) {
      return false;
    }
    const Clock::time_point now = Clock::now();
    if (limits_.max_seconds > 0 &&
        now - started_ > std::chrono::duration<double>(limits_.max_seconds)) {
      deadline_exceeded_ = true;
      return false;
    }
    if (now - last_write_ < std::chrono::milliseconds(pool_->options_.progress_interval_ms)) {
      return true;
    }
    last_write_ = now;
    const double f = std::isfinite(fraction) ? std::clamp(fraction, 0.0, 1.0) : 0.0;
    recorded_current_ = current_;
    if (Status s = pool_->store_->UpdateProgress(job_.id, job_.run, f, current_, writer_.items());
        !s.ok()) {
      spdlog::warn("job {}: progress not recorded: {}", job_.id, s.ToString());
    }
    // A cancel recorded in the store by someone other than this process's CancelOperation.
    StatusOr<bool> requested = pool_->store_->IsCancelRequested(job_.id);
    if (requested.ok() && *requested) running_->cancel = true;
    pool_->hub_->Notify();
    return !running_->cancel.load();
  }

  void Announce(const char* label) {
    if (announced_) return;
    announced_ = true;
    if (announce_) announce_(label, seconds());
  }

  // Records how the run ended; returns the outcome's label.
  const char* Finish(StatusOr<jobs::JobOutput>& output) {
    if (running_->lost.load()) {
      // The job is another run's now (or queued for one): nothing of this run may be recorded.
      Announce("lease_lost");
      return "lease_lost";
    }
    if (!writer_.error().ok()) return Failed(writer_.error(), "too_large");
    if (!output.ok()) return Failed(output.status(), "failed");
    if (output->status == "CANCELLED") {
      if (deadline_exceeded_) {
        return Failed(DeadlineExceeded("the job ran longer than its limit of " +
                                       jobs::HumanSeconds(limits_.max_seconds) +
                                       " (max_seconds of " + kind_.name + " jobs)"),
                      "deadline_exceeded");
      }
      if (running_->shutdown.load() && !running_->cancel.load()) {
        Announce("requeued");
        (void)Store("the requeue", [&] { return store().Requeue(job_.id, job_.run); });
        return "requeued";
      }
      Announce("cancelled");
      (void)Store("the cancel", [&] { return store().MarkCancelled(job_.id, job_.run); });
      return "cancelled";
    }
    google::protobuf::Message& result = *output->result;
    if (Status s = writer_.MoveItemsOf(&result); !s.ok()) return Failed(s, "too_large");
    if (Status s = writer_.Flush(); !s.ok()) return Failed(s, "failed");
    // The last value reached, when no progress record carried it (a short run): one more write.
    if (current_ && current_ != recorded_current_) {
      if (Status s = store().UpdateProgress(job_.id, job_.run, 1.0, current_, writer_.items());
          !s.ok()) {
        spdlog::warn("job {}: final value not recorded: {}", job_.id, s.ToString());
      }
    }
    std::string summary = jobs::DeterministicBytes(result);
    if (kept_ != nullptr) kept_->swap(summary);  // completed with an empty result
    Announce("succeeded");
    Status s = store().Complete(job_.id, job_.run, summary, writer_.items());
    if (s.code() == StatusCode::kResourceExhausted) {
      return Failed(
          ResourceExhausted("the job store's disk is full: the result could not be stored"),
          "failed");
    }
    s = Store(
        "the result", [&] { return store().Complete(job_.id, job_.run, summary, writer_.items()); },
        s);
    if (!s.ok() && kept_ != nullptr) kept_->clear();
    if (s.ok() && kind_.kind == v1::OPTIMUM && pool_->optimum_done_) {
      pool_->optimum_done_(job_.id, job_.cache_key);
    }
    return "succeeded";
  }

  const char* Failed(const Status& status, const char* label) {
    Announce(label);
    (void)Store("the failure",
                [&] { return store().Fail(job_.id, job_.run, status.code(), status.message()); });
    spdlog::info("job {} ({}) failed: {}", job_.id, job_.kind, status.ToString());
    return label;
  }

  // Records with retries (WorkerPool::Record); `first` is the result of a first attempt already
  // made, if any.
  Status Store(const char* what, const std::function<Status()>& record,
               std::optional<Status> first = std::nullopt) {
    if (first && Final(*first)) return *first;
    Status s = pool_->Record(job_, what, record);
    if (!s.ok())
      spdlog::warn("job {} ({}): {} not recorded: {}", job_.id, job_.kind, what, s.ToString());
    return s;
  }

  JobStore& store() { return *pool_->store_; }

  std::string* const kept_;
  WorkerPool* const pool_;
  const JobRecord& job_;
  const std::string& worker_id_;
  const jobs::JobKindSpec& kind_;
  const std::shared_ptr<Running> running_;
  const jobs::KindLimits limits_;
  ResultWriter writer_;
  const std::function<void(const char*, double)> announce_;
  bool announced_ = false;
  const Clock::time_point started_;
  Clock::time_point last_write_;
  std::optional<double> current_, recorded_current_;
  bool deadline_exceeded_ = false;
};

bool WorkerPool::RunOne(const JobRecord& job, const std::string& worker_id, std::string* kept) {
  // A trace's tasks (child jobs) are many and short: logged at debug level.
  const bool child = !job.parent.empty();
  const spdlog::level::level_enum level = child ? spdlog::level::debug : spdlog::level::info;
  auto running = std::make_shared<Running>();
  {
    std::lock_guard<std::mutex> lock(mutex_);
    // A shutdown that began between the claim and now still requeues this job.
    running->shutdown = stopping_;
    running->run = job.run;
    running->parent = job.parent;
    running_[job.id] = running;
  }
  hub_->Notify();  // QUEUED -> RUNNING
  spdlog::log(level, "job {} ({}, {} lane) started, attempt {}", job.id, job.kind,
              LaneName(job.lane), job.attempts);
  const jobs::JobKindSpec* kind = child ? jobs::FindChildKind(job.kind) : jobs::FindKind(job.kind);
  const char* outcome = "failed";
  double seconds = 0;
  if (kind == nullptr) {
    (void)Record(job, "the failure", [&] {
      return store_->Fail(job.id, job.run, StatusCode::kInternal,
                          "unknown job kind '" + job.kind + "'");
    });
  } else {
    engine_runs_.fetch_add(1);
    Run run(
        this, job, worker_id, *kind, running,
        [&](const char* label, double s) {
          if (run_done_) run_done_(job, label, s);
        },
        kept);
    outcome = run.Execute();
    seconds = run.seconds();
  }
  spdlog::log(level, "job {} ({}) {} in {:.3f} s", job.id, job.kind, outcome, seconds);
  {
    std::lock_guard<std::mutex> lock(mutex_);
    running_.erase(job.id);
  }
  hub_->Notify();
  // A large job frees hundreds of MB on its way out (a region's grid, a branch's points), which
  // glibc keeps in its arenas; without this the server's resident memory after the largest trace
  // stays near its peak although nothing holds it. malloc_trim returns the free pages (~ms);
  // not after each of a trace's tasks (the trace goes on holding its curves).
  if (!child) malloc_trim(0);
  return std::string_view(outcome) == "succeeded";
}

}  // namespace drillbif::server
