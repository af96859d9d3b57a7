#include "client/remote.h"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/wire_format_lite.h>
#include <grpcpp/generic/generic_stub.h>

#include <cctype>
#include <cerrno>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <future>
#include <sstream>
#include <stop_token>
#include <thread>
#include <utility>

#include "jobs/registry.h"
#include "jobs/result_pages.h"

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

// Whether `message` (of a gRPC error) says the TLS handshake failed, and why, in the words of
// gRPC 1.51 with OpenSSL 3: "Ssl handshake failed: SSL_ERROR_SSL: error:0A000086:SSL
// routines::certificate verify failed" (BoringSSL: CERTIFICATE_VERIFY_FAILED), "... wrong version
// number" (the server speaks plaintext).
enum class TlsFailure { kNone, kVerify, kNotTls, kOther };

TlsFailure TlsFailureOf(const std::string& message) {
  std::string lower = message;
  for (char& c : lower) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  auto has = [&lower](const char* text) { return lower.find(text) != std::string::npos; };
  if (has("certificate verify failed") || has("certificate_verify_failed")) {
    return TlsFailure::kVerify;
  }
  if (has("wrong version number") || has("wrong_version_number")) return TlsFailure::kNotTls;
  if (has("handshake")) return TlsFailure::kOther;
  return TlsFailure::kNone;
}

StatusOr<std::string> ReadPemFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return InvalidArgument("--tls-ca: cannot read " + path + ": " + std::strerror(errno));
  std::stringstream text;
  text << in.rdbuf();
  if (!in.good() && !in.eof()) {
    return InvalidArgument("--tls-ca: cannot read " + path + ": " + std::strerror(errno));
  }
  if (text.str().find("-----BEGIN CERTIFICATE-----") == std::string::npos) {
    return InvalidArgument("--tls-ca: " + path + " holds no PEM certificate");
  }
  return text.str();
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

std::string ResolveTlsCa(const std::string& flag) {
  return flag.empty() ? FromEnvironment("DRILLBIF_TLS_CA") : flag;
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
  if (result_page_size < 1 || result_page_size > jobs::kMaxResultPageSize) {
    return InvalidArgument("result page size must be in [1, " +
                           std::to_string(jobs::kMaxResultPageSize) + "], got " +
                           std::to_string(result_page_size));
  }
  if (max_receive_bytes < (4 << 20)) {
    return InvalidArgument("receive limit must be >= 4 MiB, got " +
                           std::to_string(max_receive_bytes) + " bytes");
  }
  if (!tls && !tls_ca_file.empty()) return InvalidArgument("a TLS CA file needs TLS");
  return Status::Ok();
}

RemoteClient::RemoteClient(const RemoteOptions& options,
                           const std::shared_ptr<grpc::ChannelCredentials>& credentials)
    : options_(options) {
  grpc::ChannelArguments args;
  // Result pages are bounded by the server, but one item is sent whole (RemoteOptions).
  args.SetMaxReceiveMessageSize(options_.max_receive_bytes);
  channel_ = grpc::CreateCustomChannel(options_.target, credentials, args);
  jobs_ = v1::Jobs::NewStub(channel_);
  operations_ = google::longrunning::Operations::NewStub(channel_);
}

StatusOr<std::unique_ptr<RemoteClient>> RemoteClient::Connect(const RemoteOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return s;
  std::shared_ptr<grpc::ChannelCredentials> credentials = grpc::InsecureChannelCredentials();
  if (options.tls) {
    grpc::SslCredentialsOptions ssl;
    if (!options.tls_ca_file.empty()) {
      DRILLBIF_ASSIGN_OR_RETURN(ssl.pem_root_certs, ReadPemFile(options.tls_ca_file));
    }
    credentials = grpc::SslCredentials(ssl);
  }
  return std::unique_ptr<RemoteClient>(new RemoteClient(options, credentials));
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
      if (options_.tls) {
        const TlsFailure failure = TlsFailureOf(status.error_message());
        const std::string what = "the TLS handshake with the drillbif server at " + target +
                                 " failed (" + status.error_message() + "); ";
        switch (failure) {
          case TlsFailure::kVerify:
            return Status(StatusCode::kUnauthenticated,
                          what + (options_.tls_ca_file.empty()
                                      ? std::string("its certificate is not signed by a CA of "
                                                    "the system's roots: give its CA "
                                                    "certificate with --tls-ca FILE or "
                                                    "DRILLBIF_TLS_CA")
                                      : "its certificate is not signed by the CA of " +
                                            options_.tls_ca_file + ", or does not name " + target));
          case TlsFailure::kNotTls:
            return Status(StatusCode::kUnauthenticated,
                          what +
                              "the server does not use TLS: drop --tls, --tls-ca and "
                              "DRILLBIF_TLS_CA");
          case TlsFailure::kOther:
            return Status(StatusCode::kUnauthenticated, what +
                                                            "check --tls-ca and the server's "
                                                            "certificate");
          case TlsFailure::kNone:
            break;
        }
      }
      return Status(StatusCode::kUnavailable,
                    "the drillbif server at " + target + " is not available (" +
                        status.error_message() +
                        "); start drillbif-server there, or name another with --server "
                        "HOST:PORT or DRILLBIF_SERVER" +
                        (options_.tls ? std::string()
                                      : std::string("; a server with TLS needs --tls or "
                                                    "--tls-ca FILE")));
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return Status(StatusCode::kDeadlineExceeded, "the drillbif server at " + target +
                                                       " did not answer in time (" +
                                                       status.error_message() + ")");
    case grpc::StatusCode::UNIMPLEMENTED:
      // Not the request's fault: this server takes no such call.
      return Status(StatusCode::kUnavailable,
                    "the drillbif server at " + target + " does not serve this call (" +
                        status.error_message() +
                        "): a worker process (--role worker) takes no requests, and an older "
                        "server lacks newer calls; name an API process with --server HOST:PORT "
                        "or DRILLBIF_SERVER");
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

StatusOr<Operation> RemoteClient::Submit(const v1::OptimumMapRequest& request) {
  v1::SubmitOptimumMapRequest submit;
  *submit.mutable_request() = request;
  Operation op;
  auto context = Context(options_.rpc_timeout_seconds);
  if (grpc::Status s = jobs_->SubmitOptimumMap(context.get(), submit, &op); !s.ok()) {
    return FromGrpc(s);
  }
  return op;
}

StatusOr<v1::QueryOptimumResponse> RemoteClient::QueryOptimum(
    const v1::QueryOptimumRequest& request) {
  v1::QueryOptimumResponse response;
  auto context = Context(options_.rpc_timeout_seconds);
  if (grpc::Status s = jobs_->QueryOptimum(context.get(), request, &response); !s.ok()) {
    return FromGrpc(s);
  }
  return response;
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

Status RemoteClient::GetResultPages(
    const std::string& name,
    const std::function<Status(google::protobuf::Message& page)>& on_page) {
  v1::GetResultRequest request;
  request.set_name(name);
  request.set_page_size(options_.result_page_size);
  const google::protobuf::Descriptor* type = nullptr;
  const jobs::JobKindSpec* kind = nullptr;
  int64_t total = 0;
  int64_t items = 0;
  int64_t pages = 0;
  for (;;) {
    v1::GetResultResponse response;
    auto context = Context(options_.rpc_timeout_seconds);
    if (grpc::Status s = jobs_->GetResult(context.get(), request, &response); !s.ok()) {
      Status status = FromGrpc(s);
      if (pages == 0) return status;
      return Status(status.code(), "while fetching page " + std::to_string(pages + 1) +
                                       " of the result of " + name + ": " + status.message());
    }
    google::protobuf::Message* page = MutableResultOf(response);
    if (page == nullptr) return Internal("the server returned no result for " + name);
    if (pages == 0) {
      type = page->GetDescriptor();
      kind = jobs::FindKind(type);
      if (kind == nullptr)
        return Internal("the server returned an unknown result " + type->full_name());
      total = response.total_points();
    } else if (page->GetDescriptor() != type) {
      return Internal("page " + std::to_string(pages + 1) + " of the result of " + name + " is a " +
                      page->GetDescriptor()->full_name() + ", the first a " + type->full_name());
    }
    items += kind->ItemsOf(*page);
    ++pages;
    DRILLBIF_RETURN_IF_ERROR(on_page(*page));
    const std::string& next = response.next_page_token();
    if (next.empty()) break;
    // A token that does not move on would loop forever: each page but the first and the last
    // holds an item, so a result has at most total_points + 2 pages.
    if (next == request.page_token() || pages > total + 1) {
      return Internal("the server's page token " + next.substr(0, 64) + " for the result of " +
                      name + " does not lead on (page " + std::to_string(pages) + ", " +
                      std::to_string(items) + " of " + std::to_string(total) + " items)");
    }
    request.set_page_token(next);
  }
  if (items != total) {
    return Internal("the result of " + name + " came with " + std::to_string(items) + " items in " +
                    std::to_string(pages) + " pages; the server announced " +
                    std::to_string(total));
  }
  return Status::Ok();
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

google::protobuf::Message* MutableResultOf(v1::GetResultResponse& response) {
  switch (response.result_case()) {
    case v1::GetResultResponse::kSimulate:
      return response.mutable_simulate();
    case v1::GetResultResponse::kSweep:
      return response.mutable_sweep();
    case v1::GetResultResponse::kContinue:
      return response.mutable_continue_();
    case v1::GetResultResponse::kTrace:
      return response.mutable_trace();
    case v1::GetResultResponse::kOptimum:
      return response.mutable_optimum();
    case v1::GetResultResponse::kOptimumMap:
      return response.mutable_optimum_map();
    case v1::GetResultResponse::RESULT_NOT_SET:
      break;
  }
  return nullptr;
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
