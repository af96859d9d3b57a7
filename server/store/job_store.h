// JobStore: the persistent record of the service's jobs, their results and the result cache.
//
// The store sees only bytes (serialized request and result protos) and keys; it never parses a
// request and never runs the engine. It is an interface so that a server database can replace
// the embedded SQLite file (sqlite_job_store.h) for multi-machine deployments.
//
// Life of a job (docs/store.md has the full semantics):
//
//   Submit ──► QUEUED ──ClaimNext──► RUNNING ──Complete──► SUCCEEDED
//                │                     │ ├────Fail──────► FAILED
//                │ Cancel              │ └─MarkCancelled► CANCELLED   (after Cancel set the flag)
//                ▼                     │
//            CANCELLED                 └─Requeue / RecoverAfterRestart──► QUEUED
//
// Guarantees every implementation must keep:
// - A job's result is written in the same transaction as its change to SUCCEEDED: a job that
//   reads SUCCEEDED always has its result, after any crash.
// - Exactly-once completion: Complete, Fail and MarkCancelled only act on a RUNNING job, checked
//   in the same statement that changes the state; a second attempt gets FAILED_PRECONDITION and
//   changes nothing. Runs are at-least-once: a run interrupted by a crash is run again after
//   RecoverAfterRestart.
// - Identical requests (same non-empty cache_key) share one result: a submit after a success is
//   a cache hit that never runs; a submit while an identical job is queued or running follows
//   that job ("shares" it) and finishes with it.
// - Submits with the same non-empty request_id return the same job (idempotent retries).
#ifndef DRILLBIF_SERVER_STORE_JOB_STORE_H_
#define DRILLBIF_SERVER_STORE_JOB_STORE_H_

#include <array>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "drillbif/common/status.h"

namespace drillbif::server {

// The state of a job. The numeric values are stored in the database: never renumber them.
enum class JobState {
  kQueued = 0,     // Waiting for a worker (or, when it shares another job, for that job).
  kRunning = 1,    // Claimed by a worker (or sharing a job that is running).
  kSucceeded = 2,  // Finished with a result (GetResult returns it).
  kFailed = 3,     // Finished with an error code and message.
  kCancelled = 4,  // Cancelled before it finished.
};

// Number of JobState values (for arrays indexed by state).
inline constexpr int kJobStateCount = 5;

// "QUEUED", "RUNNING", "SUCCEEDED", "FAILED", "CANCELLED".
const char* JobStateName(JobState state);

// True for SUCCEEDED, FAILED and CANCELLED: the states a job never leaves.
inline bool IsFinished(JobState state) {
  return state == JobState::kSucceeded || state == JobState::kFailed ||
         state == JobState::kCancelled;
}

// One job as stored. Timestamps are Unix time in milliseconds, 0 when the event has not happened.
struct JobRecord {
  // Opaque id: 32 lowercase hex digits (128 random bits). Never reused.
  std::string id;
  // What to run: "simulate", "sweep", "continue", "trace", "optimum", ... (the store does not
  // interpret it; the job runner does).
  std::string kind;
  JobState state = JobState::kQueued;
  // The serialized request proto. Empty in records returned by List unless asked for (it can be
  // large).
  std::string request;
  // Content address of the result (hash of the canonical request and the engine version); empty
  // when the job must neither use nor fill the cache.
  std::string cache_key;
  // The client's idempotency key; empty when the client gave none.
  std::string request_id;
  // Id of the job this one shares (the one that runs for both), empty when it runs itself.
  std::string shared_with;
  // Fraction of the work done, in [0, 1]; 1 when SUCCEEDED.
  double progress = 0.0;
  // Current value of the swept or continued parameter, when the job reports one.
  std::optional<double> current_value;
  // Points (samples, branch points, curve points) computed so far; the final count when finished.
  int64_t points = 0;
  // Why a FAILED job failed: a gRPC status code (never OK for a failed job) and a message.
  StatusCode error_code = StatusCode::kOk;
  std::string error_message;
  int64_t created_ms = 0;
  int64_t started_ms = 0;   // When it (or the job it shares) was last claimed.
  int64_t finished_ms = 0;  // When it reached a finished state.
  // True when it succeeded with a result computed for another job (the cache or a shared run):
  // the engine did not run for it.
  bool cache_hit = false;
  // How many times a worker claimed it (more than 1 after a crash or a requeue).
  int attempts = 0;
  // Cancel was asked while it ran; the worker stops and calls MarkCancelled.
  bool cancel_requested = false;
  // The worker that claimed it last (empty if never claimed).
  std::string worker_id;
};

// What to submit.
struct SubmitRequest {
  // Job kind; must not be empty.
  std::string kind;
  // Serialized request proto (may be empty: an all-default proto serializes to nothing).
  std::string request;
  // Content address of the result; empty: no cache lookup and no sharing.
  std::string cache_key;
  // Client idempotency key; empty: none. Kept until the job is deleted.
  std::string request_id;
};

// What Submit did.
struct SubmitResult {
  // The job to report to the client (new, or the existing one for a repeated request_id).
  std::string id;
  // The request_id was seen before: no new job was created, `id` is the earlier job.
  bool deduplicated = false;
  // A result for cache_key existed: the job was created SUCCEEDED and will never run.
  bool cache_hit = false;
  // The job follows a queued or running job with the same cache_key (its id); empty otherwise.
  std::string shared_with;
};

// Which jobs List returns and which page.
struct ListRequest {
  // Only jobs in this state (all states when empty).
  std::optional<JobState> state;
  // Only jobs of this kind (all kinds when empty).
  std::string kind;
  // Jobs per page; 0 means the implementation's default; larger values are capped. Negative is
  // INVALID_ARGUMENT.
  int page_size = 0;
  // Token from the previous page's next_page_token; empty for the first page. Use it only with
  // the same filter.
  std::string page_token;
  // Also return each job's request bytes.
  bool include_request = false;
};

// One page of jobs, oldest first (the order of submission).
struct ListResult {
  std::vector<JobRecord> jobs;
  // Token for the next page; empty when this is the last page.
  std::string next_page_token;
};

// Counters for metrics.
struct StoreStats {
  // Number of jobs in each state, indexed by static_cast<int>(JobState).
  std::array<int64_t, kJobStateCount> jobs_by_state{};
  // QUEUED jobs that a worker can claim (jobs waiting on a shared job are not counted).
  int64_t queue_depth = 0;
  // Jobs that ever succeeded without running (cache hits and shared runs). Monotonic: deleting
  // jobs does not decrease it, so it can back a Prometheus counter.
  int64_t cache_hits_total = 0;
};

// What RecoverAfterRestart did, counting the jobs that ran (not the jobs sharing them).
struct RecoveryReport {
  int requeued = 0;   // RUNNING -> QUEUED: they will run again.
  int cancelled = 0;  // RUNNING with cancel requested -> CANCELLED.
  int failed = 0;     // RUNNING after max_attempts claims -> FAILED (INTERNAL).
};

// The job store. Implementations are thread-safe: every method may be called from any thread.
// All methods return an error Status instead of throwing.
class JobStore {
 public:
  virtual ~JobStore() = default;

  // Creates a job, or returns the existing one:
  // - request_id non-empty and already used: returns that job (deduplicated = true) if kind and
  //   request bytes are identical, FAILED_PRECONDITION otherwise (the gRPC code ALREADY_EXISTS
  //   would fit better, but drillbif::StatusCode does not have it yet).
  // - cache_key non-empty with a stored result: the job is created SUCCEEDED with cache_hit set.
  // - cache_key non-empty with a QUEUED or RUNNING job of that key (not being cancelled): the job
  //   shares it: it mirrors that job's state and progress, is never claimed itself, and finishes
  //   when that job does (see docs/store.md for failure and cancellation).
  // - otherwise the job is QUEUED.
  // INVALID_ARGUMENT when kind is empty.
  virtual StatusOr<SubmitResult> Submit(const SubmitRequest& request) = 0;

  // Atomically takes the oldest claimable QUEUED job, makes it RUNNING (with the jobs sharing
  // it), counts the attempt and records worker_id. Returns std::nullopt when no job is waiting.
  // The record includes the request bytes.
  virtual StatusOr<std::optional<JobRecord>> ClaimNext(std::string_view worker_id) = 0;

  // Records progress of a RUNNING job (and of the jobs sharing it). fraction must be in [0, 1],
  // current_value finite when given, points >= 0 (INVALID_ARGUMENT otherwise). NOT_FOUND for an
  // unknown id, FAILED_PRECONDITION when the job is not RUNNING (e.g. requeued meanwhile).
  virtual Status UpdateProgress(std::string_view id, double fraction,
                                std::optional<double> current_value, int64_t points) = 0;

  // RUNNING -> SUCCEEDED with its result, in one transaction; the jobs sharing it succeed with
  // the same result; with a cache_key, the result fills the cache. FAILED_PRECONDITION when the
  // job is not RUNNING (this is what makes a second completion impossible), NOT_FOUND for an
  // unknown id.
  virtual Status Complete(std::string_view id, std::string_view result, int64_t points) = 0;

  // RUNNING -> FAILED with an error (code must not be kOk); the jobs sharing it fail with it.
  // Errors as for Complete.
  virtual Status Fail(std::string_view id, StatusCode code, std::string_view message) = 0;

  // Cancels a job. QUEUED: CANCELLED at once. RUNNING: sets cancel_requested (the worker polls
  // IsCancelRequested, stops and calls MarkCancelled); for a job that shares another, CANCELLED
  // at once (nothing runs for it). CANCELLED: no change (cancel is idempotent). SUCCEEDED or
  // FAILED: FAILED_PRECONDITION. Returns the job's state afterwards.
  virtual StatusOr<JobState> Cancel(std::string_view id) = 0;

  // Whether Cancel was called on this RUNNING job. NOT_FOUND for an unknown id.
  virtual StatusOr<bool> IsCancelRequested(std::string_view id) = 0;

  // RUNNING -> CANCELLED, called by the worker once it stopped. The jobs sharing it are not
  // cancelled: the oldest becomes QUEUED and runs for the others. Errors as for Complete.
  virtual Status MarkCancelled(std::string_view id) = 0;

  // RUNNING -> QUEUED for a run that was stopped without a result and should run again (graceful
  // shutdown); the interrupted attempt is not counted. Errors as for Complete.
  virtual Status Requeue(std::string_view id) = 0;

  // One job, with its request bytes. NOT_FOUND for an unknown id.
  virtual StatusOr<JobRecord> Get(std::string_view id) = 0;

  // A page of jobs matching the filter, oldest first. Pages are stable: walking all pages returns
  // every matching job that existed at the first call exactly once, whatever jobs are submitted
  // meanwhile. INVALID_ARGUMENT for a negative page_size or a malformed page_token.
  virtual StatusOr<ListResult> List(const ListRequest& request) = 0;

  // Deletes a finished job (and its result when no other job uses it). FAILED_PRECONDITION for a
  // QUEUED or RUNNING job, NOT_FOUND for an unknown id.
  virtual Status Delete(std::string_view id) = 0;

  // The result bytes of a SUCCEEDED job, wherever they are stored (a cache hit or shared job
  // reads the result computed for the other job). NOT_FOUND for an unknown id,
  // FAILED_PRECONDITION when the job has not succeeded.
  virtual StatusOr<std::string> GetResult(std::string_view id) = 0;

  // Run once at startup, before any worker claims a job: every RUNNING job was interrupted by
  // the end of the previous process. Such a job goes back to QUEUED (with the jobs sharing it),
  // except that one whose cancel was requested becomes CANCELLED, and one already claimed
  // max_attempts times becomes FAILED (INTERNAL) so that a job that kills the process cannot
  // loop forever. QUEUED jobs stay queued. Jobs that share another are counted with it, not
  // separately.
  virtual StatusOr<RecoveryReport> RecoverAfterRestart() = 0;

  // Counts for metrics.
  virtual StatusOr<StoreStats> Stats() = 0;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_STORE_JOB_STORE_H_
