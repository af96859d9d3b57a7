// A parent job as the worker running it holds it, for tests of the runners that fan a job out
// as child jobs (server/trace_fan_out.h, server/sweep_fan_out.h): submitted to the store in the
// long lane and claimed.
#ifndef DRILLBIF_TESTS_SUPPORT_CLAIMED_PARENT_H_
#define DRILLBIF_TESTS_SUPPORT_CLAIMED_PARENT_H_

#include <google/protobuf/message.h>

#include <optional>
#include <string>

#include "jobs/request_bytes.h"
#include "server/store/job_store.h"

namespace drillbif::testing {

// Submits a job of `kind` with `request` and claims the next job as `worker`: that job, which
// must be this one (the store holds no other queued job); an error or nullopt otherwise.
inline std::optional<server::JobRecord> SubmitAndClaim(server::JobStore& store,
                                                       const std::string& kind,
                                                       const google::protobuf::Message& request,
                                                       const std::string& worker) {
  server::SubmitRequest submit;
  submit.kind = kind;
  submit.request = jobs::DeterministicBytes(request);
  submit.lane = server::kLaneLong;
  StatusOr<server::SubmitResult> submitted = store.Submit(submit);
  if (!submitted.ok()) return std::nullopt;
  StatusOr<std::optional<server::JobRecord>> claimed = store.ClaimNext(worker);
  if (!claimed.ok() || !claimed->has_value() || (**claimed).id != submitted->id) {
    return std::nullopt;
  }
  return **claimed;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_CLAIMED_PARENT_H_
