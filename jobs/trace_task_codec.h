// A trace's tasks and their results as bytes (proto/drillbif/v1/trace_task.proto), for the child
// jobs a fanned-out trace stores: the parent encodes a batch of consecutive tasks with its own
// request, a worker decodes and runs them in order (RunTraceTask, continuation/trace_tasks.h) and
// encodes their results, and the parent decodes the results and applies them. One task and one
// result have codecs of their own (a batch's elements).
//
// Contract: the round trip is exact. Decoding an encoding gives values equal field for field to
// the ones encoded, every double bit for bit (NaN payloads and -0.0 included), every string byte
// for byte, every status code and message; so the parent's network is the one it would compute
// alone. Encoding is deterministic: encoding a decoded value gives the same bytes again.
//
// Decoding takes any bytes (a store row may be damaged, or written by another build): it never
// crashes, and every malformed input is INVALID_ARGUMENT naming the field, e.g.
// "TraceTaskResponse.curve.points[3].stability.monodromy: 3 x 3 matrix with 8 entries":
// unparsable bytes, a task or result that is not set, a message-typed field that is not set, an
// enum value outside the engine enum's range, a matrix whose entries are not rows * cols, a
// vector longer than its Eigen type holds (kMaxStateDim, kMaxParams), a status code outside
// StatusCode, a SwitchCandidate orbit that is neither an orbit with an OK status nor an error
// without one. A task's signatures are not checked against the model (the runner does that).
#ifndef DRILLBIF_JOBS_TRACE_TASK_CODEC_H_
#define DRILLBIF_JOBS_TRACE_TASK_CODEC_H_

#include <string>
#include <string_view>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/continuation/trace_tasks.h"
#include "drillbif/v1/trace_task.pb.h"

namespace drillbif::jobs {

// The child job's request: a drillbif.v1.TraceTaskRequest holding `parent_trace_request` (the
// parent job's serialized drillbif.v1.TraceRequest, kept as these bytes) and `task`.
std::string EncodeTraceTaskRequest(std::string_view parent_trace_request, const TraceTask& task);

// A decoded child job's request.
struct DecodedTraceTask {
  std::string trace_request;  // the parent's serialized drillbif.v1.TraceRequest
  TraceTask task;             // the task to run under it
};

// Decodes EncodeTraceTaskRequest's bytes. INVALID_ARGUMENT naming the field for malformed bytes,
// including a trace_request that does not parse as a drillbif.v1.TraceRequest.
StatusOr<DecodedTraceTask> DecodeTraceTaskRequest(std::string_view bytes);
// The same for a request already parsed (a child job's run gets it so from the registry).
StatusOr<DecodedTraceTask> DecodeTraceTaskRequest(const v1::TraceTaskRequest& request);

// The most tasks of one child job.
inline constexpr int kMaxTraceTaskBatch = 64;

// A child job's request: a drillbif.v1.TraceTaskBatch of `tasks` (1 .. kMaxTraceTaskBatch, run in
// order) under `parent_trace_request`.
std::string EncodeTraceTaskBatch(std::string_view parent_trace_request,
                                 const std::vector<const TraceTask*>& tasks);

// A decoded child job's request.
struct DecodedTraceTaskBatch {
  std::string trace_request;     // the parent's serialized drillbif.v1.TraceRequest
  std::vector<TraceTask> tasks;  // to run in order under it
};

// Decodes a child job's request. INVALID_ARGUMENT naming the field ("TraceTaskBatch.tasks[2]
// ...") for a malformed one, a trace_request that does not parse, or a count of tasks outside
// 1 .. kMaxTraceTaskBatch.
StatusOr<DecodedTraceTaskBatch> DecodeTraceTaskBatch(const v1::TraceTaskBatch& batch);

// A child job's result: its tasks' results in order, status "COMPLETED".
v1::TraceTaskBatchResponse TraceTaskBatchResponseOf(const std::vector<TraceTaskResult>& results);
// Decodes a child job's result bytes. INVALID_ARGUMENT naming the field for malformed bytes.
StatusOr<std::vector<TraceTaskResult>> DecodeTraceTaskBatchResponse(std::string_view bytes);

// A task's result as a drillbif.v1.TraceTaskResponse (the alternative at the same index).
std::string EncodeTraceTaskResult(const TraceTaskResult& result);
// The same as a message (status "COMPLETED"), e.g. a child job's result before the store
// serializes it.
v1::TraceTaskResponse TraceTaskResponseOf(const TraceTaskResult& result);

// Decodes EncodeTraceTaskResult's bytes. INVALID_ARGUMENT naming the field for malformed bytes.
StatusOr<TraceTaskResult> DecodeTraceTaskResult(std::string_view bytes);

// One orbit, exactly (an optimum map's cell keeps its optimum's orbit so).
void EncodeOrbit(const PeriodicOrbit& orbit, v1::TaskOrbit* out);
// INVALID_ARGUMENT naming the field (below "orbit.") for a malformed one. The signature is not
// checked against the model.
Status DecodeOrbit(const v1::TaskOrbit& in, PeriodicOrbit* out);

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_TRACE_TASK_CODEC_H_
