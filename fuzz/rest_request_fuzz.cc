// libFuzzer target: the REST gateway's decoding of a request (server/rest_request.h,
// server/http_text.h), as the gateway runs it before calling a service: the request target split
// and percent-decoded, the X-Server-Timeout header, the route matched, the body or the query
// bound into the route's request message.
//
// Input: "<method>\n<request target>\n<X-Server-Timeout value>\n<body>"; the body is the rest
// of the input (newlines included). An empty timeout line is a request without the header. The
// method and the target end at a NUL byte: libmicrohttpd hands them over as C strings.
//
// Invariants beyond "no crash, no sanitizer report":
// - a refusal is one of the gateway's client errors (INVALID_ARGUMENT, NOT_FOUND, UNIMPLEMENTED),
//   never INTERNAL, with a non-empty message that is valid UTF-8 (it is echoed in JSON);
// - a decoded target has valid UTF-8 without NUL in its path and query;
// - an accepted timeout is in (0, kMaxServerTimeoutSeconds];
// - a decoded request is of its route's type, carries the path's name, and re-encodes: binary
//   and JSON round trips give the same message, and a body route decodes its own JSON to it.
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>
#include <string_view>

#include "fuzz/fuzz_checks.h"
#include "server/http_text.h"
#include "server/rest_request.h"

namespace drillbif::fuzz {
namespace {

using server::DecodedRestRequest;
using server::RequestTarget;

// The next line of `input` (without its '\n'), consumed; the whole rest when there is no '\n'.
std::string_view NextLine(std::string_view* input) {
  const size_t end = input->find('\n');
  const std::string_view line = input->substr(0, end);
  input->remove_prefix(end == std::string_view::npos ? input->size() : end + 1);
  return line;
}

// `text` up to its first NUL byte, as a C string would hold it.
std::string CString(std::string_view text) { return std::string(text.substr(0, text.find('\0'))); }

bool ValidText(std::string_view text) {
  return server::FindInvalidUtf8(text) == std::string_view::npos &&
         text.find('\0') == std::string_view::npos;
}

// A refusal of the decoding: a client error with a message to show.
void CheckRefusal(const Status& status) {
  const StatusCode code = status.code();
  DRILLBIF_FUZZ_CHECK(code == StatusCode::kInvalidArgument || code == StatusCode::kNotFound ||
                          code == StatusCode::kUnimplemented,
                      status.ToString());
  DRILLBIF_FUZZ_CHECK(!status.message().empty(), status.ToString());
  DRILLBIF_FUZZ_CHECK(server::FindInvalidUtf8(status.message()) == std::string_view::npos,
                      status.ToString());
}

void CheckTarget(const RequestTarget& target) {
  DRILLBIF_FUZZ_CHECK(ValidText(target.path), target.path);
  for (const auto& [name, value] : target.query) {
    DRILLBIF_FUZZ_CHECK(ValidText(name) && ValidText(value), name + "=" + value);
  }
  DRILLBIF_FUZZ_CHECK(target.has_query || target.query.empty(), "parameters without a '?'");
}

void CheckDecoded(std::string_view method, const RequestTarget& target,
                  const DecodedRestRequest& decoded) {
  DRILLBIF_FUZZ_CHECK(decoded.route >= 0 && decoded.route < server::kRouteCount,
                      std::to_string(decoded.route));
  const server::RouteSpec& spec = server::kRoutes[decoded.route];
  DRILLBIF_FUZZ_CHECK(method == spec.method, std::string(method) + " routed to " + spec.label);
  const bool has_variable = std::string_view(spec.label).find('{') != std::string_view::npos;
  DRILLBIF_FUZZ_CHECK(has_variable != decoded.name.empty(), spec.label);
  if (spec.prototype == nullptr) {
    DRILLBIF_FUZZ_CHECK(decoded.request == nullptr, spec.label);
    return;
  }
  const google::protobuf::Message& request = *decoded.request;
  DRILLBIF_FUZZ_CHECK(request.GetDescriptor() == spec.prototype()->GetDescriptor(),
                      request.GetTypeName() + " built for " + spec.label);
  if (has_variable) {
    const auto* field = request.GetDescriptor()->FindFieldByName("name");
    DRILLBIF_FUZZ_CHECK(
        field != nullptr && request.GetReflection()->GetString(request, field) == decoded.name,
        "name not bound: " + request.ShortDebugString());
  }

  // Binary round trip: what the in-process gRPC call sends and the service parses.
  std::string bytes;
  DRILLBIF_FUZZ_CHECK(request.SerializeToString(&bytes), request.ShortDebugString());
  std::unique_ptr<google::protobuf::Message> parsed(request.New());
  DRILLBIF_FUZZ_CHECK(parsed->ParseFromString(bytes), request.ShortDebugString());
  DRILLBIF_FUZZ_CHECK(SameMessage(request, *parsed), request.ShortDebugString());

  // JSON round trip: what a client reading the API back would send again.
  StatusOr<std::string> json = server::ToJson(request);
  DRILLBIF_FUZZ_CHECK(json.ok(), json.status().ToString());
  std::unique_ptr<google::protobuf::Message> from_json(request.New());
  const Status reparsed = server::FromJson(*json, from_json.get(), "json");
  DRILLBIF_FUZZ_CHECK(reparsed.ok(), reparsed.ToString() + " for " + *json);
  DRILLBIF_FUZZ_CHECK(SameMessage(request, *from_json), *json);

  // A body route given its own JSON (and no query) decodes to the same request.
  if (spec.binding == server::Binding::kBody) {
    RequestTarget plain;
    plain.path = target.path;
    StatusOr<DecodedRestRequest> again = server::DecodeRestRequest(method, plain, *json);
    DRILLBIF_FUZZ_CHECK(again.ok(), again.status().ToString() + " for " + *json);
    DRILLBIF_FUZZ_CHECK(again->route == decoded.route, *json);
    DRILLBIF_FUZZ_CHECK(SameMessage(request, *again->request), *json);
  }
}

}  // namespace
}  // namespace drillbif::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace drillbif;  // NOLINT: the entry point is outside the namespace
  std::string_view input(reinterpret_cast<const char*>(data), size);
  const std::string method = fuzz::CString(fuzz::NextLine(&input));
  const std::string raw_target = fuzz::CString(fuzz::NextLine(&input));
  const std::string timeout(fuzz::NextLine(&input));
  const std::string_view body = input;

  if (!timeout.empty()) {
    StatusOr<double> seconds = server::ParseServerTimeout(timeout);
    if (seconds.ok()) {
      DRILLBIF_FUZZ_CHECK(
          std::isfinite(*seconds) && *seconds > 0 && *seconds <= server::kMaxServerTimeoutSeconds,
          std::to_string(*seconds));
    } else {
      fuzz::CheckRefusal(seconds.status());
      DRILLBIF_FUZZ_CHECK(seconds.status().message().find("X-Server-Timeout") != std::string::npos,
                          seconds.status().ToString());
    }
  }

  StatusOr<server::RequestTarget> target = server::ParseRequestTarget(raw_target);
  if (!target.ok()) {
    fuzz::CheckRefusal(target.status());
    DRILLBIF_FUZZ_CHECK(target.status().code() == StatusCode::kInvalidArgument,
                        target.status().ToString());
    return 0;
  }
  fuzz::CheckTarget(*target);

  StatusOr<server::DecodedRestRequest> decoded = server::DecodeRestRequest(method, *target, body);
  if (!decoded.ok()) {
    fuzz::CheckRefusal(decoded.status());
    return 0;
  }
  fuzz::CheckDecoded(method, *target, *decoded);
  return 0;
}
