#include "server/rest_gateway.h"

#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <cstdlib>
#include <mutex>
#include <optional>
#include <regex>
#include <set>
#include <thread>
#include <utility>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "google/rpc/status.pb.h"
#include "server/services.h"

// Last: httplib.h includes <resolv.h>, whose macro _res breaks Eigen's headers (a parameter name)
// when they come after it.
#include <httplib.h>

namespace drillbif::server {
namespace {

using google::longrunning::Operation;
using google::protobuf::Message;
using google::protobuf::util::JsonParseOptions;
using google::protobuf::util::JsonPrintOptions;

constexpr char kJson[] = "application/json";
// Longest deadline a request may ask for with X-Server-Timeout (the services' longest wait).
constexpr double kMaxServerTimeoutSeconds = 600;

// What binds the fields of a route's request message (google.api.http): the path's {name=...}
// variable, and either the body ("*": every other field) or the query parameters (GET, DELETE).
enum class Binding { kBody, kQuery };

// A route: its method, its path pattern as a regex (group 1: the {name} variable, if any) and
// its template as written in the annotation (the metrics label).
struct RouteSpec {
  const char* method;
  const char* regex;
  const char* label;
};

// Every route, in matching order: a path matched by two patterns goes to the first (so the
// ":result", ":watch" and ":cancel" routes precede the catch-all operations/** ones).
constexpr RouteSpec kRoutes[] = {
    {"POST", R"(/v1/jobs:simulate)", "/v1/jobs:simulate"},
    {"POST", R"(/v1/jobs:sweep)", "/v1/jobs:sweep"},
    {"POST", R"(/v1/jobs:continue)", "/v1/jobs:continue"},
    {"POST", R"(/v1/jobs:trace)", "/v1/jobs:trace"},
    {"POST", R"(/v1/jobs:optimum)", "/v1/jobs:optimum"},
    {"GET", R"(/v1/(operations/[^/]+):result)", "/v1/{name=operations/*}:result"},
    {"POST", R"(/v1/optimum:query)", "/v1/optimum:query"},
    {"GET", R"(/v1/(operations/[^/]+):watch)", "/v1/{name=operations/*}:watch"},
    {"GET", R"(/v1/(operations))", "/v1/{name=operations}"},
    {"POST", R"(/v1/(operations/.+):cancel)", "/v1/{name=operations/**}:cancel"},
    {"GET", R"(/v1/(operations/.+))", "/v1/{name=operations/**}"},
    {"DELETE", R"(/v1/(operations/.+))", "/v1/{name=operations/**}"},
    {"GET", R"(/metrics)", "/metrics"},
};

// The JSON text of a message (protobuf's JSON mapping, one line, lowerCamelCase names, fields
// at their default value left out). Any fields (Operation.metadata, .response) resolve their
// types in the generated pool, which holds every message of the API.
StatusOr<std::string> ToJson(const Message& message) {
  std::string out;
  JsonPrintOptions options;
  auto status = google::protobuf::util::MessageToJsonString(message, &out, options);
  if (!status.ok()) {
    return Status(StatusCode::kInternal, "cannot print " + message.GetTypeName() +
                                             " as JSON: " + std::string(status.message()));
  }
  return out;
}

// Parses JSON into `message`, refusing unknown fields (a misspelt field must not be silently
// ignored: the request would run with a default instead).
grpc::Status FromJson(std::string_view json, Message* message, const char* what) {
  JsonParseOptions options;
  options.ignore_unknown_fields = false;
  auto status = google::protobuf::util::JsonStringToMessage(
      google::protobuf::StringPiece(json.data(), json.size()), message, options);
  if (!status.ok()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        std::string(what) + ": not a valid " + message->GetTypeName() +
                            " in JSON: " + std::string(status.message()));
  }
  return grpc::Status::OK;
}

void SetJson(httplib::Response& res, int status, std::string body) {
  res.status = status;
  res.set_content(std::move(body), kJson);
}

void SetError(httplib::Response& res, const grpc::Status& status, int http_status = 0) {
  SetJson(res, http_status != 0 ? http_status : HttpStatusOf(status.error_code()),
          ErrorJson(status));
}

// Sets the field `name` (a string) of `message` to the path variable, refusing a different value
// given in the body or the query.
grpc::Status BindName(const std::string& name, Message* message) {
  const auto* field = message->GetDescriptor()->FindFieldByName("name");
  if (field == nullptr) {
    return grpc::Status(grpc::StatusCode::INTERNAL,
                        message->GetTypeName() + " has no field 'name' to bind the path to");
  }
  const auto* reflection = message->GetReflection();
  const std::string given = reflection->GetString(*message, field);
  if (!given.empty() && given != name) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                        "name: '" + given + "' differs from the path's '" + name + "'");
  }
  reflection->SetString(message, field, name);
  return grpc::Status::OK;
}

// The query parameters as a JSON object of strings, parsed into `message` by the JSON mapping:
// names are the fields' (proto or lowerCamelCase), numbers are accepted as strings, and an
// unknown parameter is refused like an unknown JSON field.
grpc::Status FromQuery(const httplib::Params& params, Message* message) {
  google::protobuf::Struct object;
  for (const auto& [key, value] : params) {
    auto* fields = object.mutable_fields();
    if (fields->count(key) != 0) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                          "query parameter '" + key + "' is given more than once");
    }
    (*fields)[key].set_string_value(value);
  }
  StatusOr<std::string> json = ToJson(object);
  if (!json.ok()) return ToGrpc(json.status());
  return FromJson(*json, message, "query");
}

// The deadline of a call made for `req`: X-Server-Timeout seconds when given (bounded), else the
// default. INVALID_ARGUMENT for a value that is not a positive number.
grpc::Status DeadlineOf(const httplib::Request& req, int default_ms,
                        std::chrono::system_clock::time_point* deadline) {
  double seconds = default_ms / 1000.0;
  if (req.has_header("X-Server-Timeout")) {
    const std::string text = req.get_header_value("X-Server-Timeout");
    char* end = nullptr;
    const double value = std::strtod(text.c_str(), &end);
    if (text.empty() || end == nullptr || *end != '\0' || !std::isfinite(value) || value <= 0) {
      return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                          "X-Server-Timeout: expected seconds > 0, got '" + text + "'");
    }
    seconds = std::min(value, kMaxServerTimeoutSeconds);
  }
  *deadline = std::chrono::system_clock::now() +
              std::chrono::microseconds(static_cast<int64_t>(seconds * 1e6));
  return grpc::Status::OK;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

Status RestOptions::Validate() const {
  if (host.empty()) return InvalidArgument("host: must not be empty");
  if (port < 0 || port > 65535) {
    return InvalidArgument("port: must be in [0, 65535], got " + std::to_string(port));
  }
  if (max_body_bytes < 1024) {
    return InvalidArgument("max_body_bytes: must be >= 1024, got " +
                           std::to_string(max_body_bytes));
  }
  if (threads < 1 || threads > 1024) {
    return InvalidArgument("threads: must be in [1, 1024], got " + std::to_string(threads));
  }
  if (deadline_ms < 1) {
    return InvalidArgument("deadline_ms: must be >= 1, got " + std::to_string(deadline_ms));
  }
  if (read_timeout_ms < 1) {
    return InvalidArgument("read_timeout_ms: must be >= 1, got " + std::to_string(read_timeout_ms));
  }
  if (stop_grace_ms < 0) {
    return InvalidArgument("stop_grace_ms: must be >= 0, got " + std::to_string(stop_grace_ms));
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
         ",\"message\":" + quoted(status.error_message()) + ",\"details\":[" + details + "]}";
}

// ---------------------------------------------------------------------------------------------

struct RestGateway::Impl {
  // One open event stream: the Watch call it relays.
  struct WatchCall {
    grpc::ClientContext context;
    std::unique_ptr<grpc::ClientReader<v1::JobMetadata>> reader;
    std::optional<v1::JobMetadata> first;  // Read before the response started.
    bool finished = false;                 // reader->Finish() was called.
  };

  RestOptions options;
  Metrics* metrics = nullptr;
  MetricsTextFunction metrics_text;
  std::unique_ptr<v1::Jobs::Stub> jobs;
  std::unique_ptr<google::longrunning::Operations::Stub> operations;
  httplib::Server http;
  std::vector<std::regex> route_regexes;  // kRoutes' patterns, compiled once.
  int port = 0;
  std::thread listener;

  std::mutex mutex;
  std::condition_variable watches_changed;
  bool stopped = false;
  std::set<WatchCall*> watches;  // Open streams, awaited and then cancelled by Stop.

  // The template of the route serving `method` `path`, "other" when none.
  const char* RouteLabel(const std::string& method, const std::string& path) const {
    for (size_t i = 0; i < std::size(kRoutes); ++i) {
      if (method == kRoutes[i].method && std::regex_match(path, route_regexes[i])) {
        return kRoutes[i].label;
      }
    }
    return "other";
  }

  // Whether some route serves `path` with another method (then 405 rather than 404).
  bool PathKnown(const std::string& path) const {
    for (size_t i = 0; i < std::size(kRoutes); ++i) {
      if (std::regex_match(path, route_regexes[i])) return true;
    }
    return false;
  }

  // The token check made before anything is parsed, with the REST wording of the message.
  grpc::Status Authorize(const httplib::Request& req) const {
    const bool present = req.has_header("Authorization");
    grpc::Status s = CheckBearerToken(
        options.token, present, present ? req.get_header_value("Authorization") : std::string());
    if (!s.ok() && !present) {
      return grpc::Status(s.error_code(),
                          "missing bearer token (header \"Authorization: Bearer <token>\")");
    }
    return s;
  }

  // A client context for a call made for `req`: deadline and the token as metadata.
  grpc::Status PrepareContext(const httplib::Request& req, grpc::ClientContext* context,
                              bool with_deadline) const {
    if (with_deadline) {
      std::chrono::system_clock::time_point deadline;
      if (grpc::Status s = DeadlineOf(req, options.deadline_ms, &deadline); !s.ok()) return s;
      context->set_deadline(deadline);
    }
    // Passed on only when it was checked above: a header the gateway accepted is valid metadata.
    if (!options.token.empty()) {
      context->AddMetadata("authorization", req.get_header_value("Authorization"));
    }
    return grpc::Status::OK;
  }

  // Builds the request message of a route from the path, the body or the query.
  grpc::Status BuildRequest(const httplib::Request& req, Binding binding, Message* request) const {
    if (req.body.size() > static_cast<size_t>(options.max_body_bytes)) {
      // Not reached through httplib, which refuses such a body by its Content-Length (and
      // chunked bodies before routing); kept so that the limit holds whatever reads the body.
      return grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                          "request body of " + std::to_string(req.body.size()) +
                              " bytes is larger than the limit of " +
                              std::to_string(options.max_body_bytes));
    }
    if (binding == Binding::kBody) {
      // req.params would also hold a form-encoded body's fields (curl -d sends that content
      // type): the target tells whether there is a query string. The body is JSON whatever
      // the Content-Type says.
      if (req.target.find('?') != std::string::npos) {
        return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                            "query parameters: this route takes every field from the body");
      }
      const bool blank = std::all_of(req.body.begin(), req.body.end(), [](char c) {
        return c == ' ' || c == '\n' || c == '\r' || c == '\t';
      });
      if (grpc::Status s = FromJson(blank ? std::string_view("{}") : req.body, request, "body");
          !s.ok()) {
        return s;
      }
    } else {
      if (grpc::Status s = FromQuery(req.params, request); !s.ok()) return s;
    }
    if (req.matches.size() > 1) return BindName(req.matches[1].str(), request);
    return grpc::Status::OK;
  }

  // The common shape of a unary route: token, request, call, JSON answer or JSON error.
  template <typename Request, typename Response, typename Call>
  void Unary(const httplib::Request& req, httplib::Response& res, Binding binding, Call call) {
    if (grpc::Status s = Authorize(req); !s.ok()) return SetError(res, s);
    Request request;
    if (grpc::Status s = BuildRequest(req, binding, &request); !s.ok()) {
      return SetError(res, s, s.error_code() == grpc::StatusCode::RESOURCE_EXHAUSTED ? 413 : 0);
    }
    grpc::ClientContext context;
    if (grpc::Status s = PrepareContext(req, &context, /*with_deadline=*/true); !s.ok()) {
      return SetError(res, s);
    }
    Response response;
    grpc::Status status = call(&context, request, &response);
    if (!status.ok()) return SetError(res, status);
    StatusOr<std::string> json = ToJson(response);
    if (!json.ok()) return SetError(res, ToGrpc(json.status()));
    SetJson(res, 200, std::move(json).value());
  }

  // GET .../operations/{id}:watch: the Watch stream as Server-Sent Events, one
  // "data: <JobMetadata JSON>\n\n" per message; a stream ending with an error sends
  // "event: error\ndata: <error JSON>\n\n" last. The first message is read before the response
  // starts, so that an unknown operation or a missing token is a plain JSON error instead.
  void Watch(const httplib::Request& req, httplib::Response& res) {
    if (grpc::Status s = Authorize(req); !s.ok()) return SetError(res, s);
    v1::WatchRequest request;
    if (grpc::Status s = BuildRequest(req, Binding::kQuery, &request); !s.ok()) {
      return SetError(res, s);
    }
    auto call = std::make_shared<WatchCall>();
    // No deadline: the stream lasts as long as the job.
    if (grpc::Status s = PrepareContext(req, &call->context, /*with_deadline=*/false); !s.ok()) {
      return SetError(res, s);
    }
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (stopped) {
        return SetError(res,
                        grpc::Status(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
      }
      watches.insert(call.get());
    }
    call->reader = jobs->Watch(&call->context, request);
    v1::JobMetadata first;
    if (!call->reader->Read(&first)) {
      grpc::Status s = call->reader->Finish();
      call->finished = true;
      Forget(call.get());
      return SetError(res, s.ok() ? grpc::Status(grpc::StatusCode::INTERNAL,
                                                 "the watch ended without a message")
                                  : s);
    }
    call->first = std::move(first);
    res.status = 200;
    res.set_header("Cache-Control", "no-cache");
    res.set_header("X-Accel-Buffering", "no");  // Proxies must not hold events back.
    res.set_chunked_content_provider(
        "text/event-stream",
        [call](size_t, httplib::DataSink& sink) {
          v1::JobMetadata metadata;
          if (call->first) {
            metadata = std::move(*call->first);
            call->first.reset();
          } else if (!call->reader->Read(&metadata)) {
            grpc::Status s = call->reader->Finish();
            call->finished = true;
            if (!s.ok()) {
              const std::string event = "event: error\ndata: " + ErrorJson(s) + "\n\n";
              sink.write(event.data(), event.size());
            }
            sink.done();
            return true;
          }
          StatusOr<std::string> json = ToJson(metadata);
          const std::string event =
              "data: " + (json.ok() ? *json : ErrorJson(ToGrpc(json.status()))) + "\n\n";
          // False (the client went away) ends the response; the releaser cancels the call.
          return sink.write(event.data(), event.size());
        },
        [this, call](bool) {
          if (!call->finished) {
            call->context.TryCancel();
            v1::JobMetadata ignored;
            while (call->reader->Read(&ignored)) {
            }
            call->reader->Finish();
            call->finished = true;
          }
          Forget(call.get());
        });
  }

  void Forget(WatchCall* call) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      watches.erase(call);
    }
    watches_changed.notify_all();
  }

  void ServeMetrics(const httplib::Request&, httplib::Response& res) {
    StatusOr<std::string> text = metrics_text();
    if (!text.ok()) return SetError(res, ToGrpc(text.status()));
    res.status = 200;
    res.set_content(std::move(text).value(), kMetricsContentType);
  }

  void Register() {
    for (const RouteSpec& route : kRoutes) route_regexes.emplace_back(route.regex);
    using google::longrunning::CancelOperationRequest;
    using google::longrunning::DeleteOperationRequest;
    using google::longrunning::GetOperationRequest;
    using google::longrunning::ListOperationsRequest;
    using google::longrunning::ListOperationsResponse;
    using google::protobuf::Empty;
    // One handler per kRoutes entry, in its order.
    const std::vector<httplib::Server::Handler> handlers = {
        [this](const httplib::Request& req, httplib::Response& res) {
          Unary<v1::SubmitSimulateRequest, Operation>(req, res, Binding::kBody,
                                                      [this](auto* c, const auto& r, auto* out) {
                                                        return jobs->SubmitSimulate(c, r, out);
                                                      });
        },
        [this](const httplib::Request& req, httplib::Response& res) {
          Unary<v1::SubmitSweepRequest, Operation>(
              req, res, Binding::kBody,
              [this](auto* c, const auto& r, auto* out) { return jobs->SubmitSweep(c, r, out); });
        },
        [this](const httplib::Request& req, httplib::Response& res) {
          Unary<v1::SubmitContinueRequest, Operation>(req, res, Binding::kBody,
                                                      [this](auto* c, const auto& r, auto* out) {
                                                        return jobs->SubmitContinue(c, r, out);
                                                      });
        },
        [this](const httplib::Request& req, httplib::Response& res) {
          Unary<v1::SubmitTraceRequest, Operation>(
              req, res, Binding::kBody,
              [this](auto* c, const auto& r, auto* out) { return jobs->SubmitTrace(c, r, out); });
        },
        [this](const httplib::Request& req, httplib::Response& res) {
          Unary<v1::SubmitOptimumRequest, Operation>(
              req, res, Binding::kBody,
              [this](auto* c, const auto& r, auto* out) { return jobs->SubmitOptimum(c, r, out); });
        },
        [this](const httplib::Request& req, httplib::Response& res) {
          Unary<v1::GetResultRequest, v1::GetResultResponse>(
              req, res, Binding::kQuery,
              [this](auto* c, const auto& r, auto* out) { return jobs->GetResult(c, r, out); });
        },
        [this](const httplib::Request& req, httplib::Response& res) {
          Unary<v1::QueryOptimumRequest, v1::QueryOptimumResponse>(
              req, res, Binding::kBody,
              [this](auto* c, const auto& r, auto* out) { return jobs->QueryOptimum(c, r, out); });
        },
        [this](const httplib::Request& req, httplib::Response& res) { Watch(req, res); },
        [this](const httplib::Request& req, httplib::Response& res) {
          Unary<ListOperationsRequest, ListOperationsResponse>(
              req, res, Binding::kQuery, [this](auto* c, const auto& r, auto* out) {
                return operations->ListOperations(c, r, out);
              });
        },
        [this](const httplib::Request& req, httplib::Response& res) {
          Unary<CancelOperationRequest, Empty>(req, res, Binding::kBody,
                                               [this](auto* c, const auto& r, auto* out) {
                                                 return operations->CancelOperation(c, r, out);
                                               });
        },
        [this](const httplib::Request& req, httplib::Response& res) {
          Unary<GetOperationRequest, Operation>(req, res, Binding::kQuery,
                                                [this](auto* c, const auto& r, auto* out) {
                                                  return operations->GetOperation(c, r, out);
                                                });
        },
        [this](const httplib::Request& req, httplib::Response& res) {
          Unary<DeleteOperationRequest, Empty>(req, res, Binding::kQuery,
                                               [this](auto* c, const auto& r, auto* out) {
                                                 return operations->DeleteOperation(c, r, out);
                                               });
        },
        [this](const httplib::Request& req, httplib::Response& res) { ServeMetrics(req, res); },
    };
    static_assert(std::size(kRoutes) == 13, "one handler per route");
    for (size_t i = 0; i < std::size(kRoutes); ++i) {
      const RouteSpec& route = kRoutes[i];
      // Each handler counts its answer (the error handler counts httplib's own answers).
      httplib::Server::Handler counted = [this, route, handler = handlers[i]](
                                             const httplib::Request& req, httplib::Response& res) {
        handler(req, res);
        metrics->CountHttpRequest(req.method, route.label, res.status);
      };
      const std::string method = route.method;
      if (method == "GET") {
        http.Get(route.regex, counted);
      } else if (method == "POST") {
        http.Post(route.regex, counted);
      } else {
        http.Delete(route.regex, counted);
      }
    }
    // Before any body is read: httplib 0.11 caps a body by its Content-Length only; it reads a
    // chunked body, or one with no length at all, to its end whatever its size. A request with
    // neither header has no body (RFC 9112 6.3; curl -X POST sends that): say so to httplib,
    // which would otherwise wait for the connection to close. Chunked bodies are refused (411).
    http.set_pre_routing_handler([this](const httplib::Request& req, httplib::Response& res) {
      const bool has_body_method =
          req.method == "POST" || req.method == "PUT" || req.method == "PATCH";
      if (!has_body_method || req.has_header("Content-Length")) {
        return httplib::Server::HandlerResponse::Unhandled;
      }
      if (!req.has_header("Transfer-Encoding")) {
        // The request object is httplib's own, non-const one; the handler only sees it const.
        const_cast<httplib::Request&>(req).set_header("Content-Length", "0");
        return httplib::Server::HandlerResponse::Unhandled;
      }
      SetError(res,
               grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                            "Content-Length required: chunked bodies are not accepted (bodies are "
                            "limited to " +
                                std::to_string(options.max_body_bytes) + " bytes)"),
               411);
      res.set_header("Connection", "close");
      metrics->CountHttpRequest(req.method, RouteLabel(req.method, req.path), res.status);
      return httplib::Server::HandlerResponse::Handled;
    });
    // Answers httplib makes itself (no route, body too large, unparsable request) get a JSON
    // body too. Called for every status >= 400; those with a body are the handlers' own.
    http.set_error_handler(httplib::Server::HandlerWithResponse(
        [this](const httplib::Request& req, httplib::Response& res) {
          if (!res.body.empty()) return httplib::Server::HandlerResponse::Unhandled;
          grpc::Status status;
          // httplib answers 404 (400 for PUT, PATCH, ...) when no handler matched.
          const bool unrouted = (res.status == 404 || res.status == 400) &&
                                std::string(RouteLabel(req.method, req.path)) == "other";
          if (unrouted && PathKnown(req.path)) {
            res.status = 405;
            status = grpc::Status(grpc::StatusCode::UNIMPLEMENTED,
                                  "method " + req.method + " is not served on " + req.path);
          } else if (unrouted) {
            res.status = 404;
            status = grpc::Status(grpc::StatusCode::NOT_FOUND,
                                  "no route for " + req.method + " " + req.path);
          } else if (res.status == 413) {
            status = grpc::Status(grpc::StatusCode::RESOURCE_EXHAUSTED,
                                  "request body larger than the limit of " +
                                      std::to_string(options.max_body_bytes) + " bytes");
          } else {
            status = grpc::Status(
                res.status >= 500 ? grpc::StatusCode::INTERNAL : grpc::StatusCode::INVALID_ARGUMENT,
                "HTTP " + std::to_string(res.status) + ": malformed request");
          }
          res.set_content(ErrorJson(status), kJson);
          metrics->CountHttpRequest(req.method, RouteLabel(req.method, req.path), res.status);
          return httplib::Server::HandlerResponse::Handled;
        }));
    http.set_exception_handler(
        [this](const httplib::Request& req, httplib::Response& res, std::exception_ptr e) {
          std::string what = "unknown exception";
          try {
            if (e) std::rethrow_exception(e);
          } catch (const std::exception& ex) {
            what = ex.what();
          } catch (...) {
          }
          spdlog::error("REST {} {}: {}", req.method, req.path, what);
          SetError(res, grpc::Status(grpc::StatusCode::INTERNAL, "internal error: " + what));
          metrics->CountHttpRequest(req.method, RouteLabel(req.method, req.path), res.status);
        });
  }
};

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
  impl->Register();

  httplib::Server& http = impl->http;
  const int threads = options.threads;
  http.new_task_queue = [threads] { return new httplib::ThreadPool(static_cast<size_t>(threads)); };
  http.set_payload_max_length(static_cast<size_t>(options.max_body_bytes));
  const std::chrono::milliseconds read_timeout(options.read_timeout_ms);
  http.set_read_timeout(read_timeout);
  http.set_keep_alive_timeout(std::max<time_t>(1, options.read_timeout_ms / 1000));

  impl->port = options.port == 0
                   ? http.bind_to_any_port(options.host)
                   : (http.bind_to_port(options.host, options.port) ? options.port : -1);
  if (impl->port <= 0) {
    return Status(StatusCode::kUnavailable, "cannot listen on " + options.host + ":" +
                                                std::to_string(options.port) + " (HTTP)");
  }
  Impl* raw = impl.get();
  impl->listener = std::thread([raw] { raw->http.listen_after_bind(); });
  // httplib's stop() does nothing until the listener runs: wait for it, so that a Stop right
  // after Start cannot leave the listener running (it sets the flag at once; 5 s is a bound).
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(5);
  while (!http.is_running() && std::chrono::steady_clock::now() < give_up) {
    std::this_thread::sleep_for(std::chrono::milliseconds(1));
  }
  return std::unique_ptr<RestGateway>(new RestGateway(std::move(impl)));
}

int RestGateway::port() const { return impl_->port; }

void RestGateway::Stop() {
  {
    std::unique_lock<std::mutex> lock(impl_->mutex);
    if (impl_->stopped) return;
    impl_->stopped = true;
    // Streams whose Watch ended write their last event and close; httplib's stop() would cut
    // them short (it ends a response between two writes).
    impl_->watches_changed.wait_for(lock, std::chrono::milliseconds(impl_->options.stop_grace_ms),
                                    [this] { return impl_->watches.empty(); });
    // Streams still waiting for their job's next change end now.
    for (Impl::WatchCall* call : impl_->watches) call->context.TryCancel();
  }
  impl_->http.stop();
  if (impl_->listener.joinable()) impl_->listener.join();
}

}  // namespace drillbif::server
