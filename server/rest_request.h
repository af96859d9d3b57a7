// The pure half of the REST gateway (server/rest_gateway.h): its routes, and the decoding of a
// request (method, target, headers, body) into the request message of its route, with the
// gateway's errors. No I/O, no gRPC: the gateway calls these on its HTTP threads, and the fuzz
// targets (fuzz/) call them directly.
//
//   StatusOr<RequestTarget> target = ParseRequestTarget("/v1/operations/abc:result?page_size=5");
//   StatusOr<DecodedRestRequest> decoded = DecodeRestRequest("GET", *target, "");
//   // decoded->request is a drillbif.v1.GetResultRequest {name: "operations/abc", page_size: 5}
#ifndef DRILLBIF_SERVER_REST_REQUEST_H_
#define DRILLBIF_SERVER_REST_REQUEST_H_

#include <google/protobuf/message.h>

#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "drillbif/common/status.h"
#include "server/http_text.h"

namespace drillbif::server {

// What binds the fields of a route's request message (google.api.http): the path's {name=...}
// variable, and either the body ("*": every other field) or the query parameters (GET, DELETE).
enum class Binding { kBody, kQuery };

// A route: its method, its path template as written in the annotation (also the metrics label),
// how its request is bound and the request message it builds. A template has at most one
// variable, {name=operations} (that text), {name=operations/*} (one non-empty segment after
// "operations/") or {name=operations/**} (anything non-empty after it, '/' included).
struct RouteSpec {
  const char* method;
  const char* label;
  Binding binding;
  // The default instance of the route's request message; null for a route that builds none
  // (/metrics, /healthz).
  const google::protobuf::Message* (*prototype)();
};

// Every route, in matching order: a path matched by two templates goes to the first (so the
// ":result", ":watch" and ":cancel" routes precede the catch-all operations/** ones). Indexed by
// RouteIndex.
enum RouteIndex {
  kSubmitSimulate,
  kSubmitSweep,
  kSubmitContinue,
  kSubmitTrace,
  kSubmitOptimum,
  kSubmitOptimumMap,
  kGetResult,
  kQueryOptimum,
  kWatch,
  kListOperations,
  kCancelOperation,
  kGetOperation,
  kDeleteOperation,
  kMetrics,
  kHealth,
  kOpenApi,
  kRouteCount,
};
extern const RouteSpec kRoutes[kRouteCount];

// The first route serving `method` `path` (-1 if none); *name gets its path variable (empty for
// a route without one), and `*path_known` tells whether some route serves the path with another
// method (405 rather than 404).
int MatchRoute(std::string_view method, std::string_view path, std::string* name, bool* path_known);

// Every route whose template matches `path`, whatever its method, in matching order.
std::vector<int> RoutesOf(std::string_view path);

// MatchRoute with the gateway's errors: NOT_FOUND "no route for <method> <path>", or
// UNIMPLEMENTED "method <method> is not served on <path>" (answered 405) when other methods serve
// the path. Method and path are echoed sanitized.
StatusOr<int> FindRoute(std::string_view method, std::string_view path, std::string* name);

// The JSON text of a message (protobuf's JSON mapping, one line, lowerCamelCase names, fields
// at their default value left out). INTERNAL when the message cannot be printed.
StatusOr<std::string> ToJson(const google::protobuf::Message& message);

// Parses JSON into `message`, refusing unknown fields (a misspelt field must not be silently
// ignored: the request would run with a default instead) and text that is not UTF-8 (RFC 8259
// 8.1). INVALID_ARGUMENT starting with `what` ("body", "query") otherwise.
Status FromJson(std::string_view json, google::protobuf::Message* message, const char* what);

// Builds the request message of route `route` (a message of its prototype's type) from the
// path's `name` (empty: the route has no variable), the body or the query parameters of
// `target`. INVALID_ARGUMENT naming the part at fault; INTERNAL when `request` is not of the
// route's type.
Status BuildRequest(int route, const RequestTarget& target, std::string_view body,
                    const std::string& name, google::protobuf::Message* request);

// The seconds asked for by an "X-Server-Timeout" header: its whole value must be a finite
// number > 0; capped at kMaxServerTimeoutSeconds. INVALID_ARGUMENT naming the header otherwise.
StatusOr<double> ParseServerTimeout(const std::string& text);

// Longest deadline a request may ask for with X-Server-Timeout (the services' longest wait).
inline constexpr double kMaxServerTimeoutSeconds = 600;

// A request decoded as the gateway decodes it before calling a service.
struct DecodedRestRequest {
  int route = -1;    // RouteIndex
  std::string name;  // the path variable; empty for a route without one
  // The route's request message, built; null for /metrics and /healthz.
  std::unique_ptr<google::protobuf::Message> request;
};

// Routes `method` `target` and builds its request from `body` (FindRoute, then BuildRequest).
// Errors: FindRoute's, BuildRequest's.
StatusOr<DecodedRestRequest> DecodeRestRequest(std::string_view method, const RequestTarget& target,
                                               std::string_view body);

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_REST_REQUEST_H_
