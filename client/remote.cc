#include "client/remote.h"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/wire_format_lite.h>
#include <grpcpp/generic/generic_stub.h>

#include <chrono>
#include <cstdlib>
#include <future>
#include <stop_token>
#include <thread>
#include <utility>

namespace drillbif::client {
namespace {

using google::longrunning::Operation;

constexpr char kOperationsPrefix[] = "operations/";

// How often the helper thread of Watch polls `interrupted`: Ctrl-C is acted on within this.
constexpr auto kInterruptPoll = std::chrono::milliseconds(50);

// How long FollowJob waits for a job to reach its final state after the Watch stream said so or
// after a cancel (a running job stops within ~100 ms of a cancel; 60 s covers a loaded server).
constexpr double kFinalWaitSeconds = 60.0;

bool IsFinal(v1::JobState state) {
  return state == v1::SUCCEEDED || state == v1::FAILED || state == v1::CANCELLED;
}

// The gRPC codes drillbif::StatusCode has (the same numbers); others become INTERNAL.
bool IsKnownCode(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::CANCELLED:
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::DEADLINE_EXCEEDED:
    case grpc::StatusCode::NOT_FOUND:
    case grpc::StatusCode::ALREADY_EXISTS:
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
    case grpc::StatusCode::FAILED_PRECONDITION:
    case grpc::StatusCode::ABORTED:
    case grpc::StatusCode::OUT_OF_RANGE:
    case grpc::StatusCode::UNIMPLEMENTED:
    case grpc::StatusCode::INTERNAL:
    case grpc::StatusCode::UNAVAILABLE:
    case grpc::StatusCode::UNAUTHENTICATED:
      return true;
    default:
      return false;
  }
}

std::string FromEnvironment(const char* name) {
  const char* value = std::getenv(name);
  return value != nullptr ? std::string(value) : std::string();
}

std::chrono::system_clock::time_point After(double seconds) {
  return std::chrono::system_clock::now() +
         std::chrono::duration_cast<std::chrono::system_clock::duration>(
             std::chrono::duration<double>(seconds));
}

template <typename Result>
Status Unpack(bool has, const Result& field, Result* out) {
  if (!has) {
    return Internal("the server returned a result of another kind than " +
                    out->GetDescriptor()->name());
  }
  *out = field;
  return Status::Ok();
}

}  // namespace

std::string ResolveServer(const std::string& flag) {
  if (!flag.empty()) return flag;
  std::string env = FromEnvironment("DRILLBIF_SERVER");
  return env.empty() ? std::string(kDefaultServer) : env;
}

std::string ResolveToken(const std::string& flag) {
  return flag.empty() ? FromEnvironment("DRILLBIF_TOKEN") : flag;
}

std::string OperationName(const std::string& id_or_name) {
  if (id_or_name.rfind(kOperationsPrefix, 0) == 0) return id_or_name;
  return kOperationsPrefix + id_or_name;
}

Status RemoteOptions::Validate() const {
  if (target.empty()) return InvalidArgument("server: empty address (expected HOST:PORT)");
  if (!(rpc_timeout_seconds > 0.0)) {
    return InvalidArgument("rpc timeout must be > 0 seconds, got " +
                           std::to_string(rpc_timeout_seconds));
  }
  if (!(watch_seconds > 0.0)) {
    return InvalidArgument("watch deadline must be > 0 seconds, got " +
                           std::to_string(watch_seconds));
  }
  return Status::Ok();
}

RemoteClient::RemoteClient(const RemoteOptions& options) : options_(options) {
  grpc::ChannelArguments args;
  // Results can be large (a long sweep, a trace with a region grid); the server sends them
  // whole, so the client accepts any size rather than gRPC's default 4 MB.
  args.SetMaxReceiveMessageSize(-1);
  channel_ = grpc::CreateCustomChannel(options_.target, grpc::InsecureChannelCredentials(), args);
  jobs_ = v1::Jobs::NewStub(channel_);
  operations_ = google::longrunning::Operations::NewStub(channel_);
}

StatusOr<std::unique_ptr<RemoteClient>> RemoteClient::Connect(const RemoteOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return s;
  return std::unique_ptr<RemoteClient>(new RemoteClient(options));
}

std::unique_ptr<grpc::ClientContext> RemoteClient::Context(double seconds) const {
  auto context = std::make_unique<grpc::ClientContext>();
  context->set_deadline(After(seconds));
  if (!options_.token.empty()) context->AddMetadata("authorization", "Bearer " + options_.token);
  return context;
}

Status RemoteClient::FromGrpc(const grpc::Status& status) const {
  if (status.ok()) return Status::Ok();
  const std::string& target = options_.target;
  switch (status.error_code()) {
    case grpc::StatusCode::UNAVAILABLE:
      return Status(StatusCode::kUnavailable,
                    "the drillbif server at " + target + " is not available (" +
                        status.error_message() +
                        "); start drillbif-server there, or name another with --server "
                        "HOST:PORT or DRILLBIF_SERVER");
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return Status(StatusCode::kDeadlineExceeded, "the drillbif server at " + target +
                                                       " did not answer in time (" +
                                                       status.error_message() + ")");
    case grpc::StatusCode::UNAUTHENTICATED:
      return Status(StatusCode::kUnauthenticated,
                    "the drillbif server at " + target +
                        " refused the call: " + status.error_message() +
                        (options_.token.empty()
                             ? std::string("; it needs a token: pass --token or set DRILLBIF_TOKEN")
                             : std::string("; the token given (--token or DRILLBIF_TOKEN) is not "
                                           "the server's")));
    default:
      break;
  }
  if (IsKnownCode(status.error_code())) {
    return Status(static_cast<StatusCode>(static_cast<int>(status.error_code())),
                  status.error_message());
  }
  return Internal("gRPC code " + std::to_string(static_cast<int>(status.error_code())) + ": " +
                  status.error_message());
}

StatusOr<Operation> RemoteClient::Submit(const v1::SimulateRequest& request) {
  v1::SubmitSimulateRequest submit;
  *submit.mutable_request() = request;
  Operation op;
  auto context = Context(options_.rpc_timeout_seconds);
  if (grpc::Status s = jobs_->SubmitSimulate(context.get(), submit, &op); !s.ok()) {
    return FromGrpc(s);
  }
  return op;
}

StatusOr<Operation> RemoteClient::Submit(const v1::SweepRequest& request) {
  v1::SubmitSweepRequest submit;
  *submit.mutable_request() = request;
  Operation op;
  auto context = Context(options_.rpc_timeout_seconds);
  if (grpc::Status s = jobs_->SubmitSweep(context.get(), submit, &op); !s.ok()) {
    return FromGrpc(s);
  }
  return op;
}

StatusOr<Operation> RemoteClient::Submit(const v1::ContinueRequest& request) {
  v1::SubmitContinueRequest submit;
  *submit.mutable_request() = request;
  Operation op;
  auto context = Context(options_.rpc_timeout_seconds);
  if (grpc::Status s = jobs_->SubmitContinue(context.get(), submit, &op); !s.ok()) {
    return FromGrpc(s);
  }
  return op;
}

StatusOr<Operation> RemoteClient::Submit(const v1::TraceRequest& request) {
  v1::SubmitTraceRequest submit;
  *submit.mutable_request() = request;
  Operation op;
  auto context = Context(options_.rpc_timeout_seconds);
  if (grpc::Status s = jobs_->SubmitTrace(context.get(), submit, &op); !s.ok()) {
    return FromGrpc(s);
  }
  return op;
}

StatusOr<Operation> RemoteClient::Submit(const v1::OptimumRequest& request) {
  v1::SubmitOptimumRequest submit;
  *submit.mutable_request() = request;
  Operation op;
  auto context = Context(options_.rpc_timeout_seconds);
  if (grpc::Status s = jobs_->SubmitOptimum(context.get(), submit, &op); !s.ok()) {
    return FromGrpc(s);
  }
  return op;
}

StatusOr<Operation> RemoteClient::Get(const std::string& name) {
  google::longrunning::GetOperationRequest request;
  request.set_name(name);
  Operation op;
  auto context = Context(options_.rpc_timeout_seconds);
  if (grpc::Status s = operations_->GetOperation(context.get(), request, &op); !s.ok()) {
    return FromGrpc(s);
  }
  return op;
}

StatusOr<google::longrunning::ListOperationsResponse> RemoteClient::List(
    const std::string& filter, int page_size, const std::string& page_token) {
  google::longrunning::ListOperationsRequest request;
  request.set_filter(filter);
  request.set_page_size(page_size);
  request.set_page_token(page_token);
  google::longrunning::ListOperationsResponse response;
  auto context = Context(options_.rpc_timeout_seconds);
  if (grpc::Status s = operations_->ListOperations(context.get(), request, &response); !s.ok()) {
    return FromGrpc(s);
  }
  return response;
}

Status RemoteClient::Cancel(const std::string& name) {
  google::longrunning::CancelOperationRequest request;
  request.set_name(name);
  google::protobuf::Empty empty;
  auto context = Context(options_.rpc_timeout_seconds);
  return FromGrpc(operations_->CancelOperation(context.get(), request, &empty));
}

StatusOr<Operation> RemoteClient::Wait(const std::string& name, double seconds) {
  google::longrunning::WaitOperationRequest request;
  request.set_name(name);
  const auto timeout = std::chrono::duration<double>(seconds);
  const auto whole = std::chrono::duration_cast<std::chrono::seconds>(timeout);
  request.mutable_timeout()->set_seconds(whole.count());
  request.mutable_timeout()->set_nanos(static_cast<int>(
      std::chrono::duration_cast<std::chrono::nanoseconds>(timeout - whole).count()));
  Operation op;
  // The rpc's deadline leaves the server its whole `timeout` plus the usual margin.
  auto context = Context(seconds + options_.rpc_timeout_seconds);
  if (grpc::Status s = operations_->WaitOperation(context.get(), request, &op); !s.ok()) {
    return FromGrpc(s);
  }
  return op;
}

StatusOr<v1::GetResultResponse> RemoteClient::GetResult(const std::string& name) {
  v1::GetResultRequest request;
  request.set_name(name);
  v1::GetResultResponse response;
  auto context = Context(options_.rpc_timeout_seconds);
  if (grpc::Status s = jobs_->GetResult(context.get(), request, &response); !s.ok()) {
    return FromGrpc(s);
  }
  return response;
}

StatusOr<std::string> RemoteClient::Health() {
  // grpc.health.v1 is not compiled here (gRPC's server has it built in): the call goes through
  // the generic stub. HealthCheckRequest{service: ""} is the empty message; the response is
  // HealthCheckResponse{status = 1 (enum ServingStatus)}: 0 UNKNOWN, 1 SERVING, 2 NOT_SERVING,
  // 3 SERVICE_UNKNOWN.
  grpc::GenericStub stub(channel_);
  auto context = Context(options_.rpc_timeout_seconds);
  grpc::Slice empty(std::string{});  // a ByteBuffer needs a slice, even an empty one
  grpc::ByteBuffer request(&empty, 1);
  grpc::ByteBuffer response;
  std::promise<grpc::Status> done;
  stub.UnaryCall(context.get(), "/grpc.health.v1.Health/Check", grpc::StubOptions(), &request,
                 &response, [&done](grpc::Status s) { done.set_value(std::move(s)); });
  const grpc::Status status = done.get_future().get();
  if (!status.ok()) return FromGrpc(status);
  std::vector<grpc::Slice> slices;
  std::string bytes;
  if (!response.Dump(&slices).ok()) return Internal("unreadable health response");
  for (const grpc::Slice& slice : slices) bytes.append(slice.begin(), slice.end());
  google::protobuf::io::CodedInputStream in(reinterpret_cast<const uint8_t*>(bytes.data()),
                                            static_cast<int>(bytes.size()));
  uint32_t serving = 0;
  for (uint32_t tag = in.ReadTag(); tag != 0; tag = in.ReadTag()) {
    if (tag == 8) {  // field 1, varint
      if (!in.ReadVarint32(&serving)) return Internal("malformed health response");
    } else if (!google::protobuf::internal::WireFormatLite::SkipField(&in, tag)) {
      return Internal("malformed health response");
    }
  }
  switch (serving) {
    case 1:
      return std::string("SERVING");
    case 2:
      return std::string("NOT_SERVING");
    case 3:
      return std::string("SERVICE_UNKNOWN");
    default:
      return std::string("UNKNOWN");
  }
}

StatusOr<v1::JobMetadata> RemoteClient::Watch(
    const std::string& name, const std::function<bool(const v1::JobMetadata&)>& on_update,
    const std::function<bool()>& interrupted) {
  v1::JobMetadata last;
  for (;;) {
    auto context = Context(options_.watch_seconds);
    std::atomic<bool> interrupt_seen = false;
    // Declared after the context, so destroyed (stopped and joined) before it.
    std::jthread poller;
    if (interrupted) {
      poller = std::jthread([&](std::stop_token stop) {
        while (!stop.stop_requested()) {
          if (interrupted()) {
            interrupt_seen = true;
            context->TryCancel();
            return;
          }
          std::this_thread::sleep_for(kInterruptPoll);
        }
      });
    }
    v1::WatchRequest request;
    request.set_name(name);
    std::unique_ptr<grpc::ClientReader<v1::JobMetadata>> reader =
        jobs_->Watch(context.get(), request);
    v1::JobMetadata metadata;
    bool stopped = false;
    bool final_seen = false;
    while (reader->Read(&metadata)) {
      last = metadata;
      final_seen = final_seen || IsFinal(metadata.state());
      if (!on_update(metadata)) {
        stopped = true;
        context->TryCancel();
        while (reader->Read(&metadata)) {
        }
        break;
      }
    }
    const grpc::Status status = reader->Finish();
    if (poller.joinable()) {
      poller.request_stop();
      poller.join();
    }
    if (interrupt_seen) return Status(StatusCode::kCancelled, "interrupted");
    if (stopped || final_seen) return last;
    if (status.ok()) return last;
    // The stream reached its deadline while the job runs: reopen it.
    if (status.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED) continue;
    return FromGrpc(status);
  }
}

v1::JobMetadata MetadataOf(const Operation& operation) {
  v1::JobMetadata metadata;
  if (!operation.metadata().UnpackTo(&metadata)) metadata.Clear();
  return metadata;
}

Status ResultOf(const v1::GetResultResponse& response, v1::SimulateResult* result) {
  return Unpack(response.has_simulate(), response.simulate(), result);
}
Status ResultOf(const v1::GetResultResponse& response, v1::SweepResult* result) {
  return Unpack(response.has_sweep(), response.sweep(), result);
}
Status ResultOf(const v1::GetResultResponse& response, v1::ContinueResult* result) {
  return Unpack(response.has_continue_(), response.continue_(), result);
}
Status ResultOf(const v1::GetResultResponse& response, v1::TraceResult* result) {
  return Unpack(response.has_trace(), response.trace(), result);
}
Status ResultOf(const v1::GetResultResponse& response, v1::OptimumResult* result) {
  return Unpack(response.has_optimum(), response.optimum(), result);
}

namespace internal {

Status ErrorOf(const Operation& operation) {
  if (!operation.has_error() || operation.error().code() == 0) return Status::Ok();
  const auto code = static_cast<grpc::StatusCode>(operation.error().code());
  if (IsKnownCode(code)) {
    return Status(static_cast<StatusCode>(operation.error().code()), operation.error().message());
  }
  return Internal("job failed with code " + std::to_string(operation.error().code()) + ": " +
                  operation.error().message());
}

StatusOr<Operation> FollowJob(RemoteClient& client, const std::string& name,
                              const ProgressCallback& progress,
                              const std::function<bool()>& interrupted, bool* cancelled) {
  bool stop = false;
  StatusOr<v1::JobMetadata> last = client.Watch(
      name,
      [&](const v1::JobMetadata& metadata) {
        if (progress && !progress(metadata.progress())) {
          stop = true;
          return false;
        }
        return true;
      },
      interrupted);
  const bool cancel = stop || (interrupted && interrupted());
  if (!last.ok() && !cancel) {
    // The job itself is not affected (e.g. a server restarting requeues it): say how to resume.
    return Status(last.status().code(), "while following " + name + ": " + last.status().message() +
                                            " (then: drillctl jobs watch " + name +
                                            ", drillctl jobs result " + name + ")");
  }
  if (cancel) {
    Status s = client.Cancel(name);
    // FAILED_PRECONDITION: it finished before the cancel arrived; its result stands.
    if (!s.ok() && s.code() != StatusCode::kFailedPrecondition) return s;
    *cancelled = s.ok();
  }
  // The final operation (after a final Watch message, or a cancel of a running job, this
  // returns at once or within ~100 ms).
  StatusOr<Operation> op = client.Wait(name, kFinalWaitSeconds);
  if (!op.ok()) return op.status();
  if (!op->done()) {
    return Status(StatusCode::kDeadlineExceeded,
                  name + " did not finish within " + std::to_string(kFinalWaitSeconds) + " s of " +
                      (cancel ? "its cancel" : "its last progress message"));
  }
  return op;
}

}  // namespace internal
}  // namespace drillbif::client
