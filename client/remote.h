// drillctl's server mode: a thin client of the drillbif service (proto/drillbif/v1/service.proto).
// A job is submitted with a Jobs.Submit* rpc, followed through the Watch stream (progress), and
// its result fetched with GetResult; Ctrl-C cancels it on the server with CancelOperation.
//
// Every rpc has a deadline (RemoteOptions::rpc_timeout_seconds for unary calls; a Watch stream is
// reopened every RemoteOptions::watch_seconds, so no call waits without a bound). Errors come
// back as Status with the gRPC code (the numbers are the same) and a message that names the
// server for transport failures (UNAVAILABLE, DEADLINE_EXCEEDED) and the token for
// UNAUTHENTICATED.
#ifndef DRILLBIF_CLIENT_REMOTE_H_
#define DRILLBIF_CLIENT_REMOTE_H_

#include <grpcpp/grpcpp.h>

#include <functional>
#include <memory>
#include <string>

#include "drillbif/common/status.h"
#include "drillbif/simulate/simulator.h"
#include "drillbif/v1/continue.pb.h"
#include "drillbif/v1/optimum.pb.h"
#include "drillbif/v1/service.grpc.pb.h"
#include "drillbif/v1/simulate.pb.h"
#include "drillbif/v1/sweep.pb.h"
#include "drillbif/v1/trace.pb.h"
#include "google/longrunning/operations.grpc.pb.h"

namespace drillbif::client {

// The default server address when neither --server nor DRILLBIF_SERVER is given.
inline constexpr char kDefaultServer[] = "localhost:50051";

// The server to talk to: `flag` (--server) when not empty, else the environment variable
// DRILLBIF_SERVER when set and not empty, else kDefaultServer.
std::string ResolveServer(const std::string& flag);

// The bearer token: `flag` (--token) when not empty, else DRILLBIF_TOKEN, else empty (none).
std::string ResolveToken(const std::string& flag);

// "operations/{id}" for an id given with or without the "operations/" prefix.
std::string OperationName(const std::string& id_or_name);

// How to reach the server.
struct RemoteOptions {
  // "host:port" (any gRPC target, e.g. "localhost:50051", "dns:///drillbif:50051").
  std::string target = kDefaultServer;
  // Bearer token sent as "authorization: Bearer <token>" on every rpc; empty: none.
  std::string token;
  // Deadline of every unary rpc, in seconds. 30 s: submits and reads are store work (an fsync
  // or a read), far quicker; a bound this loose only catches a hung server or network.
  double rpc_timeout_seconds = 30.0;
  // Deadline of one Watch stream, in seconds; a stream that reaches it while the job runs is
  // reopened. 60 s: one reconnect a minute is negligible, and a dead connection is noticed.
  double watch_seconds = 60.0;
  // Validate(): the target is not empty and both times are > 0.
  Status Validate() const;
};

// A connection to one drillbif server. Thread-compatible: use one per thread.
class RemoteClient {
 public:
  // Creates the channel (insecure: the service has no TLS yet). Connects lazily, on the first
  // rpc. INVALID_ARGUMENT when the options are not valid.
  static StatusOr<std::unique_ptr<RemoteClient>> Connect(const RemoteOptions& options);

  const RemoteOptions& options() const { return options_; }

  // Jobs.Submit*: the operation of the new job (done at once for a cache hit).
  StatusOr<google::longrunning::Operation> Submit(const v1::SimulateRequest& request);
  StatusOr<google::longrunning::Operation> Submit(const v1::SweepRequest& request);
  StatusOr<google::longrunning::Operation> Submit(const v1::ContinueRequest& request);
  StatusOr<google::longrunning::Operation> Submit(const v1::TraceRequest& request);
  StatusOr<google::longrunning::Operation> Submit(const v1::OptimumRequest& request);

  // Operations.GetOperation (with the result when done).
  StatusOr<google::longrunning::Operation> Get(const std::string& name);
  // Operations.ListOperations: one page, oldest first; `filter` as in service.proto.
  StatusOr<google::longrunning::ListOperationsResponse> List(const std::string& filter,
                                                             int page_size,
                                                             const std::string& page_token);
  // Operations.CancelOperation.
  Status Cancel(const std::string& name);
  // Operations.WaitOperation for at most `seconds`: the operation, done or not.
  StatusOr<google::longrunning::Operation> Wait(const std::string& name, double seconds);
  // Jobs.GetResult of the whole result (page_size 0).
  StatusOr<v1::GetResultResponse> GetResult(const std::string& name);

  // grpc.health.v1.Health/Check of the whole server (service ""; no token needed): the
  // serving status, "SERVING", "NOT_SERVING" (e.g. shutting down), "SERVICE_UNKNOWN" or
  // "UNKNOWN". Errors as every rpc (UNAVAILABLE when nothing answers).
  StatusOr<std::string> Health();

  // Jobs.Watch until the job reaches a final state: `on_update` gets each JobMetadata (on the
  // calling thread) and returns false to stop watching. `interrupted` (optional) is polled every
  // 50 ms from a helper thread; once it returns true the stream is cancelled and Watch returns
  // CANCELLED at once. Returns the last metadata received (a final state unless stopped).
  // Streams reaching their deadline (RemoteOptions::watch_seconds) are reopened.
  StatusOr<v1::JobMetadata> Watch(const std::string& name,
                                  const std::function<bool(const v1::JobMetadata&)>& on_update,
                                  const std::function<bool()>& interrupted = {});

 private:
  explicit RemoteClient(const RemoteOptions& options);
  // A context with the token and a deadline `seconds` from now.
  std::unique_ptr<grpc::ClientContext> Context(double seconds) const;
  // A gRPC error as a Status with the same code and a message that says what to do about it.
  Status FromGrpc(const grpc::Status& status) const;

  RemoteOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::Jobs::Stub> jobs_;
  std::unique_ptr<google::longrunning::Operations::Stub> operations_;
};

// The JobMetadata of an operation (a default one when it has none).
v1::JobMetadata MetadataOf(const google::longrunning::Operation& operation);

// The result of one kind from a GetResult response; INTERNAL when it holds another kind.
Status ResultOf(const v1::GetResultResponse& response, v1::SimulateResult* result);
Status ResultOf(const v1::GetResultResponse& response, v1::SweepResult* result);
Status ResultOf(const v1::GetResultResponse& response, v1::ContinueResult* result);
Status ResultOf(const v1::GetResultResponse& response, v1::TraceResult* result);
Status ResultOf(const v1::GetResultResponse& response, v1::OptimumResult* result);

// What RunRemote reports of a job besides its result.
struct RemoteRun {
  // The operation, "operations/{id}".
  std::string name;
  // True when the server answered from its cache (or an identical job) without running.
  bool cache_hit = false;
};

// Runs a job on the server as the local job runners run it in-process: submits `request`, calls
// `progress` with the fraction done from each Watch message (from the calling thread) and, when
// the job succeeded, returns its result. `progress` returning false, or `interrupted` (polled
// every 50 ms) returning true, cancels the job on the server; the result is then the server's
// if it finished first, else an empty result of the kind with status "CANCELLED" and a message
// naming the operation (the server keeps no partial result of a cancelled job).
// Errors: the submit's (INVALID_ARGUMENT naming the field, UNAUTHENTICATED, UNAVAILABLE, ...),
// and a FAILED job's error (its code and message, e.g. INVALID_ARGUMENT or FAILED_PRECONDITION
// from the job runner, as --local reports them).
template <typename Result, typename Request>
StatusOr<Result> RunRemote(RemoteClient& client, const Request& request,
                           const ProgressCallback& progress,
                           const std::function<bool()>& interrupted, RemoteRun* run = nullptr);

// ---------------------------------------------------------------------------------------------
// Implementation details of RunRemote.
namespace internal {

// Follows a submitted job to its end (see RunRemote): the final operation, or an error. Sets
// `*cancelled` when this call cancelled the job.
StatusOr<google::longrunning::Operation> FollowJob(RemoteClient& client, const std::string& name,
                                                   const ProgressCallback& progress,
                                                   const std::function<bool()>& interrupted,
                                                   bool* cancelled);

// The error of a finished operation that did not succeed (its google.rpc.Status), or OK.
Status ErrorOf(const google::longrunning::Operation& operation);

}  // namespace internal

template <typename Result, typename Request>
StatusOr<Result> RunRemote(RemoteClient& client, const Request& request,
                           const ProgressCallback& progress,
                           const std::function<bool()>& interrupted, RemoteRun* run) {
  StatusOr<google::longrunning::Operation> submitted = client.Submit(request);
  if (!submitted.ok()) return submitted.status();
  const std::string name = submitted->name();
  if (run != nullptr) {
    run->name = name;
    run->cache_hit = MetadataOf(*submitted).cache_hit();
  }
  bool cancelled = false;
  StatusOr<google::longrunning::Operation> final_op =
      submitted->done() ? submitted
                        : internal::FollowJob(client, name, progress, interrupted, &cancelled);
  if (!final_op.ok()) return final_op.status();
  const v1::JobMetadata metadata = MetadataOf(*final_op);
  if (metadata.state() == v1::CANCELLED) {
    Result result;
    result.set_status(std::string("CANCELLED"));
    result.set_message(std::string(cancelled ? "cancelled on the server (" : "cancelled (") + name +
                       "); the server keeps no partial result");
    return result;
  }
  if (Status s = internal::ErrorOf(*final_op); !s.ok()) return s;
  StatusOr<v1::GetResultResponse> response = client.GetResult(name);
  if (!response.ok()) return response.status();
  Result result;
  if (Status s = ResultOf(*response, &result); !s.ok()) return s;
  return result;
}

}  // namespace drillbif::client

#endif  // DRILLBIF_CLIENT_REMOTE_H_
