#include "server/cors.h"

#include <grpcpp/grpcpp.h>

#include <algorithm>

#include "server/http_text.h"
#include "server/rest_gateway.h"

namespace drillbif::server {
namespace {

// Whether `host` is a lower-case DNS name or IPv4 address (letters, digits, '-', '.'), or a
// bracketed IPv6 address (hex digits, ':' and '.').
bool ValidHost(const std::string& host) {
  if (host.empty() || host.size() > 253) return false;
  if (host.front() == '[') {
    return host.size() > 2 && host.back() == ']' &&
           std::all_of(host.begin() + 1, host.end() - 1, [](char c) {
             return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f') || c == ':' || c == '.';
           });
  }
  return std::all_of(host.begin(), host.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '-' || c == '.';
  });
}

Status CheckOrigin(const std::string& origin) {
  const auto bad = [&origin](const std::string& why) {
    return InvalidArgument("--cors-origins: '" + Sanitize(origin) + "' " + why);
  };
  const size_t scheme_end = origin.find("://");
  if (scheme_end == std::string::npos) return bad("is not an origin scheme://host[:port]");
  const std::string scheme = origin.substr(0, scheme_end);
  if (scheme != "http" && scheme != "https") return bad("must start with http:// or https://");
  std::string authority = origin.substr(scheme_end + 3);
  if (authority.find_first_of("/?#") != std::string::npos) {
    return bad("must have no path (a browser's Origin is scheme://host[:port], without '/')");
  }
  if (authority.find('@') != std::string::npos) return bad("must have no user name");
  // The port: after the last ':' unless that is inside an IPv6 address's brackets.
  const size_t colon = authority.rfind(':');
  if (colon != std::string::npos && authority.find(']', colon) == std::string::npos) {
    const std::string port = authority.substr(colon + 1);
    const bool digits =
        !port.empty() && port.size() <= 5 && port.front() != '0' &&
        std::all_of(port.begin(), port.end(), [](char c) { return c >= '0' && c <= '9'; });
    if (!digits || std::stoi(port) > 65535) return bad("has no valid port (1 to 65535)");
    authority.resize(colon);
  }
  if (!ValidHost(authority)) {
    return bad(
        "has no valid host (lower case, as browsers send it: letters, digits, '-', '.', "
        "or [IPv6])");
  }
  return Status::Ok();
}

}  // namespace

Status ValidateCorsOrigins(const std::vector<std::string>& origins) {
  for (const std::string& origin : origins) {
    if (origin == "*") {
      if (origins.size() > 1) {
        return InvalidArgument("--cors-origins: '*' (any origin) must be the only value");
      }
      continue;
    }
    DRILLBIF_RETURN_IF_ERROR(CheckOrigin(origin));
  }
  return Status::Ok();
}

std::string CorsAllowOrigin(const std::vector<std::string>& allowed, const std::string* origin) {
  if (allowed.empty() || origin == nullptr) return "";
  if (allowed.size() == 1 && allowed.front() == "*") return "*";
  return std::find(allowed.begin(), allowed.end(), *origin) != allowed.end() ? *origin : "";
}

void AddCorsHeaders(const std::vector<std::string>& allowed, const std::string* origin,
                    HttpResponse* response) {
  if (allowed.empty()) return;
  // Caches must keep answers to different origins apart (or answers with and without Origin).
  response->headers.emplace_back("Vary", "Origin");
  const bool has_allow =
      std::any_of(response->headers.begin(), response->headers.end(),
                  [](const auto& header) { return header.first == "Access-Control-Allow-Origin"; });
  if (has_allow) return;
  const std::string allow = CorsAllowOrigin(allowed, origin);
  if (allow.empty()) return;
  response->headers.emplace_back("Access-Control-Allow-Origin", allow);
  response->headers.emplace_back("Access-Control-Expose-Headers", kCorsExposedHeaders);
}

HttpResponse CorsPreflight(const std::vector<std::string>& allowed, const std::string& origin,
                           const std::string& methods) {
  HttpResponse response;
  const std::string allow = CorsAllowOrigin(allowed, &origin);
  if (allow.empty()) {
    response.status = 403;
    response.content_type = "application/json";
    response.body =
        ErrorJson(grpc::Status(grpc::StatusCode::PERMISSION_DENIED,
                               "CORS: origin '" + Sanitize(origin) + "' is not allowed"));
    return response;
  }
  response.status = 204;
  response.headers = {
      {"Access-Control-Allow-Origin", allow},
      {"Access-Control-Allow-Methods", methods},
      {"Access-Control-Allow-Headers", kCorsAllowedHeaders},
      {"Access-Control-Max-Age", std::to_string(kCorsMaxAgeSeconds)},
  };
  return response;
}

}  // namespace drillbif::server
