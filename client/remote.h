// drillctl's server mode: a thin client of the drillbif service (proto/drillbif/v1/service.proto).
// A job is submitted with a Jobs.Submit* rpc, followed through the Watch stream (progress), and
// its result fetched page by page with GetResult; Ctrl-C cancels it on the server with
// CancelOperation. The channel is plaintext, or TLS (RemoteOptions::tls) verified against the
// system's roots or a given CA certificate.
//
// Every rpc has a deadline (RemoteOptions::rpc_timeout_seconds for unary calls; a Watch stream is
// reopened every RemoteOptions::watch_seconds, so no call waits without a bound). Errors come
// back as Status with the gRPC code (the numbers are the same) and a message that names the
// server for transport failures (UNAVAILABLE, DEADLINE_EXCEEDED) and the token for
// UNAUTHENTICATED.
#ifndef DRILLBIF_CLIENT_REMOTE_H_
#define DRILLBIF_CLIENT_REMOTE_H_

#include <google/protobuf/message.h>
#include <grpcpp/grpcpp.h>

#include <cstdint>
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

// The CA certificate file to verify a TLS server with: `flag` (--tls-ca) when not empty, else
// DRILLBIF_TLS_CA, else empty (the system's roots).
std::string ResolveTlsCa(const std::string& flag);

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
  // TLS: the server's certificate is verified against `tls_ca_file`, or the system's roots
  // when it is empty. false: plaintext (the server must not use TLS then).
  bool tls = false;
  // A PEM file of the CA certificate(s) (or the self-signed certificate) that signed the
  // server's certificate; empty: the system's roots. Only with `tls`.
  std::string tls_ca_file;
  // Items per GetResult page (GetResultRequest.page_size, in [1, 100000]). 1000: a result of a
  // million items (a long sweep or trajectory) takes a thousand rpcs, while a page stays small
  // enough to hold (the server bounds pages in bytes as well).
  int result_page_size = 1000;
  // Largest message the client accepts, in bytes. The server bounds pages in bytes too, but a
  // single item (a sweep value with many samples, a long curve) is sent whole: 256 MiB holds
  // any item of a result within the server's default result limit (256 MB), far above gRPC's
  // default of 4 MiB, while a broken or hostile server cannot make the client allocate more.
  int max_receive_bytes = 256 << 20;
  // Validate(): the target is not empty, both times are > 0, the page size and receive limit in
  // range, a CA file only with `tls`.
  Status Validate() const;
};

// A connection to one drillbif server. Thread-compatible: use one per thread.
class RemoteClient {
 public:
  // Creates the channel (plaintext, or TLS with `options.tls`). Connects lazily, on the first
  // rpc. INVALID_ARGUMENT when the options are not valid or the CA file cannot be read.
  static StatusOr<std::unique_ptr<RemoteClient>> Connect(const RemoteOptions& options);

  const RemoteOptions& options() const { return options_; }

  // Jobs.Submit*: the operation of the new job (done at once for a cache hit).
  StatusOr<google::longrunning::Operation> Submit(const v1::SimulateRequest& request);
  StatusOr<google::longrunning::Operation> Submit(const v1::SweepRequest& request);
  StatusOr<google::longrunning::Operation> Submit(const v1::ContinueRequest& request);
  StatusOr<google::longrunning::Operation> Submit(const v1::TraceRequest& request);
  StatusOr<google::longrunning::Operation> Submit(const v1::OptimumRequest& request);
  StatusOr<google::longrunning::Operation> Submit(const v1::OptimumMapRequest& request);
  // QueryOptimum: a stored optimum, or one answered from a stored optimum map (no computation
  // unless the request asks for it). NOT_FOUND when neither exists.
  StatusOr<v1::QueryOptimumResponse> QueryOptimum(const v1::QueryOptimumRequest& request);

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
  // Jobs.GetResult page by page (RemoteOptions::result_page_size items a page), following
  // next_page_token to the last page: `on_page` gets each page's result message, in order (it
  // may take the page's items). Checks that every page is of the first page's kind, that each
  // token moves on, and that the pages' items add up to the first page's total_points
  // (INTERNAL otherwise). Errors: the rpc's (FAILED_PRECONDITION when the job has no result,
  // NOT_FOUND, ...) and on_page's; an error after the first page leaves what on_page did.
  Status GetResultPages(const std::string& name,
                        const std::function<Status(google::protobuf::Message& page)>& on_page);

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
  RemoteClient(const RemoteOptions& options,
               const std::shared_ptr<grpc::ChannelCredentials>& credentials);
  // A context with the token and a deadline `seconds` from now.
  std::unique_ptr<grpc::ClientContext> Context(double seconds) const;
  // A gRPC error as a Status with the same code and a message that says what to do about it
  // (a failed TLS verification: UNAUTHENTICATED, naming --tls-ca).
  Status FromGrpc(const grpc::Status& status) const;

  RemoteOptions options_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::Jobs::Stub> jobs_;
  std::unique_ptr<google::longrunning::Operations::Stub> operations_;
};

// The JobMetadata of an operation (a default one when it has none).
v1::JobMetadata MetadataOf(const google::longrunning::Operation& operation);

// The result message a GetResult response holds (the member of its `result` oneof that is set);
// null when none is.
google::protobuf::Message* MutableResultOf(v1::GetResultResponse& response);

// What RunRemote reports of a job.
struct RemoteRun {
  // The operation, "operations/{id}".
  std::string name;
  // True when the server answered from its cache (or an identical job) without running.
  bool cache_hit = false;
  // True when the job was cancelled (by this call, or before): it has no result, since the
  // server keeps no partial result. `message` names the operation and says so.
  bool cancelled = false;
  std::string message;
};

// Runs a job on the server as the local job runners run it in-process: submits `request`, calls
// `progress` with the fraction done from each Watch message (from the calling thread) and
// returns when the job SUCCEEDED (fetch its result with GetResultPages) or was cancelled.
// `progress` returning false, or `interrupted` (polled every 50 ms) returning true, cancels the
// job on the server; the run is then the server's if the job finished first, else `cancelled`.
// Errors: the submit's (INVALID_ARGUMENT naming the field, UNAUTHENTICATED, UNAVAILABLE, ...),
// and a FAILED job's error (its code and message, e.g. INVALID_ARGUMENT or FAILED_PRECONDITION
// from the job runner, as --local reports them).
template <typename Request>
StatusOr<RemoteRun> RunRemote(RemoteClient& client, const Request& request,
                              const ProgressCallback& progress,
                              const std::function<bool()>& interrupted);

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

template <typename Request>
StatusOr<RemoteRun> RunRemote(RemoteClient& client, const Request& request,
                              const ProgressCallback& progress,
                              const std::function<bool()>& interrupted) {
  StatusOr<google::longrunning::Operation> submitted = client.Submit(request);
  if (!submitted.ok()) return submitted.status();
  RemoteRun run;
  run.name = submitted->name();
  run.cache_hit = MetadataOf(*submitted).cache_hit();
  bool cancelled = false;
  StatusOr<google::longrunning::Operation> final_op =
      submitted->done() ? submitted
                        : internal::FollowJob(client, run.name, progress, interrupted, &cancelled);
  if (!final_op.ok()) return final_op.status();
  if (MetadataOf(*final_op).state() == v1::CANCELLED) {
    run.cancelled = true;
    run.message = std::string(cancelled ? "cancelled on the server (" : "cancelled (") + run.name +
                  "); the server keeps no partial result";
    return run;
  }
  if (Status s = internal::ErrorOf(*final_op); !s.ok()) return s;
  return run;
}

}  // namespace drillbif::client

#endif  // DRILLBIF_CLIENT_REMOTE_H_
