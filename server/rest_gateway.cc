#include "server/rest_gateway.h"

#include <google/protobuf/struct.pb.h>
#include <grpcpp/generic/generic_stub.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <map>
#include <mutex>
#include <optional>
#include <utility>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "google/rpc/status.pb.h"
#include "server/cors.h"
#include "server/dashboard.h"
#include "server/executor.h"
#include "server/http_server.h"
#include "server/http_text.h"
#include "server/openapi.h"
#include "server/rest_request.h"
#include "server/services.h"

namespace drillbif::server {
namespace {

using google::longrunning::Operation;
using google::protobuf::Message;

constexpr char kJson[] = "application/json";
// Deadline of GET /healthz's Check: the health service answers from memory, so this only bounds
// a server too overloaded to answer, which a probe should see as unhealthy.
constexpr std::chrono::seconds kHealthDeadline{5};
// /metrics renders wait beyond the one running; more are refused (429): scrapers come every few
// seconds, so only a flood fills this.
constexpr int kMaxQueuedMetricsRenders = 16;

HttpResponse JsonResponse(int status, std::string body) {
  HttpResponse response;
  response.status = status;
  response.content_type = kJson;
  response.body = std::move(body);
  return response;
}

HttpResponse ErrorResponse(const grpc::Status& status, int http_status = 0) {
  return JsonResponse(http_status != 0 ? http_status : HttpStatusOf(status.error_code()),
                      ErrorJson(status));
}

HttpResponse MessageResponse(const Message& message) {
  StatusOr<std::string> json = ToJson(message);
  if (!json.ok()) return ErrorResponse(ToGrpc(json.status()));
  return JsonResponse(200, std::move(json).value());
}

// The deadline of a call made for `exchange`: X-Server-Timeout seconds when given (bounded),
// else the default. INVALID_ARGUMENT for a value that is not a positive number.
grpc::Status DeadlineOf(const HttpExchange& exchange, int default_ms,
                        std::chrono::system_clock::time_point* deadline) {
  double seconds = default_ms / 1000.0;
  if (const std::string* text = exchange.header("X-Server-Timeout")) {
    StatusOr<double> asked = ParseServerTimeout(*text);
    if (!asked.ok()) return ToGrpc(asked.status());
    seconds = *asked;
  }
  *deadline = std::chrono::system_clock::now() +
              std::chrono::microseconds(static_cast<int64_t>(seconds * 1e6));
  return grpc::Status::OK;
}

HttpResponse StreamHead() {
  HttpResponse head;
  head.status = 200;
  head.content_type = "text/event-stream";
  head.headers = {{"Cache-Control", "no-cache"},
                  {"X-Accel-Buffering", "no"}};  // Proxies must not hold events back.
  return head;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

Status RestOptions::Validate() const {
  if (host.empty()) return InvalidArgument("host: must not be empty");
  if (port < 0 || port > 65535) {
    return InvalidArgument("port: must be in [0, 65535], got " + std::to_string(port));
  }
  if (tls_cert_file.empty() != tls_key_file.empty()) {
    return InvalidArgument("tls_cert_file, tls_key_file: give both or neither");
  }
  const auto in_range = [](const char* name, int64_t value, int64_t low, int64_t high) {
    if (value >= low && value <= high) return Status::Ok();
    return InvalidArgument(std::string(name) + ": must be in [" + std::to_string(low) + ", " +
                           std::to_string(high) + "], got " + std::to_string(value));
  };
  if (Status s = ValidateCorsOrigins(cors_origins); !s.ok()) {
    return InvalidArgument("cors_origins (" + s.message() + ")");
  }
  for (const Status& s : {
           in_range("threads", threads, 1, 64),
           in_range("connection_limit", connection_limit, 1, 1 << 20),
           in_range("listen_backlog", listen_backlog, 1, 1 << 16),
           in_range("connection_memory_bytes", connection_memory_bytes, 8 << 10, 64 << 20),
           in_range("max_uri_bytes", max_uri_bytes, 64, 64 << 20),
           in_range("max_header_bytes", max_header_bytes, 256, 64 << 20),
           in_range("max_header_count", max_header_count, 4, 1 << 20),
           in_range("max_body_bytes", max_body_bytes, 1024, 1 << 30),
           in_range("idle_timeout_ms", idle_timeout_ms, 1, 24 * 3600 * 1000),
           in_range("request_timeout_ms", request_timeout_ms, 1, 24 * 3600 * 1000),
           in_range("write_timeout_ms", write_timeout_ms, 1, 24 * 3600 * 1000),
           in_range("deadline_ms", deadline_ms, 1, 24 * 3600 * 1000),
           in_range("stop_grace_ms", stop_grace_ms, 0, 3600 * 1000),
       }) {
    if (!s.ok()) return s;
  }
  // The request line is part of the header bytes, which libmicrohttpd must hold with room to
  // spare (it also keeps a record per header there); else its own HTML answer comes first.
  if (max_uri_bytes > max_header_bytes) {
    return InvalidArgument("max_uri_bytes: must be <= max_header_bytes (" +
                           std::to_string(max_header_bytes) + "), got " +
                           std::to_string(max_uri_bytes));
  }
  if (2 * int64_t{max_header_bytes} > connection_memory_bytes) {
    return InvalidArgument("max_header_bytes: must be at most half of connection_memory_bytes (" +
                           std::to_string(connection_memory_bytes) + "), got " +
                           std::to_string(max_header_bytes));
  }
  return Status::Ok();
}

int HttpStatusOf(grpc::StatusCode code) {
  switch (code) {
    case grpc::StatusCode::OK:
      return 200;
    case grpc::StatusCode::INVALID_ARGUMENT:
    case grpc::StatusCode::FAILED_PRECONDITION:
      return 400;
    case grpc::StatusCode::UNAUTHENTICATED:
      return 401;
    case grpc::StatusCode::PERMISSION_DENIED:
      return 403;
    case grpc::StatusCode::NOT_FOUND:
      return 404;
    case grpc::StatusCode::ALREADY_EXISTS:
    case grpc::StatusCode::ABORTED:
      return 409;
    case grpc::StatusCode::RESOURCE_EXHAUSTED:
      return 429;
    case grpc::StatusCode::UNIMPLEMENTED:
      return 501;
    case grpc::StatusCode::UNAVAILABLE:
      return 503;
    case grpc::StatusCode::DEADLINE_EXCEEDED:
      return 504;
    default:
      return 500;
  }
}

std::string ErrorJson(const grpc::Status& status) {
  // Written field by field (a Struct would print its keys in hash order); the strings are
  // escaped by the JSON printer.
  const auto quoted = [](const std::string& text) {
    google::protobuf::Value value;
    value.set_string_value(text);
    StatusOr<std::string> json = ToJson(value);
    return json.ok() ? *json : std::string("\"\"");
  };
  std::string details;
  google::rpc::Status rich;
  if (!status.error_details().empty() && rich.ParseFromString(status.error_details())) {
    for (const google::protobuf::Any& any : rich.details()) {
      StatusOr<std::string> json = ToJson(any);
      if (!json.ok()) continue;  // A detail of a type this build does not know.
      if (!details.empty()) details += ",";
      details += *json;
    }
  }
  return "{\"code\":" + quoted(GrpcCodeName(static_cast<int>(status.error_code()))) +
         ",\"message\":" + quoted(ValidUtf8(status.error_message())) + ",\"details\":[" + details +
         "]}";
}

// ---------------------------------------------------------------------------------------------

struct RestGateway::Impl final : public HttpHandler {
  class WatchStream;

  RestOptions options;
  Metrics* metrics = nullptr;
  MetricsTextFunction metrics_text;
  std::unique_ptr<v1::Jobs::Stub> jobs;
  std::unique_ptr<google::longrunning::Operations::Stub> operations;
  std::unique_ptr<grpc::GenericStub> generic;  // grpc.health.v1.Health (no proto compiled here)
  std::unique_ptr<BoundedExecutor> renderer;   // /metrics (it reads the store: may block).
  std::unique_ptr<HttpServer> http;

  // Calls in progress, by a number of their own, with what cancels each (Stop cancels them).
  std::mutex mutex;
  std::condition_variable changed;
  bool stopping = false;
  uint64_t next_call = 1;
  std::map<uint64_t, std::function<void()>> calls;    // Unary calls.
  std::map<uint64_t, std::function<void()>> streams;  // Watch streams.

  // Registers a call about to start; 0 when the gateway stops (then answer 503).
  uint64_t Enter(std::function<void()> cancel, bool stream) {
    std::lock_guard<std::mutex> lock(mutex);
    if (stopping) return 0;
    const uint64_t id = next_call++;
    (stream ? streams : calls).emplace(id, std::move(cancel));
    return id;
  }

  // The call ended. The last use of the gateway by the call's callbacks: Stop may return as soon
  // as the lock is released.
  void Leave(uint64_t id, bool stream) {
    std::lock_guard<std::mutex> lock(mutex);
    (stream ? streams : calls).erase(id);
    changed.notify_all();
  }

  static HttpResponse ShuttingDown() {
    return ErrorResponse(
        grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
  }

  // The token check made before the body is read, with the REST wording of the message.
  grpc::Status Authorize(const HttpExchange& exchange) const {
    const std::string* authorization = exchange.header("Authorization");
    if (authorization != nullptr && FindInvalidUtf8(*authorization) != std::string_view::npos) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                          "header Authorization: not valid UTF-8");
    }
    const StatusOr<std::string> client = options.tokens->Authenticate(
        authorization != nullptr, authorization != nullptr ? *authorization : std::string());
    const grpc::Status s = ToGrpc(client.status());
    if (!s.ok() && authorization == nullptr) {
      return grpc::Status(s.error_code(),
                          "missing bearer token (header \"Authorization: Bearer <token>\")");
    }
    return s;
  }

  // A client context for a call made for `exchange`: deadline and the token as metadata.
  grpc::Status PrepareContext(const HttpExchange& exchange, grpc::ClientContext* context,
                              bool with_deadline) const {
    if (with_deadline) {
      std::chrono::system_clock::time_point deadline;
      if (grpc::Status s = DeadlineOf(exchange, options.deadline_ms, &deadline); !s.ok()) {
        return s;
      }
      context->set_deadline(deadline);
    }
    // Passed on only when it was checked: a header the gateway accepted is valid metadata.
    if (!options.tokens->empty()) {
      context->AddMetadata("authorization", *exchange.header("Authorization"));
    }
    return grpc::Status::OK;
  }

  // The common shape of a unary route: request, callback call, JSON answer or JSON error. The
  // connection stays suspended until the callback answers; a client that goes away cancels.
  template <typename Request, typename Response, typename StartCall>
  void Unary(const std::shared_ptr<HttpExchange>& exchange, int route, const std::string& name,
             StartCall start) {
    struct Call {
      grpc::ClientContext context;
      Request request;
      Response response;
    };
    auto call = std::make_shared<Call>();
    if (Status s = BuildRequest(route, exchange->target(), exchange->body(), name, &call->request);
        !s.ok()) {
      return exchange->Respond(ErrorResponse(ToGrpc(s)));
    }
    if (grpc::Status s = PrepareContext(*exchange, &call->context, true); !s.ok()) {
      return exchange->Respond(ErrorResponse(s));
    }
    const uint64_t id = Enter([call] { call->context.TryCancel(); }, false);
    if (id == 0) return exchange->Respond(ShuttingDown());
    exchange->OnClientGone([call] { call->context.TryCancel(); });
    start(
        &call->context, &call->request, &call->response,
        [this, exchange, call, id](grpc::Status status) {
          // On a gRPC thread: the JSON is printed here, not on an HTTP thread.
          exchange->Respond(status.ok() ? MessageResponse(call->response) : ErrorResponse(status));
          Leave(id, false);
        });
  }

  void Watch(const std::shared_ptr<HttpExchange>& exchange, const std::string& name);

  void ServeMetrics(const std::shared_ptr<HttpExchange>& exchange) {
    const bool queued = renderer->TrySubmit([this, exchange] {
      StatusOr<std::string> text = metrics_text();
      if (!text.ok()) return exchange->Respond(ErrorResponse(ToGrpc(text.status())));
      HttpResponse response;
      response.content_type = kMetricsContentType;
      response.body = std::move(text).value();
      exchange->Respond(std::move(response));
    });
    if (!queued) {
      exchange->Respond(ErrorResponse(grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                                   "too many /metrics requests at once")));
    }
  }

  // GET /healthz: the gRPC health service's Check of the whole server, over the in-process
  // channel like every route: 200 {"status":"SERVING"}, else 503 with the status it gave
  // (NOT_SERVING during shutdown or a store fault).
  void ServeHealth(const std::shared_ptr<HttpExchange>& exchange) {
    struct Call {
      grpc::ClientContext context;
      grpc::ByteBuffer request;
      grpc::ByteBuffer response;
    };
    auto call = std::make_shared<Call>();
    // No token is passed on (the route is open, and so is the health service); a probe's
    // answer is due at once.
    call->context.set_deadline(std::chrono::system_clock::now() + kHealthDeadline);
    grpc::Slice empty("");  // HealthCheckRequest{service: ""}: the empty message.
    call->request = grpc::ByteBuffer(&empty, 1);
    const uint64_t id = Enter([call] { call->context.TryCancel(); }, false);
    if (id == 0) return exchange->Respond(ShuttingDown());
    exchange->OnClientGone([call] { call->context.TryCancel(); });
    generic->UnaryCall(&call->context, "/grpc.health.v1.Health/Check", grpc::StubOptions(),
                       &call->request, &call->response,
                       [this, exchange, call, id](grpc::Status status) {
                         if (!status.ok()) {
                           exchange->Respond(ErrorResponse(status));
                           return Leave(id, false);
                         }
                         std::vector<grpc::Slice> slices;
                         std::string bytes;
                         if (call->response.Dump(&slices).ok()) {
                           for (const grpc::Slice& slice : slices)
                             bytes.append(slice.begin(), slice.end());
                         }
                         // HealthCheckResponse.status is field 1, a varint: 1 SERVING, 2
                         // NOT_SERVING; the empty message is UNKNOWN (0).
                         const int value = bytes.size() == 2 && bytes[0] == '\x08' ? bytes[1] : 0;
                         HttpResponse response;
                         response.status = value == 1 ? 200 : 503;
                         response.content_type = "application/json";
                         response.body = std::string(R"({"status":")") +
                                         (value == 1   ? "SERVING"
                                          : value == 2 ? "NOT_SERVING"
                                                       : "UNKNOWN") +
                                         "\"}";
                         exchange->Respond(std::move(response));
                         Leave(id, false);
                       });
  }

  // A CORS preflight (OPTIONS with Origin and Access-Control-Request-Method on a served path,
  // CORS on): answered here, before the token check, since browsers send no Authorization on
  // a preflight. nullopt for any other request (an OPTIONS that is not a preflight, or on an
  // unknown path, then gets FindRoute's 405 or 404).
  std::optional<HttpResponse> Preflight(HttpExchange& exchange) const {
    if (options.cors_origins.empty() || exchange.method() != "OPTIONS") return std::nullopt;
    const std::string* origin = exchange.header("Origin");
    if (origin == nullptr || exchange.header("Access-Control-Request-Method") == nullptr) {
      return std::nullopt;
    }
    const std::vector<int> routes = RoutesOf(exchange.target().path);
    if (routes.empty()) return std::nullopt;
    std::string methods;
    for (int route : routes) {
      if (methods.find(kRoutes[route].method) != std::string::npos) continue;
      methods += (methods.empty() ? "" : ", ") + std::string(kRoutes[route].method);
    }
    exchange.set_route_label(kRoutes[routes.front()].label);
    return CorsPreflight(options.cors_origins, *origin, methods);
  }

  // HttpHandler: route, method and token, before the body is read.
  std::optional<HttpResponse> OnHeaders(HttpExchange& exchange) override {
    if (std::optional<HttpResponse> preflight = Preflight(exchange)) return preflight;
    std::string name;
    const StatusOr<int> found = FindRoute(exchange.method(), exchange.target().path, &name);
    if (!found.ok() && found.status().code() == StatusCode::kNotFound) {
      // No API route: the dashboard's static files (open: they hold no data), or its 404 /
      // 405. A file is answered in OnRequest: an answer given before the (empty) body is read
      // would close the connection, and a browser loads several files.
      if (std::optional<HttpResponse> file = ServeDashboard(
              exchange.method(), exchange.target().path, exchange.header("If-None-Match"))) {
        exchange.set_route_label("dashboard");
        if (file->status >= 400) return file;
        return std::nullopt;
      }
    }
    if (!found.ok()) {
      // A path served with other methods is 405 (UNIMPLEMENTED alone would be 501).
      return ErrorResponse(ToGrpc(found.status()),
                           found.status().code() == StatusCode::kUnimplemented ? 405 : 0);
    }
    const int route = *found;
    exchange.set_route_label(kRoutes[route].label);
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (stopping) return ShuttingDown();
    }
    // Open, like gRPC health; the document is the contract, not data.
    if (route == kMetrics || route == kHealth || route == kOpenApi) return std::nullopt;
    if (grpc::Status s = Authorize(exchange); !s.ok()) return ErrorResponse(s);
    return std::nullopt;
  }

  // HttpHandler: the whole request is in.
  void OnRequest(std::shared_ptr<HttpExchange> exchange) override {
    using google::longrunning::CancelOperationRequest;
    using google::longrunning::DeleteOperationRequest;
    using google::longrunning::GetOperationRequest;
    using google::longrunning::ListOperationsRequest;
    using google::longrunning::ListOperationsResponse;
    using google::protobuf::Empty;
    std::string name;
    bool path_known = false;
    const int route = MatchRoute(exchange->method(), exchange->target().path, &name, &path_known);
    auto* j = jobs->async();
    auto* o = operations->async();
    // Each lambda starts one callback call: (context, request, response, done).
    switch (route) {
      case kSubmitSimulate:
        return Unary<v1::SubmitSimulateRequest, Operation>(
            exchange, route, name, [j](auto... a) { j->SubmitSimulate(a...); });
      case kSubmitSweep:
        return Unary<v1::SubmitSweepRequest, Operation>(exchange, route, name,
                                                        [j](auto... a) { j->SubmitSweep(a...); });
      case kSubmitContinue:
        return Unary<v1::SubmitContinueRequest, Operation>(
            exchange, route, name, [j](auto... a) { j->SubmitContinue(a...); });
      case kSubmitTrace:
        return Unary<v1::SubmitTraceRequest, Operation>(exchange, route, name,
                                                        [j](auto... a) { j->SubmitTrace(a...); });
      case kSubmitOptimum:
        return Unary<v1::SubmitOptimumRequest, Operation>(
            exchange, route, name, [j](auto... a) { j->SubmitOptimum(a...); });
      case kSubmitOptimumMap:
        return Unary<v1::SubmitOptimumMapRequest, Operation>(
            exchange, route, name, [j](auto... a) { j->SubmitOptimumMap(a...); });
      case kGetResult:
        return Unary<v1::GetResultRequest, v1::GetResultResponse>(
            exchange, route, name, [j](auto... a) { j->GetResult(a...); });
      case kQueryOptimum:
        return Unary<v1::QueryOptimumRequest, v1::QueryOptimumResponse>(
            exchange, route, name, [j](auto... a) { j->QueryOptimum(a...); });
      case kWatch:
        return Watch(exchange, name);
      case kListOperations:
        return Unary<ListOperationsRequest, ListOperationsResponse>(
            exchange, route, name, [o](auto... a) { o->ListOperations(a...); });
      case kCancelOperation:
        return Unary<CancelOperationRequest, Empty>(exchange, route, name,
                                                    [o](auto... a) { o->CancelOperation(a...); });
      case kGetOperation:
        return Unary<GetOperationRequest, Operation>(exchange, route, name,
                                                     [o](auto... a) { o->GetOperation(a...); });
      case kDeleteOperation:
        return Unary<DeleteOperationRequest, Empty>(exchange, route, name,
                                                    [o](auto... a) { o->DeleteOperation(a...); });
      case kMetrics:
        return ServeMetrics(exchange);
      case kHealth:
        return ServeHealth(exchange);
      case kOpenApi: {
        StatusOr<std::string> document = OpenApiJson();
        return exchange->Respond(document.ok() ? JsonResponse(200, std::move(document).value())
                                               : ErrorResponse(ToGrpc(document.status())));
      }
      default:
        // The dashboard's files; OnHeaders refused every other path.
        if (std::optional<HttpResponse> file = ServeDashboard(
                exchange->method(), exchange->target().path, exchange->header("If-None-Match"))) {
          return exchange->Respond(std::move(*file));
        }
        return exchange->Respond(
            ErrorResponse(grpc::Status(grpc::StatusCode::INTERNAL, "request reached no route")));
    }
  }
};

// GET .../operations/{id}:watch: the Watch stream as Server-Sent Events, one
// "data: <JobMetadata JSON>\n\n" per message; a stream ending with an error sends
// "event: error\ndata: <error JSON>\n\n" last. The answer starts with the first message, so that
// an unknown operation or a missing token is a plain JSON error instead. One message is read at
// a time: the next read starts when the HTTP side has taken the previous event, so a client that
// reads slowly holds one event, not a queue (Watch sends the newest state; nothing is lost but
// intermediate progress).
class RestGateway::Impl::WatchStream final : public grpc::ClientReadReactor<v1::JobMetadata>,
                                             public HttpStream,
                                             public std::enable_shared_from_this<WatchStream> {
 public:
  WatchStream(Impl* gateway, std::shared_ptr<HttpExchange> exchange)
      : gateway_(gateway), exchange_(std::move(exchange)) {}

  grpc::ClientContext& context() { return context_; }
  v1::WatchRequest& request() { return request_; }

  // Starts the call; the stream keeps itself alive until OnDone.
  void Begin(uint64_t id) {
    id_ = id;
    self_ = shared_from_this();
    gateway_->jobs->async()->Watch(&context_, &request_, this);
    StartRead(&message_);
    StartCall();
  }

  void OnReadDone(bool ok) override {
    if (!ok) return;  // OnDone follows.
    StatusOr<std::string> json = ToJson(message_);
    std::string event = "data: " + (json.ok() ? *json : ErrorJson(ToGrpc(json.status()))) + "\n\n";
    bool first;
    std::shared_ptr<HttpExchange> exchange;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      pending_ = std::move(event);
      first = !started_;
      started_ = true;
      exchange = exchange_;
    }
    if (exchange == nullptr) return;
    if (first) {
      exchange->RespondStream(StreamHead(), shared_from_this());
    } else {
      exchange->Wake();
    }
  }

  void OnDone(const grpc::Status& status) override {
    bool started;
    std::shared_ptr<HttpExchange> exchange;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      done_ = true;
      status_ = status;
      started = started_;
      exchange.swap(exchange_);
    }
    if (!started) {
      exchange->Respond(ErrorResponse(
          status.ok()
              ? grpc::Status(grpc::StatusCode::INTERNAL, "the watch ended without a message")
              : status));
    } else {
      exchange->Wake();
    }
    Impl* gateway = gateway_;
    const uint64_t id = id_;
    std::shared_ptr<WatchStream> self = std::move(self_);  // May be the last reference.
    gateway->Leave(id, true);
  }

  // HttpStream (HTTP thread).
  Pull Next(std::string* out) override {
    bool read_next = false;
    Pull pull;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!pending_.empty()) {
        *out = std::move(pending_);
        pending_.clear();
        read_next = !done_;
        pull = Pull::kData;
      } else if (!done_) {
        pull = Pull::kWait;
      } else if (!status_.ok() && !error_sent_) {
        error_sent_ = true;
        *out = "event: error\ndata: " + ErrorJson(status_) + "\n\n";
        pull = Pull::kData;
      } else {
        pull = Pull::kEnd;
      }
    }
    // Outside the lock: gRPC may run OnReadDone inline.
    if (read_next) StartRead(&message_);
    return pull;
  }

 private:
  Impl* const gateway_;
  grpc::ClientContext context_;
  v1::WatchRequest request_;
  v1::JobMetadata message_;
  uint64_t id_ = 0;
  std::shared_ptr<WatchStream> self_;

  std::mutex mutex_;
  std::shared_ptr<HttpExchange> exchange_;  // Until OnDone.
  std::string pending_;                     // The event read and not yet taken.
  bool started_ = false;                    // The answer started (with the first event).
  bool done_ = false;
  grpc::Status status_;
  bool error_sent_ = false;
};

void RestGateway::Impl::Watch(const std::shared_ptr<HttpExchange>& exchange,
                              const std::string& name) {
  auto stream = std::make_shared<WatchStream>(this, exchange);
  if (Status s =
          BuildRequest(kWatch, exchange->target(), exchange->body(), name, &stream->request());
      !s.ok()) {
    return exchange->Respond(ErrorResponse(ToGrpc(s)));
  }
  // No deadline: the stream lasts as long as the job.
  if (grpc::Status s = PrepareContext(*exchange, &stream->context(), false); !s.ok()) {
    return exchange->Respond(ErrorResponse(s));
  }
  const uint64_t id = Enter([stream] { stream->context().TryCancel(); }, true);
  if (id == 0) return exchange->Respond(ShuttingDown());
  exchange->OnClientGone([stream] { stream->context().TryCancel(); });
  stream->Begin(id);
}

RestGateway::RestGateway(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

RestGateway::~RestGateway() { Stop(); }

StatusOr<std::unique_ptr<RestGateway>> RestGateway::Start(const RestOptions& options,
                                                          std::shared_ptr<grpc::Channel> channel,
                                                          Metrics* metrics,
                                                          MetricsTextFunction metrics_text) {
  if (Status s = options.Validate(); !s.ok()) return s;
  if (channel == nullptr || metrics == nullptr || !metrics_text) {
    return InvalidArgument("RestGateway::Start: channel, metrics and metrics_text are required");
  }
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  impl->metrics = metrics;
  impl->metrics_text = std::move(metrics_text);
  impl->jobs = v1::Jobs::NewStub(channel);
  impl->operations = google::longrunning::Operations::NewStub(channel);
  impl->generic = std::make_unique<grpc::GenericStub>(channel);
  ExecutorOptions renderer;
  renderer.threads = 1;
  renderer.max_queued = kMaxQueuedMetricsRenders;
  impl->renderer = std::make_unique<BoundedExecutor>(renderer);
  StatusOr<std::unique_ptr<HttpServer>> http = HttpServer::Start(options, impl.get(), metrics);
  if (!http.ok()) {
    impl->renderer->Stop();
    return http.status();
  }
  impl->http = std::move(http).value();
  return std::unique_ptr<RestGateway>(new RestGateway(std::move(impl)));
}

int RestGateway::port() const { return impl_->http->port(); }

void RestGateway::Stop() {
  Impl& impl = *impl_;
  const std::chrono::milliseconds grace(impl.options.stop_grace_ms);
  // Cancels run outside the lock: gRPC may run a call's callback inline, which takes it.
  const auto cancel_all = [&impl](const std::map<uint64_t, std::function<void()>>& which) {
    std::vector<std::function<void()>> cancels;
    {
      std::lock_guard<std::mutex> lock(impl.mutex);
      for (const auto& [id, cancel] : which) cancels.push_back(cancel);
    }
    for (const auto& cancel : cancels) cancel();
  };
  {
    std::unique_lock<std::mutex> lock(impl.mutex);
    if (impl.stopping) return;
    impl.stopping = true;
    // Streams whose Watch ended write their last event and close.
    impl.changed.wait_for(lock, grace, [&impl] { return impl.streams.empty(); });
  }
  cancel_all(impl.streams);
  {
    std::unique_lock<std::mutex> lock(impl.mutex);
    impl.changed.wait_for(lock, grace, [&impl] { return impl.calls.empty(); });
  }
  cancel_all(impl.calls);
  {
    std::unique_lock<std::mutex> lock(impl.mutex);
    impl.changed.wait(lock, [&impl] { return impl.calls.empty() && impl.streams.empty(); });
  }
  impl.http->Stop(impl.options.stop_grace_ms);
  impl.renderer->Stop();
}

}  // namespace drillbif::server
