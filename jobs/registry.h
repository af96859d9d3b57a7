// The job kinds: one registry entry per kind (simulate, sweep, continue, trace, optimum) holding
// everything the rest of the system needs to know of it: its name, the rpc that submits it, its
// request and result types, which result fields are streamed and paged, how a request is checked
// and its cost estimated without running anything, and how it runs. The server's gRPC services
// and worker pool, the REST gateway (through the services) and drillctl (--local runs, --server
// submits) all go through here, so adding a kind means one entry in registry.cc plus its proto
// messages and its Submit rpc.
//
//   const JobKindSpec* kind = FindKind("sweep");
//   std::unique_ptr<Message> request = kind->NewRequest();   // parse or fill it
//   StatusOr<JobCost> cost = CheckRequest(*kind, *request);   // at submit
//   StatusOr<JobOutput> out = RunJob(*kind, request_bytes, context);
#ifndef DRILLBIF_JOBS_REGISTRY_H_
#define DRILLBIF_JOBS_REGISTRY_H_

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/v1/service.pb.h"
#include "jobs/job_cost.h"
#include "jobs/run_context.h"

namespace drillbif::jobs {

// One job kind. Entries are built once (registry.cc) and never change.
struct JobKindSpec {
  v1::JobKind kind = v1::JOB_KIND_UNSPECIFIED;
  // "simulate": the store's kind string, the REST path /v1/jobs:simulate, drillctl's subcommand.
  std::string name;
  // "SubmitSimulate": the drillbif.v1.Jobs rpc that submits it; its request message holds the
  // kind's request in field `request` and the idempotency key in `request_id`.
  std::string submit_method;
  const google::protobuf::Descriptor* request_type = nullptr;
  const google::protobuf::Descriptor* result_type = nullptr;
  // The result's repeated message fields whose items a run streams (RunContext::sink) and
  // GetResult pages, in the order of the page unit (GetResultRequest.page_size counts them).
  std::vector<std::string> paged_fields;
  // The limits a server applies to the kind unless configured otherwise (job_cost.h): sized so
  // that no accepted job of the kind takes more than ~1 GB on a 2-core machine.
  KindLimits default_limits;
  // Fields of the result's summary sent with the first page only (nested results that can be as
  // large as the whole: the continuation's period-doubled branch, the trace's region).
  std::vector<std::string> first_page_fields;
  // Checks a request without running anything and estimates its cost; INVALID_ARGUMENT naming
  // the field for a bad request. `request` is of request_type.
  std::function<StatusOr<JobCost>(const google::protobuf::Message& request)> plan;
  // Runs a request of request_type; returns the result (of result_type) with its summary and the
  // items it did not stream to `context.sink`. The runners' errors (INVALID_ARGUMENT,
  // FAILED_PRECONDITION, INTERNAL) are errors; a run that starts and then fails or is cancelled is
  // a result with that status.
  std::function<StatusOr<std::unique_ptr<google::protobuf::Message>>(
      const google::protobuf::Message& request, const RunContext& context)>
      run;

  // Fields of the request (dotted paths) that do not change the result, such as the threads it
  // runs on: cleared in its cache key (CacheKeyOf), so that the same computation asked for on
  // other threads is found in the cache.
  std::vector<std::string> key_neutral_fields;

  std::unique_ptr<google::protobuf::Message> NewRequest() const;
  std::unique_ptr<google::protobuf::Message> NewResult() const;
  // Items of the paged fields in `result` (a message of result_type).
  int64_t ItemsOf(const google::protobuf::Message& result) const;
};

// The content address of a request's result (request_bytes.h, CacheKey): its deterministic bytes
// without the kind's key_neutral_fields. `request` is of the kind's request_type.
std::string CacheKeyOf(const JobKindSpec& spec, const google::protobuf::Message& request);

// Every kind, in JobKind order.
const std::vector<const JobKindSpec*>& AllKinds();

// The kind of an enum value, a name, or a request or result type; null for an unknown one.
const JobKindSpec* FindKind(v1::JobKind kind);
const JobKindSpec* FindKind(std::string_view name);
const JobKindSpec* FindKind(const google::protobuf::Descriptor* request_or_result_type);
// The kind of a child job by its store name ("trace_task", jobs/trace_task_job.h): what workers
// run for a parent job; never a kind clients submit (FindKind and AllKinds do not know it). Null
// for an unknown one.
const JobKindSpec* FindChildKind(std::string_view name);

// The submit-time checks of a request: every float and double field (at any depth) is finite
// (else INVALID_ARGUMENT "request.params.xi: ...", `prefix` before the field's path), then the
// kind's own checks (INVALID_ARGUMENT naming the field); returns its estimated cost.
StatusOr<JobCost> CheckRequest(const JobKindSpec& kind, const google::protobuf::Message& request,
                               std::string_view prefix = "request.");

// What a run produced.
struct JobOutput {
  // The result message (of the kind's result_type): its summary and the items not streamed.
  std::unique_ptr<google::protobuf::Message> result;
  // Items streamed to the context's sink.
  int64_t streamed_items = 0;
  // The result's status: "COMPLETED", "CANCELLED", "FAILED", "NOT_FOUND".
  std::string status;
};

// Parses `request_bytes` as the kind's request and runs it. Errors: the runner's; INVALID_ARGUMENT
// for unparsable bytes.
StatusOr<JobOutput> RunJob(const JobKindSpec& kind, std::string_view request_bytes,
                           const RunContext& context);

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_REGISTRY_H_
