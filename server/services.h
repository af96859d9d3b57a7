// The gRPC services of the server (internal to server/): drillbif.v1.Jobs and
// google.longrunning.Operations, callback API with raw requests (server/grpc_calls.h: bytes that
// do not parse are INVALID_ARGUMENT naming the field). Handlers check the bearer token, then hand
// their store work to the bounded executor (RESOURCE_EXHAUSTED when it is full) or register with
// the watch hub (Watch, WaitOperation, QueryOptimum computing); they never run the engine and
// never block a gRPC thread on disk. The one exception is QueryOptimum's cached answer, an
// in-memory map lookup answered inline.
#ifndef DRILLBIF_SERVER_SERVICES_H_
#define DRILLBIF_SERVER_SERVICES_H_

#include <grpcpp/grpcpp.h>

#include <atomic>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <unordered_map>

#include "drillbif/common/status.h"
#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "server/executor.h"
#include "server/grpc_calls.h"
#include "server/map_index.h"
#include "server/metrics.h"
#include "server/server.h"
#include "server/store/job_store.h"
#include "server/tokens.h"
#include "server/watch_hub.h"
#include "server/worker_pool.h"

namespace drillbif::server {

// Stored optimum results by cache key, so that QueryOptimum answers from memory. Filled from the
// store at startup and by the worker pool as optimum jobs succeed. Thread-safe.
class OptimumIndex {
 public:
  // Records that job `id` holds the result for `key` (the first job recorded for a key stays).
  void Add(const std::string& key, const std::string& id);
  // Forgets every key held by job `id` (it was deleted).
  void RemoveJob(const std::string& id);
  // The job holding `key` and its parsed result if already read (nullptr if not); false when
  // the key is unknown.
  bool Find(const std::string& key, std::string* id,
            std::shared_ptr<const v1::OptimumResult>* result);
  // Keeps the parsed result of `key` for the next queries.
  void SetResult(const std::string& key, std::shared_ptr<const v1::OptimumResult> result);
  // Forgets everything, then loads every SUCCEEDED optimum job of the store.
  Status Load(JobStore& store);

 private:
  struct Entry {
    std::string id;
    std::shared_ptr<const v1::OptimumResult> result;
  };
  std::mutex mutex_;
  std::unordered_map<std::string, Entry> entries_;
};

// What the services share. Owned by the server; outlives the services.
struct ServiceState {
  ServerOptions options;
  // The bearer tokens and their clients (never null; empty: no authentication).
  std::shared_ptr<const TokenSet> tokens = std::make_shared<TokenSet>();
  JobStore* store = nullptr;
  WatchHub* hub = nullptr;
  WorkerPool* pool = nullptr;
  BoundedExecutor* executor = nullptr;
  // Counts refusals at submit (null in tests that need no metrics).
  Metrics* metrics = nullptr;
  OptimumIndex optimum_index;
  // Stored optimum maps, for queries between their cells.
  MapIndex map_index;
  // Set by Server::Shutdown: submits fail with UNAVAILABLE.
  std::atomic<bool> shutting_down{false};
};

// grpc::Status of a drillbif::Status (same numeric codes).
grpc::Status ToGrpc(const Status& status);

// "operations/{id}".
std::string OperationName(const std::string& id);

// The metadata of a job record.
v1::JobMetadata MetadataOf(const JobRecord& record);

// The calls of the two services, served from raw bytes (server/grpc_calls.h).
using SubmitSimulateCall = UnaryCall<v1::SubmitSimulateRequest, google::longrunning::Operation>;
using SubmitSweepCall = UnaryCall<v1::SubmitSweepRequest, google::longrunning::Operation>;
using SubmitContinueCall = UnaryCall<v1::SubmitContinueRequest, google::longrunning::Operation>;
using SubmitTraceCall = UnaryCall<v1::SubmitTraceRequest, google::longrunning::Operation>;
using SubmitOptimumCall = UnaryCall<v1::SubmitOptimumRequest, google::longrunning::Operation>;
using SubmitOptimumMapCall = UnaryCall<v1::SubmitOptimumMapRequest, google::longrunning::Operation>;
using GetResultCall = UnaryCall<v1::GetResultRequest, v1::GetResultResponse>;
using QueryOptimumCall = UnaryCall<v1::QueryOptimumRequest, v1::QueryOptimumResponse>;
using ListOperationsCall = UnaryCall<google::longrunning::ListOperationsRequest,
                                     google::longrunning::ListOperationsResponse>;
using GetOperationCall =
    UnaryCall<google::longrunning::GetOperationRequest, google::longrunning::Operation>;
using DeleteOperationCall =
    UnaryCall<google::longrunning::DeleteOperationRequest, google::protobuf::Empty>;
using CancelOperationCall =
    UnaryCall<google::longrunning::CancelOperationRequest, google::protobuf::Empty>;
using WaitOperationCall =
    UnaryCall<google::longrunning::WaitOperationRequest, google::longrunning::Operation>;

// drillbif.v1.Jobs. Every method is a raw callback method (server/grpc_calls.h), registered by
// the constructor: the generated typed handlers are never called.
class JobsService final : public v1::Jobs::CallbackService {
 public:
  explicit JobsService(ServiceState* state);

 private:
  // A unary method of the service by name, parsed into `Call`'s request and handled by
  // `handle`.
  template <typename Call>
  void RegisterUnary(const char* method, void (JobsService::*handle)(Call*));

  // Submit<Kind>: a job of kind kKind from the call's request and request_id.
  template <v1::JobKind kKind, typename Call>
  void SubmitJob(Call* call);
  void GetResult(GetResultCall* call);
  void QueryOptimum(QueryOptimumCall* call);
  grpc::ServerWriteReactor<grpc::ByteBuffer>* Watch(grpc::CallbackServerContext* context,
                                                    const grpc::ByteBuffer* request);

  ServiceState* const state_;
};

// google.longrunning.Operations over the same jobs; raw callback methods as JobsService's.
class OperationsService final : public google::longrunning::Operations::CallbackService {
 public:
  explicit OperationsService(ServiceState* state);

 private:
  template <typename Call>
  void RegisterUnary(const char* method, void (OperationsService::*handle)(Call*));

  void ListOperations(ListOperationsCall* call);
  void GetOperation(GetOperationCall* call);
  void DeleteOperation(DeleteOperationCall* call);
  void CancelOperation(CancelOperationCall* call);
  void WaitOperation(WaitOperationCall* call);

  ServiceState* const state_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_SERVICES_H_
