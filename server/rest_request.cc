#include "server/rest_request.h"

#include <google/protobuf/empty.pb.h>
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>

#include "drillbif/v1/service.pb.h"
#include "google/longrunning/operations.pb.h"

namespace drillbif::server {
namespace {

using google::protobuf::Message;
using google::protobuf::util::JsonParseOptions;
using google::protobuf::util::JsonPrintOptions;

// The default instance of `T` as a route's prototype.
template <typename T>
const Message* Prototype() {
  return &T::default_instance();
}

// Whether `path` matches the template `label`; *name gets the variable's value.
bool MatchTemplate(std::string_view label, std::string_view path, std::string* name) {
  const size_t open = label.find('{');
  if (open == std::string_view::npos) return path == label;
  const size_t close = label.find('}', open);
  const std::string_view prefix = label.substr(0, open);
  const std::string_view suffix = label.substr(close + 1);
  const std::string_view variable = label.substr(open + 1, close - open - 1);
  const std::string_view pattern = variable.substr(variable.find('=') + 1);
  if (path.size() < prefix.size() + suffix.size() || !path.starts_with(prefix) ||
      !path.ends_with(suffix)) {
    return false;
  }
  const std::string_view value =
      path.substr(prefix.size(), path.size() - prefix.size() - suffix.size());
  bool match;
  if (pattern.ends_with("/**")) {
    const std::string_view base = pattern.substr(0, pattern.size() - 2);
    match = value.size() > base.size() && value.starts_with(base);
  } else if (pattern.ends_with("/*")) {
    const std::string_view base = pattern.substr(0, pattern.size() - 1);
    match = value.size() > base.size() && value.starts_with(base) &&
            value.find('/', base.size()) == std::string_view::npos;
  } else {
    match = value == pattern;
  }
  if (match) *name = std::string(value);
  return match;
}

// Sets the field `name` (a string) of `message` to the path variable, refusing a different value
// given in the body or the query.
Status BindName(const std::string& name, Message* message) {
  const auto* field = message->GetDescriptor()->FindFieldByName("name");
  if (field == nullptr) {
    return Internal(message->GetTypeName() + " has no field 'name' to bind the path to");
  }
  const auto* reflection = message->GetReflection();
  const std::string given = reflection->GetString(*message, field);
  if (!given.empty() && given != name) {
    return InvalidArgument("name: '" + Sanitize(given) + "' differs from the path's '" +
                           Sanitize(name) + "'");
  }
  reflection->SetString(message, field, name);
  return Status::Ok();
}

// The query parameters as a JSON object of strings, parsed into `message` by the JSON mapping:
// names are the fields' (proto or lowerCamelCase), numbers are accepted as strings, and an
// unknown parameter is refused like an unknown JSON field. (Names and values are valid UTF-8:
// ParseRequestTarget checked them.)
Status FromQuery(const std::vector<std::pair<std::string, std::string>>& params, Message* message) {
  google::protobuf::Struct object;
  for (const auto& [key, value] : params) {
    auto* fields = object.mutable_fields();
    if (fields->count(key) != 0) {
      return InvalidArgument("query parameter '" + Sanitize(key) + "' is given more than once");
    }
    (*fields)[key].set_string_value(value);
  }
  DRILLBIF_ASSIGN_OR_RETURN(const std::string json, ToJson(object));
  return FromJson(json, message, "query");
}

}  // namespace

const RouteSpec kRoutes[kRouteCount] = {
    {"POST", "/v1/jobs:simulate", Binding::kBody, Prototype<v1::SubmitSimulateRequest>},
    {"POST", "/v1/jobs:sweep", Binding::kBody, Prototype<v1::SubmitSweepRequest>},
    {"POST", "/v1/jobs:continue", Binding::kBody, Prototype<v1::SubmitContinueRequest>},
    {"POST", "/v1/jobs:trace", Binding::kBody, Prototype<v1::SubmitTraceRequest>},
    {"POST", "/v1/jobs:optimum", Binding::kBody, Prototype<v1::SubmitOptimumRequest>},
    {"POST", "/v1/jobs:optimum-map", Binding::kBody, Prototype<v1::SubmitOptimumMapRequest>},
    {"GET", "/v1/{name=operations/*}:result", Binding::kQuery, Prototype<v1::GetResultRequest>},
    {"POST", "/v1/optimum:query", Binding::kBody, Prototype<v1::QueryOptimumRequest>},
    {"GET", "/v1/{name=operations/*}:watch", Binding::kQuery, Prototype<v1::WatchRequest>},
    {"GET", "/v1/{name=operations}", Binding::kQuery,
     Prototype<google::longrunning::ListOperationsRequest>},
    {"POST", "/v1/{name=operations/**}:cancel", Binding::kBody,
     Prototype<google::longrunning::CancelOperationRequest>},
    {"GET", "/v1/{name=operations/**}", Binding::kQuery,
     Prototype<google::longrunning::GetOperationRequest>},
    {"DELETE", "/v1/{name=operations/**}", Binding::kQuery,
     Prototype<google::longrunning::DeleteOperationRequest>},
    {"GET", "/metrics", Binding::kQuery, nullptr},
    {"GET", "/healthz", Binding::kQuery, nullptr},
    {"GET", "/openapi.json", Binding::kQuery, nullptr},
};

int MatchRoute(std::string_view method, std::string_view path, std::string* name,
               bool* path_known) {
  *path_known = false;
  for (int i = 0; i < kRouteCount; ++i) {
    std::string value;
    if (!MatchTemplate(kRoutes[i].label, path, &value)) continue;
    if (method == kRoutes[i].method) {
      *name = std::move(value);
      return i;
    }
    *path_known = true;
  }
  return -1;
}

std::vector<int> RoutesOf(std::string_view path) {
  std::vector<int> routes;
  for (int i = 0; i < kRouteCount; ++i) {
    std::string value;
    if (MatchTemplate(kRoutes[i].label, path, &value)) routes.push_back(i);
  }
  return routes;
}

StatusOr<int> FindRoute(std::string_view method, std::string_view path, std::string* name) {
  bool path_known = false;
  const int route = MatchRoute(method, path, name, &path_known);
  if (route >= 0) return route;
  if (path_known) {
    return Status(StatusCode::kUnimplemented,
                  "method " + Sanitize(method) + " is not served on " + Sanitize(path));
  }
  return NotFound("no route for " + Sanitize(method) + " " + Sanitize(path));
}

StatusOr<std::string> ToJson(const Message& message) {
  std::string out;
  JsonPrintOptions options;
  auto status = google::protobuf::util::MessageToJsonString(message, &out, options);
  if (!status.ok()) {
    return Internal("cannot print " + message.GetTypeName() +
                    " as JSON: " + std::string(status.message()));
  }
  return out;
}

// Strings parsed are valid UTF-8: the text is checked first, and protobuf's parser refuses \u
// escapes of lone surrogates ("Missing low surrogate", "Invalid unicode code point").
Status FromJson(std::string_view json, Message* message, const char* what) {
  if (const size_t bad = FindInvalidUtf8(json); bad != std::string_view::npos) {
    return InvalidArgument(std::string(what) + ": not valid UTF-8 (at byte " + std::to_string(bad) +
                           ")");
  }
  JsonParseOptions options;
  options.ignore_unknown_fields = false;
  auto status = google::protobuf::util::JsonStringToMessage(
      google::protobuf::StringPiece(json.data(), json.size()), message, options);
  if (!status.ok()) {
    return InvalidArgument(std::string(what) + ": not a valid " + message->GetTypeName() +
                           " in JSON: " + ValidUtf8(std::string(status.message())));
  }
  return Status::Ok();
}

Status BuildRequest(int route, const RequestTarget& target, std::string_view body,
                    const std::string& name, Message* request) {
  const RouteSpec& spec = kRoutes[route];
  if (spec.prototype == nullptr || spec.prototype()->GetDescriptor() != request->GetDescriptor()) {
    return Internal(std::string("route ") + spec.label + " does not build a " +
                    request->GetTypeName());
  }
  if (spec.binding == Binding::kBody) {
    if (target.has_query) {
      return InvalidArgument("query parameters: this route takes every field from the body");
    }
    // The body is JSON whatever the Content-Type says (curl -d sends a form's type).
    const bool blank = std::all_of(body.begin(), body.end(), [](char c) {
      return c == ' ' || c == '\n' || c == '\r' || c == '\t';
    });
    DRILLBIF_RETURN_IF_ERROR(FromJson(blank ? std::string_view("{}") : body, request, "body"));
  } else {
    DRILLBIF_RETURN_IF_ERROR(FromQuery(target.query, request));
  }
  if (!name.empty()) return BindName(name, request);
  return Status::Ok();
}

StatusOr<double> ParseServerTimeout(const std::string& text) {
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  // The whole value must be the number (a NUL byte inside would end strtod's string early).
  if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(value) || value <= 0) {
    return InvalidArgument("header X-Server-Timeout: expected seconds > 0, got '" + Sanitize(text) +
                           "'");
  }
  return std::min(value, kMaxServerTimeoutSeconds);
}

StatusOr<DecodedRestRequest> DecodeRestRequest(std::string_view method, const RequestTarget& target,
                                               std::string_view body) {
  DecodedRestRequest decoded;
  DRILLBIF_ASSIGN_OR_RETURN(decoded.route, FindRoute(method, target.path, &decoded.name));
  const RouteSpec& spec = kRoutes[decoded.route];
  if (spec.prototype == nullptr) return decoded;
  decoded.request.reset(spec.prototype()->New());
  DRILLBIF_RETURN_IF_ERROR(
      BuildRequest(decoded.route, target, body, decoded.name, decoded.request.get()));
  return decoded;
}

}  // namespace drillbif::server
