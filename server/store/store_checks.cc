#include "server/store/store_checks.h"

#include <utf8cpp/utf8.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iterator>
#include <string>

#include "drillbif/common/checked.h"

namespace drillbif::server {

int64_t NowMs() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

Status NoJob(std::string_view id) { return NotFound("no job '" + std::string(id) + "'"); }

std::string NewJobId(std::random_device& random) {
  char buffer[33];
  std::snprintf(buffer, sizeof(buffer), "%08x%08x%08x%08x", random(), random(), random(), random());
  return std::string(buffer, 32);
}

Status CheckRunning(std::string_view id, const char* action, int64_t run, const JobHead& head) {
  const std::string what = std::string("cannot ") + action + " job '" + std::string(id) + "': ";
  if (head.state != kRunning) {
    return FailedPrecondition(what + "it is " + JobStateName(static_cast<JobState>(head.state)) +
                              ", not RUNNING");
  }
  if (head.shares) {
    return FailedPrecondition(what + "it shares another job's run and is not run by a worker");
  }
  if (run != kAnyRun && run != head.run) {
    return FailedPrecondition(what + "this is run " + std::to_string(run) +
                              " but the job is at run " + std::to_string(head.run) +
                              " (it was requeued and claimed again: this run is stale)");
  }
  return Status::Ok();
}

std::string ResultKey(const SubmitRequest& request, const std::string& id) {
  return request.cache_key.empty() ? "j:" + id : "c:" + request.cache_key;
}

Status CheckText(const char* field, std::string_view text) {
  if (text.find('\0') != std::string_view::npos) {
    return InvalidArgument(std::string(field) + ": contains a NUL byte");
  }
  if (!utf8::is_valid(text.begin(), text.end())) {
    return InvalidArgument(std::string(field) + ": is not valid UTF-8");
  }
  return Status::Ok();
}

std::string StoredText(std::string_view text) {
  std::string valid;
  valid.reserve(text.size());
  utf8::replace_invalid(text.begin(), text.end(), std::back_inserter(valid));
  std::string out;
  out.reserve(valid.size());
  for (const char c : valid) {
    if (c == '\0') {
      out += "\xEF\xBF\xBD";  // U+FFFD
    } else {
      out += c;
    }
  }
  return out;
}

Status CheckSubmit(const SubmitRequest& request) {
  if (request.kind.empty()) return InvalidArgument("kind: must not be empty");
  DRILLBIF_RETURN_IF_ERROR(CheckText("kind", request.kind));
  DRILLBIF_RETURN_IF_ERROR(CheckText("cache_key", request.cache_key));
  DRILLBIF_RETURN_IF_ERROR(CheckText("request_id", request.request_id));
  DRILLBIF_RETURN_IF_ERROR(CheckText("client", request.client));
  if (request.lane < 0 || request.lane >= kLaneCount) {
    return InvalidArgument("lane: must be 0 (short) or 1 (long), got " +
                           std::to_string(request.lane));
  }
  if (request.client.size() > kMaxClientBytes) {
    return InvalidArgument("client: " + std::to_string(request.client.size()) + " bytes, at most " +
                           std::to_string(kMaxClientBytes));
  }
  if (request.max_queued < 0) return InvalidArgument("max_queued: must be >= 0 (0 = no limit)");
  if (request.max_queued_per_client < 0) {
    return InvalidArgument("max_queued_per_client: must be >= 0 (0 = no limit)");
  }
  DRILLBIF_RETURN_IF_ERROR(CheckText("parent", request.parent));
  if (request.parent.empty()) {
    if (request.parent_run != 0) return InvalidArgument("parent_run: set without a parent");
    return Status::Ok();
  }
  if (request.parent_run < 1) {
    return InvalidArgument("parent_run: must be >= 1 (the parent's run that submits the child)");
  }
  if (!request.cache_key.empty()) {
    return InvalidArgument("cache_key: a child job neither uses nor fills the cache");
  }
  return Status::Ok();
}

Status CheckParent(std::string_view parent, int64_t parent_run, const JobHead* head) {
  if (head == nullptr) return NotFound("parent: no job '" + std::string(parent) + "'");
  DRILLBIF_RETURN_IF_ERROR(CheckRunning(parent, "submit a child of", parent_run, *head));
  if (head->cancel_requested) {
    return FailedPrecondition("cannot submit a child of job '" + std::string(parent) +
                              "': its cancel was requested");
  }
  return Status::Ok();
}

Status CheckProgress(double fraction, std::optional<double> current_value, int64_t points) {
  if (!(fraction >= 0.0 && fraction <= 1.0)) {
    return InvalidArgument("progress fraction must be in [0, 1] (got " + std::to_string(fraction) +
                           ")");
  }
  if (current_value && !std::isfinite(*current_value)) {
    return InvalidArgument("current value must be finite");
  }
  if (points < 0) return InvalidArgument("points must be >= 0");
  return Status::Ok();
}

Status CheckChunk(int64_t run, int stream, int64_t first_item, int64_t item_count) {
  if (run < 1) return InvalidArgument("run: must be >= 1 (the run from the claimed JobRecord)");
  if (stream < 0 || stream >= kMaxResultStreams) {
    return InvalidArgument("stream: must be in [0, " + std::to_string(kMaxResultStreams) +
                           "), got " + std::to_string(stream));
  }
  if (first_item < 0) return InvalidArgument("first_item: must be >= 0");
  if (item_count < 1) return InvalidArgument("item_count: must be >= 1");
  if (!CheckedAdd(first_item, item_count)) {
    return InvalidArgument("first_item + item_count: beyond 2^63 - 1");
  }
  return Status::Ok();
}

Status CheckChunkRead(int stream, int64_t first_item, int64_t max_bytes) {
  if (stream < 0 || stream >= kMaxResultStreams) {
    return InvalidArgument("stream: must be in [0, " + std::to_string(kMaxResultStreams) + ")");
  }
  if (first_item < 0) return InvalidArgument("first_item: must be >= 0");
  if (max_bytes < 1) return InvalidArgument("max_bytes: must be >= 1");
  return Status::Ok();
}

Status CheckSize(const char* field, size_t size, int64_t max_value_bytes) {
  if (size > static_cast<uint64_t>(max_value_bytes)) {
    return InvalidArgument(std::string(field) + ": " + std::to_string(size) +
                           " bytes, more than the job store accepts (" +
                           std::to_string(max_value_bytes) + ")");
  }
  return Status::Ok();
}

Status CheckQueueLimits(const SubmitRequest& request, int64_t waiting_of_client, int64_t waiting) {
  if (request.max_queued_per_client > 0 && waiting_of_client >= request.max_queued_per_client) {
    const std::string who = request.client.empty() ? std::string("anonymous clients have ")
                                                   : "client '" + request.client + "' has ";
    return ResourceExhausted(who + std::to_string(waiting_of_client) + " jobs waiting (limit " +
                             std::to_string(request.max_queued_per_client) + "); retry later");
  }
  if (request.max_queued > 0 && waiting >= request.max_queued) {
    return ResourceExhausted("the job queue is full: " + std::to_string(waiting) +
                             " jobs waiting (limit " + std::to_string(request.max_queued) +
                             "); retry later");
  }
  return Status::Ok();
}

Status RequestIdReused(const std::string& request_id, const std::string& id) {
  return FailedPrecondition("request_id '" + request_id +
                            "' was already used for a different request (job '" + id + "')");
}

Status NotFinished(std::string_view id, JobState state) {
  return FailedPrecondition("job '" + std::string(id) + "' is " + JobStateName(state) +
                            ": cancel it and wait until it is finished before deleting it");
}

Status AlreadyFinished(std::string_view id, JobState state) {
  return FailedPrecondition("job '" + std::string(id) + "' already finished (" +
                            JobStateName(state) + ")");
}

int64_t ClaimedLeaseExpiry(int64_t now_ms, int64_t lease_ms) {
  return lease_ms == 0 ? 0 : CheckedAdd(now_ms, lease_ms).value_or(INT64_MAX);
}

StatusOr<int64_t> RenewedLeaseExpiry(int64_t lease_ms) {
  if (lease_ms < 1) return InvalidArgument("lease_ms: must be >= 1");
  const std::optional<int64_t> expires = CheckedAdd(NowMs(), lease_ms);
  if (!expires) return InvalidArgument("lease_ms: now + lease_ms beyond 2^63 - 1");
  return *expires;
}

TakeBackAction TakeBackActionOf(bool cancel_requested, int attempts, int max_attempts) {
  if (cancel_requested) return TakeBackAction::kCancel;
  return attempts >= max_attempts ? TakeBackAction::kFail : TakeBackAction::kRequeue;
}

std::string TooManyAttempts(TakenBack why, int attempts, int max_attempts) {
  const char* what = why == TakenBack::kRestart
                         ? "the server stopped while this job ran, "
                         : "the worker running this job stopped renewing its lease, ";
  return what + std::to_string(attempts) + " times; not retried (max_attempts " +
         std::to_string(max_attempts) + ")";
}

std::string PageToken(int64_t seq) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "p%llx", static_cast<unsigned long long>(seq));
  return buffer;
}

StatusOr<int64_t> ParsePageToken(const std::string& token) {
  if (token.empty()) return int64_t{0};
  const auto bad = [&] {
    // Echo at most 40 bytes of a hostile token.
    return InvalidArgument("page_token: malformed '" + token.substr(0, 40) +
                           (token.size() > 40 ? "...'" : "'"));
  };
  if (token.size() < 2 || token.size() > 17 || token[0] != 'p') return bad();
  std::optional<int64_t> seq = 0;
  for (size_t i = 1; i < token.size(); ++i) {
    const char c = token[i];
    int digit;
    if (c >= '0' && c <= '9') {
      digit = c - '0';
    } else if (c >= 'a' && c <= 'f') {
      digit = c - 'a' + 10;
    } else {
      return bad();
    }
    seq = CheckedAdd(CheckedMul(seq, int64_t{16}), int64_t{digit});
    if (!seq) return bad();
  }
  return *seq;
}

int PageSize(int requested, int default_page_size, int max_page_size) {
  return requested == 0 ? default_page_size : std::min(requested, max_page_size);
}

int64_t LaneMask(const ClaimOptions& options) {
  if (options.lanes.empty()) return INT64_MAX;
  int64_t mask = 0;
  for (const int lane : options.lanes) mask |= int64_t{1} << lane;
  return mask;
}

}  // namespace drillbif::server
