// What every JobStore implementation checks the same way, whatever its database: the arguments
// of each call (before any I/O), the state checks of a job that a call finishes or appends to,
// job ids, page tokens and the errors users see. Internal to server/store/.
#ifndef DRILLBIF_SERVER_STORE_STORE_CHECKS_H_
#define DRILLBIF_SERVER_STORE_STORE_CHECKS_H_

#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <string_view>

#include "drillbif/common/status.h"
#include "server/store/job_store.h"

namespace drillbif::server {

// JobState values as stored.
inline constexpr int kQueued = static_cast<int>(JobState::kQueued);
inline constexpr int kRunning = static_cast<int>(JobState::kRunning);
inline constexpr int kSucceeded = static_cast<int>(JobState::kSucceeded);
inline constexpr int kFailed = static_cast<int>(JobState::kFailed);
inline constexpr int kCancelled = static_cast<int>(JobState::kCancelled);

// Unix time in milliseconds.
int64_t NowMs();

// NOT_FOUND "no job '<id>'".
Status NoJob(std::string_view id);

// A new job id: 32 lowercase hex digits, 128 bits from the OS entropy source on every call (no
// generator state to duplicate across fork(): two processes sharing a store must never draw the
// same ids).
std::string NewJobId(std::random_device& random);

// The part of a job the state checks need.
struct JobHead {
  int state = 0;
  bool shares = false;  // It follows another job.
  bool cancel_requested = false;
  int attempts = 0;
  int64_t run = 0;
  int64_t streamed_items = 0;  // Items appended by the current run.
  int64_t streamed_bytes = 0;  // Their bytes.
  std::string result_key;
};

// The job must be RUNNING, run itself (not share another) and, unless run is kAnyRun, be at that
// run: only the worker of its current run acts on it. FAILED_PRECONDITION "cannot <action> job
// '<id>': ..." otherwise.
Status CheckRunning(std::string_view id, const char* action, int64_t run, const JobHead& head);

// The result row's key of a new job: "c:" + cache_key for cached jobs (content-addressed:
// identical requests share one row), "j:" + id otherwise.
std::string ResultKey(const SubmitRequest& request, const std::string& id);

// Argument checks, before any I/O; INVALID_ARGUMENT naming the field.
// Text the store keeps as text (kind, cache_key, request_id, client): valid UTF-8 without NUL
// bytes, which every database's text type holds as it is (PostgreSQL's refuses both, and a
// driver passing C strings would cut the text at a NUL: two request_ids could become one).
Status CheckText(const char* field, std::string_view text);
// Includes the child rules that need no I/O: parent_run set exactly with parent, no cache_key.
Status CheckSubmit(const SubmitRequest& request);
// Whether run `parent_run` of job `parent` (its head, nullptr when there is no such job) may
// submit a child: NOT_FOUND "parent: no job ..." for none; FAILED_PRECONDITION unless it is
// RUNNING, runs itself, is at that run and has no cancel requested (a stale or stopping run must
// not spawn work).
Status CheckParent(std::string_view parent, int64_t parent_run, const JobHead* head);
Status CheckProgress(double fraction, std::optional<double> current_value, int64_t points);
Status CheckChunk(int64_t run, int stream, int64_t first_item, int64_t item_count);
Status CheckChunkRead(int stream, int64_t first_item, int64_t max_bytes);
// A value of `size` bytes against the database's limit on one value.
Status CheckSize(const char* field, size_t size, int64_t max_value_bytes);

// `text` as the store keeps a message or a name it did not choose (a failure's message, a
// worker id): invalid UTF-8 and NUL bytes replaced by U+FFFD, so that recording an outcome never
// fails on its text.
std::string StoredText(std::string_view text);

// RESOURCE_EXHAUSTED when a new QUEUED job would exceed the request's limits, given the jobs
// waiting from its client and from every client.
Status CheckQueueLimits(const SubmitRequest& request, int64_t waiting_of_client, int64_t waiting);

// FAILED_PRECONDITION for a request_id already used by job `id` for another kind or request.
Status RequestIdReused(const std::string& request_id, const std::string& id);

// FAILED_PRECONDITION for Delete of a job that is not finished.
Status NotFinished(std::string_view id, JobState state);

// FAILED_PRECONDITION for Cancel of a job that finished with a result or an error.
Status AlreadyFinished(std::string_view id, JobState state);

// When a lease claimed at now_ms for lease_ms expires: 0 for no lease (lease_ms 0); INT64_MAX,
// never, for a lease that ends beyond the clock's range (any lease_ms >= 0 is valid input).
int64_t ClaimedLeaseExpiry(int64_t now_ms, int64_t lease_ms);
// When a lease renewed now for lease_ms expires; INVALID_ARGUMENT for lease_ms < 1 or an end
// beyond 2^63 - 1.
StatusOr<int64_t> RenewedLeaseExpiry(int64_t lease_ms);

// Why a RUNNING job is taken back: its process ended (RecoverAfterRestart) or its lease expired
// (ReclaimExpiredLeases).
enum class TakenBack { kRestart, kLeaseExpired };

// What taking back a RUNNING job does to it: CANCELLED when a cancel was asked, FAILED after
// max_attempts claims, else QUEUED again.
enum class TakeBackAction { kCancel, kFail, kRequeue };
TakeBackAction TakeBackActionOf(bool cancel_requested, int attempts, int max_attempts);

// The message of a job failed when taken back after too many claims.
std::string TooManyAttempts(TakenBack why, int attempts, int max_attempts);

// Page tokens are "p" + the hex seq of the last job returned: opaque to clients, checked on use.
std::string PageToken(int64_t seq);
// The seq in a page token (0 for an empty token); INVALID_ARGUMENT for anything but "p" + 1 to
// 16 lowercase hex digits whose value fits an int64 (a token never wraps to a small or negative
// seq).
StatusOr<int64_t> ParsePageToken(const std::string& token);
// List's page size for a request's page_size (0: the default; larger than the maximum: capped).
int PageSize(int requested, int default_page_size, int max_page_size);

// Bit mask of the lanes a claim may take (every bit for "any lane").
int64_t LaneMask(const ClaimOptions& options);

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_STORE_STORE_CHECKS_H_
