// The gRPC services of the server (internal to server/): drillbif.v1.Jobs and
// google.longrunning.Operations, callback API. Handlers check the bearer token, then hand their
// store work to the bounded executor (RESOURCE_EXHAUSTED when it is full) or register with the
// watch hub (Watch, WaitOperation, QueryOptimum computing); they never run the engine and never
// block a gRPC thread on disk. The one exception is QueryOptimum's cached answer, an in-memory
// map lookup answered inline.
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
  // Set by Server::Shutdown: submits fail with UNAVAILABLE.
  std::atomic<bool> shutting_down{false};
};

// grpc::Status of a drillbif::Status (same numeric codes).
grpc::Status ToGrpc(const Status& status);

// "operations/{id}".
std::string OperationName(const std::string& id);

// The metadata of a job record.
v1::JobMetadata MetadataOf(const JobRecord& record);

// drillbif.v1.Jobs.
class JobsService final : public v1::Jobs::CallbackService {
 public:
  explicit JobsService(ServiceState* state) : state_(state) {}

  grpc::ServerUnaryReactor* SubmitSimulate(grpc::CallbackServerContext* context,
                                           const v1::SubmitSimulateRequest* request,
                                           google::longrunning::Operation* response) override;
  grpc::ServerUnaryReactor* SubmitSweep(grpc::CallbackServerContext* context,
                                        const v1::SubmitSweepRequest* request,
                                        google::longrunning::Operation* response) override;
  grpc::ServerUnaryReactor* SubmitContinue(grpc::CallbackServerContext* context,
                                           const v1::SubmitContinueRequest* request,
                                           google::longrunning::Operation* response) override;
  grpc::ServerUnaryReactor* SubmitTrace(grpc::CallbackServerContext* context,
                                        const v1::SubmitTraceRequest* request,
                                        google::longrunning::Operation* response) override;
  grpc::ServerUnaryReactor* SubmitOptimum(grpc::CallbackServerContext* context,
                                          const v1::SubmitOptimumRequest* request,
                                          google::longrunning::Operation* response) override;
  grpc::ServerUnaryReactor* GetResult(grpc::CallbackServerContext* context,
                                      const v1::GetResultRequest* request,
                                      v1::GetResultResponse* response) override;
  grpc::ServerUnaryReactor* QueryOptimum(grpc::CallbackServerContext* context,
                                         const v1::QueryOptimumRequest* request,
                                         v1::QueryOptimumResponse* response) override;
  grpc::ServerWriteReactor<v1::JobMetadata>* Watch(grpc::CallbackServerContext* context,
                                                   const v1::WatchRequest* request) override;

 private:
  ServiceState* const state_;
};

// google.longrunning.Operations over the same jobs.
class OperationsService final : public google::longrunning::Operations::CallbackService {
 public:
  explicit OperationsService(ServiceState* state) : state_(state) {}

  grpc::ServerUnaryReactor* ListOperations(
      grpc::CallbackServerContext* context,
      const google::longrunning::ListOperationsRequest* request,
      google::longrunning::ListOperationsResponse* response) override;
  grpc::ServerUnaryReactor* GetOperation(grpc::CallbackServerContext* context,
                                         const google::longrunning::GetOperationRequest* request,
                                         google::longrunning::Operation* response) override;
  grpc::ServerUnaryReactor* DeleteOperation(
      grpc::CallbackServerContext* context,
      const google::longrunning::DeleteOperationRequest* request,
      google::protobuf::Empty* response) override;
  grpc::ServerUnaryReactor* CancelOperation(
      grpc::CallbackServerContext* context,
      const google::longrunning::CancelOperationRequest* request,
      google::protobuf::Empty* response) override;
  grpc::ServerUnaryReactor* WaitOperation(grpc::CallbackServerContext* context,
                                          const google::longrunning::WaitOperationRequest* request,
                                          google::longrunning::Operation* response) override;

 private:
  ServiceState* const state_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_SERVICES_H_
