// The job kinds of the service: what the store's `kind` strings mean, how a request of each kind
// is checked, keyed and run (through the client library's job runners, the one boundary between
// protos and the engine), and how its result is counted and paged. The gRPC layer and the worker
// pool both go through here, so that a kind is defined in one place.
#ifndef DRILLBIF_JOBS_JOB_KINDS_H_
#define DRILLBIF_JOBS_JOB_KINDS_H_

#include <google/protobuf/message.h>

#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>

#include "drillbif/common/status.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/v1/service.pb.h"
#include "jobs/optimum_cache.h"

namespace drillbif::jobs {

// The store's kind strings ("simulate", "sweep", "continue", "trace", "optimum").
const char* KindName(v1::JobKind kind);

// The kind of a store kind string; JOB_KIND_UNSPECIFIED for an unknown one.
v1::JobKind KindOf(std::string_view name);

// The result message's full name of a kind ("drillbif.v1.SweepResult"), for Any type URLs.
std::string ResultTypeName(v1::JobKind kind);

// The deterministic serialization of a message: the same message gives the same bytes in this
// build (map entries sorted, fields in number order). The cache key and the store's request
// bytes use it.
std::string DeterministicBytes(const google::protobuf::Message& message);

// Hex SHA-256 (64 lowercase digits) of the kind, the engine version (EngineVersion()) and the
// request bytes, each length-prefixed so that no two different triples hash the same input:
// the content address of a result. The request_id is never part of `request_bytes`.
std::string CacheKey(v1::JobKind kind, std::string_view request_bytes);

// Hex SHA-256 of `data` (64 lowercase digits).
std::string Sha256Hex(std::string_view data);

// Checks that can be made at submit without running anything: every float and double field of
// the request (at any depth) is finite, and the model parameters are in their domain.
// INVALID_ARGUMENT naming the field ("request.params.xi: ...") otherwise. The job runner makes
// all other checks when the job runs (they then fail the operation with INVALID_ARGUMENT).
Status ValidateAtSubmit(v1::JobKind kind, const google::protobuf::Message& request);

// What a run produced.
struct JobOutput {
  // The serialized result message of the kind.
  std::string result;
  // Points of the result, in GetResult's page unit (see PointsOf).
  int64_t points = 0;
  // The runner stopped because the progress callback returned false (result status CANCELLED).
  bool cancelled = false;
};

// Parses `request_bytes` as the request message of `kind` and runs its job runner (RunSimulate,
// RunSweep, RunContinue, RunTrace, RunOptimum). Errors: the runner's (INVALID_ARGUMENT,
// FAILED_PRECONDITION, INTERNAL); INVALID_ARGUMENT for an unknown kind or unparsable bytes.
// `progress` as in the runners (fraction in [0, 1]; return false to cancel); `value` (optional)
// receives the current parameter value where the kind has one (sweep: the grid point finished
// last; continue: each accepted point). `optimum_cache` (optional) is RunOptimum's cache, which
// RunTrace fills too.
StatusOr<JobOutput> RunJob(v1::JobKind kind, std::string_view request_bytes,
                           const ProgressCallback& progress,
                           const std::function<void(double)>& value = {},
                           jobs::OptimumCache* optimum_cache = nullptr);

// The number of points a request of `kind` will produce, when known before the run (sweep:
// steps times directions), else 0. Used to estimate JobMetadata.points from the progress.
int64_t ExpectedPoints(v1::JobKind kind, std::string_view request_bytes);

// Fills `response` with the result `result_bytes` of `kind`, whole (page_size 0) or the page at
// `page_token` (GetResultRequest's semantics). INVALID_ARGUMENT for a negative or too large
// page_size or a malformed token; INTERNAL for unparsable bytes.
Status PageResult(v1::JobKind kind, std::string_view result_bytes, int page_size,
                  std::string_view page_token, v1::GetResultResponse* response);

// Largest GetResultRequest.page_size.
inline constexpr int kMaxResultPageSize = 100000;

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_JOB_KINDS_H_
