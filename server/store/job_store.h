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
// - Results are streamed: a running job appends chunks of its result items (AppendResultChunk),
//   in one or more streams (the caller's: one per repeated field of a result, so that each
//   field's items stay together whatever order the run produced them in); Complete makes them
//   the job's result together with a summary, and a run that does not complete leaves nothing
//   behind. Readers page through a stream's chunks (ReadResultChunks) without loading the whole
//   result.
// - Runs are fenced: every claim starts a new run (JobRecord::run); a worker passes its run to
//   the calls that append to or finish it, and a call from a stale run is refused.
// - Store faults (full disk, I/O errors, corruption) are reported with client-readable messages
//   and without SQL; Health() says whether the store can currently write.
// - Child jobs: a RUNNING job's current run may submit child jobs (its tasks, SubmitRequest::
//   parent), which any worker, or the parent itself (ClaimOptions::parent), claims and runs like
//   any job. Children of RUNNING parents are claimed before new top-level jobs, and a parent that
//   leaves RUNNING cancels its unfinished children in the same transaction (docs/store.md, child
//   jobs).
#ifndef DRILLBIF_SERVER_STORE_JOB_STORE_H_
#define DRILLBIF_SERVER_STORE_JOB_STORE_H_

#include <array>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
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

// Cost lanes: how long a job is expected to take. Workers can be dedicated to a lane so that short
// jobs are never stuck behind long ones (ClaimOptions). Stored as integers: never renumber.
inline constexpr int kLaneShort = 0;
inline constexpr int kLaneLong = 1;
// Number of lanes (for arrays indexed by lane).
inline constexpr int kLaneCount = 2;

// "short", "long" ("unknown" for a value outside [0, kLaneCount)).
const char* LaneName(int lane);

// Longest client identity Submit accepts, in bytes (it is stored with every job and named in
// error messages).
inline constexpr size_t kMaxClientBytes = 1024;

// Passed as `run` to the finishing calls by callers that do not fence (any current run).
inline constexpr int64_t kAnyRun = 0;

// Streams of one result (AppendResultChunk): enough for every repeated field of a result.
inline constexpr int kMaxResultStreams = 64;

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
  // Who submitted it ("" = anonymous): claims are fair across clients.
  std::string client;
  // Its cost lane (kLaneShort or kLaneLong).
  int lane = kLaneShort;
  // Number of the current (or last) run: every claim increments it, nothing decrements it (unlike
  // attempts, which Requeue gives back). A worker passes it to AppendResultChunk and to the
  // finishing calls, so that a call from a stale run (the job was requeued and claimed again)
  // is refused. 0 before the first claim.
  int64_t run = 0;
  // While RUNNING with a lease (ClaimOptions::lease_ms): when the lease of the current run
  // expires unless its worker renews it (RenewLease), Unix ms. 0: no lease (the claim holds
  // until the run finishes or RecoverAfterRestart). Meaningless in other states.
  int64_t lease_expires_ms = 0;
  // The id of the job that submitted this one as its child (SubmitRequest::parent); "" for a
  // top-level job.
  std::string parent{};
};

// What to submit.
struct SubmitRequest {
  // Job kind; must not be empty.
  std::string kind;
  // Serialized request proto (may be empty: an all-default proto serializes to nothing).
  std::string request;
  // Content address of the result; empty: no cache lookup and no sharing.
  std::string cache_key;
  // Client idempotency key; empty: none. Kept until the job is deleted (or evicted).
  std::string request_id;
  // Who submits ("" = anonymous; all anonymous jobs count as one client). At most
  // kMaxClientBytes bytes. (Brace-initialized like the fields below, so that callers may
  // aggregate-initialize only the first fields without -Wmissing-field-initializers.)
  std::string client{};
  // Cost lane: kLaneShort or kLaneLong (INVALID_ARGUMENT otherwise).
  int lane = kLaneShort;
  // Refuse the job (RESOURCE_EXHAUSTED) when this many QUEUED jobs that run themselves are
  // waiting already, over all clients and lanes; 0 = no limit. Checked in Submit's transaction,
  // so concurrent submits cannot overshoot it. Cache hits, followers and repeated request_ids
  // are never refused: they add no work.
  int64_t max_queued = 0;
  // The same limit for this request's client alone; 0 = no limit.
  int64_t max_queued_per_client = 0;
  // The job submitting this one as its child (a task of its run); empty: a top-level job. Only
  // the current run of a RUNNING parent may submit children, so that a stale worker cannot spawn
  // work: NOT_FOUND for an unknown parent, FAILED_PRECONDITION when the parent is not RUNNING,
  // shares another job's run, has its cancel requested, or parent_run is not its current run. A
  // child must have an empty cache_key (INVALID_ARGUMENT: it neither uses nor fills the cache)
  // and is never refused by the queue limits above (its parent was admitted with its cost), nor
  // counted by them for other submits. client and lane are the caller's (a parent's runner
  // passes the parent's).
  std::string parent{};
  // The parent's run that submits the child (JobRecord::run of the parent's claim); must be set
  // (>= 1) exactly when parent is (INVALID_ARGUMENT otherwise).
  int64_t parent_run = 0;
};

// Which jobs a worker may claim.
struct ClaimOptions {
  // Lanes the worker takes (kLaneShort, kLaneLong); empty = any lane.
  std::vector<int> lanes;
  // The claim is a lease of this many milliseconds, renewed by the worker's heartbeat
  // (RenewLease); once it expires any process may take the job back (ReclaimExpiredLeases).
  // 0: no lease, for a store that one process uses (its restart recovers every RUNNING job).
  int64_t lease_ms = 0;
  // Non-empty: take only QUEUED children of this job, oldest first (a parent running its own
  // tasks while it waits for them, so that a pool whose every worker runs a parent cannot
  // deadlock). Empty: any claimable job, QUEUED children of RUNNING parents first (oldest child
  // first, whatever their client), then top-level jobs fairly across clients: a worker finishes
  // work already running before it starts new work. Lanes apply either way.
  std::string parent{};

  // INVALID_ARGUMENT naming the field when a lane is out of range or lease_ms is negative.
  Status Validate() const;
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
  // Empty: top-level jobs only (children are listed through their parent). Non-empty: only the
  // children of this job (the same filters and paging).
  std::string parent{};
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
  // QUEUED jobs that a worker can claim (jobs waiting on a shared job are not counted), children
  // included: an autoscaler on queue depth sees the fanned-out work.
  int64_t queue_depth = 0;
  // queue_depth split by lane, indexed by lane.
  std::array<int64_t, kLaneCount> queue_depth_by_lane{};
  // Jobs that ever succeeded without running (cache hits and shared runs). Monotonic: deleting
  // jobs does not decrease it, so it can back a Prometheus counter.
  int64_t cache_hits_total = 0;
  // Bytes of the store's data (for the SQLite store: pages in use times the page size, the size
  // RetentionOptions::max_db_bytes limits).
  int64_t used_bytes = 0;
};

// The stored result of a job, without its streamed items.
struct ResultInfo {
  // The summary bytes given to Complete (the result message without its streamed items).
  std::string summary;
  // Items in the result's chunks (0 when nothing was streamed).
  int64_t total_items = 0;
  // Items of each stream, indexed by stream (empty when nothing was streamed).
  std::vector<int64_t> stream_items;
  // Bytes of the summary plus all chunks: the size of GetResult's answer.
  int64_t total_bytes = 0;
  // The points count given to Complete.
  int64_t points = 0;
};

// One chunk of a result: the serialized bytes of `item_count` consecutive items of stream
// `stream`, starting at the stream's item `first_item` (the store does not interpret the bytes).
struct ResultChunk {
  int stream = 0;
  int64_t first_item = 0;
  int64_t item_count = 0;
  std::string bytes;
};

// Limits for Evict. Only finished jobs (SUCCEEDED, FAILED, CANCELLED) are ever evicted.
struct RetentionOptions {
  // Finished jobs older than this (by finished_ms) are deleted; 0 = no age limit.
  int64_t max_age_ms = 0;
  // While the store's data (StoreStats::used_bytes) is larger than this, the oldest finished jobs
  // are deleted; 0 = no size limit.
  int64_t max_db_bytes = 0;

  // INVALID_ARGUMENT naming the field when a value is negative.
  Status Validate() const;
};

// What Evict did.
struct EvictionReport {
  // Jobs deleted (by age and by size together), and the result rows that went with them.
  int64_t jobs_deleted = 0;
  int64_t results_deleted = 0;
  // StoreStats::used_bytes before and after.
  int64_t used_bytes_before = 0;
  int64_t used_bytes_after = 0;
  // What the store occupies on disk (for SQLite: the file plus its WAL) before and after.
  int64_t disk_bytes_before = 0;
  int64_t disk_bytes_after = 0;
  // False when max_db_bytes was set and could not be reached (what remains is queued, running,
  // followed, or the store's fixed overhead).
  bool size_limit_met = true;
};

// What RecoverAfterRestart or ReclaimExpiredLeases did, counting the jobs that ran (not the jobs
// sharing them).
struct RecoveryReport {
  int requeued = 0;   // RUNNING -> QUEUED: they will run again.
  int cancelled = 0;  // RUNNING with cancel requested -> CANCELLED.
  int failed = 0;     // RUNNING after max_attempts claims -> FAILED (INTERNAL).
};

// One change to the jobs of a store, as a change feed (JobStore::OpenChangeFeed) reports it.
struct JobChange {
  enum class Kind {
    kQueued,   // Job `id` became claimable (a submit or a requeue): idle workers may take it.
    kChanged,  // Job `id` changed what a watcher reads (state, progress, ...).
    kResync,   // Changes may have been missed (the feed reconnected): re-read every job of
               // interest; `id` is empty.
  };
  Kind kind = Kind::kChanged;
  std::string id;
};

// A running change feed. Destroying it stops it: no call of its callback is running or starts
// after the destructor returns.
class JobChangeFeed {
 public:
  virtual ~JobChangeFeed() = default;
};

// Called on the feed's own thread, one change at a time. Must not throw and should return
// quickly (it delays the changes after it).
using JobChangeCallback = std::function<void(const JobChange& change)>;

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
  // INVALID_ARGUMENT when kind is empty. A child (SubmitRequest::parent) is checked against its
  // parent after the request_id lookup (a retried submit returns its job whatever the parent
  // became): see SubmitRequest::parent for its errors.
  virtual StatusOr<SubmitResult> Submit(const SubmitRequest& request) = 0;

  // Atomically takes a claimable QUEUED job of the allowed lanes, makes it RUNNING (with the jobs
  // sharing it), counts the attempt, starts a new run (JobRecord::run + 1) and records
  // worker_id. Fair across clients: the job comes from the client with the fewest RUNNING jobs
  // in those lanes, ties going to the oldest waiting job (so with one client it is FIFO).
  // Returns std::nullopt when no job is waiting. The record includes the request bytes.
  // QUEUED children of RUNNING parents come before top-level jobs, oldest first;
  // ClaimOptions::parent restricts the claim to one parent's children. Leases, runs, attempts and
  // fencing are the same for children. INVALID_ARGUMENT for a bad lane.
  virtual StatusOr<std::optional<JobRecord>> ClaimNext(std::string_view worker_id,
                                                       const ClaimOptions& options) = 0;
  // ClaimNext of any lane.
  StatusOr<std::optional<JobRecord>> ClaimNext(std::string_view worker_id) {
    return ClaimNext(worker_id, ClaimOptions{});
  }

  // Records progress of run `run` of a RUNNING job (and of the jobs sharing it). fraction must
  // be in [0, 1], current_value finite when given, points >= 0 (INVALID_ARGUMENT otherwise).
  // NOT_FOUND for an unknown id, FAILED_PRECONDITION when the job is not RUNNING (e.g. requeued
  // meanwhile) or the run is stale.
  virtual Status UpdateProgress(std::string_view id, int64_t run, double fraction,
                                std::optional<double> current_value, int64_t points) = 0;
  // UpdateProgress without a run fence.
  Status UpdateProgress(std::string_view id, double fraction, std::optional<double> current_value,
                        int64_t points) {
    return UpdateProgress(id, kAnyRun, fraction, current_value, points);
  }

  // Appends a chunk to stream `stream` (in [0, kMaxResultStreams)) of the result of run `run` of
  // a RUNNING job that runs itself: the serialized bytes of `item_count` (>= 1) items starting
  // at the stream's item `first_item`, which must equal the number of items this run appended
  // to that stream so far (a stream's chunks are contiguous and in order). The chunks become
  // the job's result only when the run completes; Requeue, Fail, MarkCancelled and
  // RecoverAfterRestart drop them. Errors: INVALID_ARGUMENT (bad stream or counts, a gap or
  // overlap, bytes larger than the store accepts), NOT_FOUND, FAILED_PRECONDITION (not RUNNING,
  // a follower, or `run` is not the job's current run: a stale worker), RESOURCE_EXHAUSTED (disk
  // full: the chunk is not stored, nothing else changed).
  virtual Status AppendResultChunk(std::string_view id, int64_t run, int stream, int64_t first_item,
                                   int64_t item_count, std::string_view bytes) = 0;

  // RUNNING -> SUCCEEDED, in one transaction: `summary` (the result message without its streamed
  // items; the whole result when nothing was streamed) and the chunks this run appended become
  // the job's result; the jobs sharing it succeed with the same result; with a cache_key, the
  // result fills the cache (if that key has a result already, the first is kept and this run's
  // chunks are dropped). `run` fences a stale worker (kAnyRun: no fence). FAILED_PRECONDITION
  // when the job is not RUNNING (this is what makes a second completion impossible) or the run
  // is stale, NOT_FOUND for an unknown id.
  virtual Status Complete(std::string_view id, int64_t run, std::string_view summary,
                          int64_t points) = 0;
  // Complete without a run fence.
  Status Complete(std::string_view id, std::string_view summary, int64_t points) {
    return Complete(id, kAnyRun, summary, points);
  }

  // RUNNING -> FAILED with an error (code must not be kOk); the jobs sharing it fail with it, and
  // the run's chunks are dropped. Errors as for Complete. After a RESOURCE_EXHAUSTED append or
  // Complete, this small write usually fits; if it fails too, retry once Probe() succeeds
  // (docs/store.md, faults).
  virtual Status Fail(std::string_view id, int64_t run, StatusCode code,
                      std::string_view message) = 0;
  // Fail without a run fence.
  Status Fail(std::string_view id, StatusCode code, std::string_view message) {
    return Fail(id, kAnyRun, code, message);
  }

  // Cancels a job. QUEUED: CANCELLED at once. RUNNING: sets cancel_requested (the worker polls
  // IsCancelRequested, stops and calls MarkCancelled); for a job that shares another, CANCELLED
  // at once (nothing runs for it). CANCELLED: no change (cancel is idempotent). SUCCEEDED or
  // FAILED: FAILED_PRECONDITION. Returns the job's state afterwards. Cancelling a RUNNING parent
  // also cancels its unfinished children in the same transaction: QUEUED ones at once, RUNNING
  // ones by their cancel_requested (each task's worker sees it on its usual poll). (A QUEUED job
  // has no unfinished children: its last run's were cancelled when it left RUNNING.)
  virtual StatusOr<JobState> Cancel(std::string_view id) = 0;

  // Whether Cancel was called on this RUNNING job. NOT_FOUND for an unknown id.
  virtual StatusOr<bool> IsCancelRequested(std::string_view id) = 0;

  // RUNNING -> CANCELLED, called by the worker once it stopped; the run's chunks are dropped. The
  // jobs sharing it are not cancelled: the oldest becomes QUEUED and runs for the others. Errors
  // as for Complete.
  virtual Status MarkCancelled(std::string_view id, int64_t run) = 0;
  // MarkCancelled without a run fence.
  Status MarkCancelled(std::string_view id) { return MarkCancelled(id, kAnyRun); }

  // RUNNING -> QUEUED for a run that was stopped without a result and should run again (graceful
  // shutdown); the interrupted attempt is not counted and its chunks are dropped. Errors as for
  // Complete.
  virtual Status Requeue(std::string_view id, int64_t run) = 0;
  // Requeue without a run fence.
  Status Requeue(std::string_view id) { return Requeue(id, kAnyRun); }

  // One job, with its request bytes unless include_request is false (JobRecord::request empty:
  // what a reader of its state and progress needs, e.g. the watch hub's polls). NOT_FOUND for
  // an unknown id.
  virtual StatusOr<JobRecord> Get(std::string_view id, bool include_request) = 0;
  // Get with the request bytes.
  StatusOr<JobRecord> Get(std::string_view id) { return Get(id, /*include_request=*/true); }

  // A page of jobs matching the filter, oldest first: top-level jobs, or one parent's children
  // (ListRequest::parent). Pages are stable: walking all pages returns every matching job that
  // existed at the first call exactly once, whatever jobs are submitted meanwhile.
  // INVALID_ARGUMENT for a negative page_size or a malformed page_token.
  virtual StatusOr<ListResult> List(const ListRequest& request) = 0;

  // Deletes a finished job (and its result and chunks when no other job uses them), with its
  // finished children (children still stopping after its cancel are left to Evict).
  // FAILED_PRECONDITION for a QUEUED or RUNNING job, NOT_FOUND for an unknown id.
  virtual Status Delete(std::string_view id) = 0;

  // The oldest SUCCEEDED job whose cache_key is `cache_key` (its result is the key's cached
  // result), or nullopt when none: how a process finds a result another process computed.
  // INVALID_ARGUMENT for an empty key.
  virtual StatusOr<std::optional<std::string>> FindSucceeded(std::string_view cache_key) = 0;

  // The whole result of a SUCCEEDED job: the summary followed by every chunk's bytes, in order
  // (for protobuf results whose chunks hold serialized item fields, the complete message). It is
  // held in memory whole: use it for small results (check GetResultInfo's total_bytes) and page
  // through large ones with ReadResultChunks. A cache hit or shared job reads the result
  // computed for the other job. NOT_FOUND for an unknown id, FAILED_PRECONDITION when the job
  // has not succeeded.
  virtual StatusOr<std::string> GetResult(std::string_view id) = 0;

  // The summary and sizes of a SUCCEEDED job's result, without its chunks. Errors as GetResult.
  virtual StatusOr<ResultInfo> GetResultInfo(std::string_view id) = 0;

  // A page of a SUCCEEDED job's result chunks of stream `stream`, in order: the chunk containing
  // the stream's item `first_item` (>= 0) and the ones after it, stopping once their bytes reach
  // `max_bytes` (>= 1); at least one chunk while any remains, none when first_item is at or past
  // the stream's end. Reads only those chunks. The caller skips the items of the first chunk
  // before first_item. INVALID_ARGUMENT for a bad stream, a negative first_item or max_bytes
  // < 1; otherwise errors as GetResult.
  virtual StatusOr<std::vector<ResultChunk>> ReadResultChunks(std::string_view id, int stream,
                                                              int64_t first_item,
                                                              int64_t max_bytes) = 0;

  // Run once at startup, before any worker claims a job: every RUNNING job was interrupted by
  // the end of the previous process. Such a job goes back to QUEUED (with the jobs sharing it),
  // except that one whose cancel was requested becomes CANCELLED, and one already claimed
  // max_attempts times becomes FAILED (INTERNAL) so that a job that kills the process cannot
  // loop forever. QUEUED jobs stay queued. Jobs that share another are counted with it, not
  // separately.
  virtual StatusOr<RecoveryReport> RecoverAfterRestart() = 0;

  // The heartbeat of a leased run: the lease of run `run` of RUNNING job `id` now expires at
  // now + lease_ms. INVALID_ARGUMENT for lease_ms < 1, NOT_FOUND for an unknown id,
  // FAILED_PRECONDITION when the job is not RUNNING or `run` is stale: the lease expired and
  // the job was taken back (and maybe claimed again), so the worker has lost it and must stop
  // it; its Complete, Fail and appends are refused the same way.
  virtual Status RenewLease(std::string_view id, int64_t run, int64_t lease_ms) = 0;

  // Takes back the RUNNING jobs whose lease expired before now_ms (their worker stopped renewing
  // it: it crashed, was stopped or lost the store), as RecoverAfterRestart does for every
  // RUNNING job: back to QUEUED with the attempt counted, CANCELLED when a cancel was asked,
  // FAILED (INTERNAL) after max_attempts claims. Jobs without a lease are left alone. Any
  // process sharing the store may call it, any number of times.
  virtual StatusOr<RecoveryReport> ReclaimExpiredLeases(int64_t now_ms) = 0;

  // Counts for metrics.
  virtual StatusOr<StoreStats> Stats() = 0;

  // OK while the store is usable; otherwise the fault that makes it unusable: a write failed for
  // lack of space (RESOURCE_EXHAUSTED) or an I/O error (UNAVAILABLE), or a read or write found
  // the data corrupt (DATA_LOSS). The fault stays until Probe() succeeds. Cheap (no I/O): the
  // health service can call it on every check.
  virtual Status Health() = 0;

  // Tries a small write transaction and a read; when both succeed, clears the fault Health()
  // reports and returns OK. After a DATA_LOSS fault the read is a full integrity check (it
  // reads the whole store). Returns the error otherwise (the fault stays).
  virtual Status Probe() = 0;

  // Deletes finished jobs by the retention limits (docs/store.md has the order and guarantees):
  // first those finished more than max_age_ms before now_ms, oldest first; then, while the
  // store's data exceeds max_db_bytes, the oldest finished jobs. QUEUED and RUNNING jobs, jobs
  // that a QUEUED or RUNNING job follows, and children of a QUEUED or RUNNING parent (it may
  // still read their results) are never deleted. A result goes with the last job
  // that holds it; request_ids of deleted jobs are forgotten. Then frees the space on disk where
  // the implementation can. INVALID_ARGUMENT for bad options.
  virtual StatusOr<EvictionReport> Evict(const RetentionOptions& options, int64_t now_ms) = 0;

  // Reports the changes that any process sharing the store makes to its jobs, as they commit,
  // to `on_change` (on a thread of the feed's), until the feed is destroyed: for a process that
  // would otherwise poll the store to learn of other processes' work. Delivery is at most
  // once per change and may merge changes; after a break it reports kResync. UNIMPLEMENTED by
  // default: a store that one process owns (SQLite) has no one else's changes to report.
  virtual StatusOr<std::unique_ptr<JobChangeFeed>> OpenChangeFeed(JobChangeCallback on_change) {
    (void)on_change;
    return Status(StatusCode::kUnimplemented, "this job store has no change feed");
  }
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_STORE_JOB_STORE_H_
