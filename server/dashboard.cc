#include "server/dashboard.h"

#include <cstdint>
#include <cstdio>
#include <utility>
#include <vector>

#include "server/dashboard_files.h"
#include "server/http_text.h"
#include "server/rest_gateway.h"

namespace drillbif::server {
namespace {

// FNV-1a (64 bits) of a file's bytes, as its ETag: the bytes change only with the binary, so
// any stable hash tells versions apart; no need for a cryptographic one.
std::string ETagOf(const DashboardFile& file) {
  uint64_t hash = 14695981039346656037ull;
  for (std::size_t i = 0; i < file.size; ++i) {
    hash ^= file.data[i];
    hash *= 1099511628211ull;
  }
  char text[24];
  std::snprintf(text, sizeof(text), "\"%016llx\"", static_cast<unsigned long long>(hash));
  return text;
}

// The ETags, computed once (a few hundred kilobytes in all).
const std::vector<std::string>& ETags() {
  static const std::vector<std::string> tags = [] {
    std::vector<std::string> out;
    for (int i = 0; i < kDashboardFileCount; ++i) out.push_back(ETagOf(kDashboardFiles[i]));
    return out;
  }();
  return tags;
}

// Headers of every answer, errors included.
void AddSecurityHeaders(HttpResponse* response) {
  response->headers.emplace_back("Content-Security-Policy", kDashboardCsp);
  response->headers.emplace_back("X-Content-Type-Options", "nosniff");
  response->headers.emplace_back("Referrer-Policy", "no-referrer");
}

HttpResponse Error(int http_status, grpc::StatusCode code, const std::string& message) {
  HttpResponse response;
  response.status = http_status;
  response.content_type = "application/json";
  response.body = ErrorJson(grpc::Status(code, message));
  AddSecurityHeaders(&response);
  return response;
}

}  // namespace

std::string DashboardContentType(std::string_view path) {
  static constexpr std::pair<const char*, const char*> kTypes[] = {
      {".html", "text/html; charset=utf-8"},
      {".js", "text/javascript; charset=utf-8"},
      {".css", "text/css; charset=utf-8"},
      {".svg", "image/svg+xml"},
      {".png", "image/png"},
      {".json", "application/json"},
  };
  for (const auto& [extension, type] : kTypes) {
    if (path.ends_with(extension)) return type;
  }
  return "application/octet-stream";
}

std::optional<HttpResponse> ServeDashboard(std::string_view method, std::string_view path,
                                           const std::string* if_none_match) {
  if (path.starts_with("/v1/") || path == "/v1") return std::nullopt;
  const std::string_view file_path = path == "/" ? std::string_view("/index.html") : path;
  int found = -1;
  for (int i = 0; i < kDashboardFileCount; ++i) {
    if (file_path == kDashboardFiles[i].path) found = i;
  }
  if (found < 0) {
    return Error(404, grpc::StatusCode::NOT_FOUND, "no file " + Sanitize(std::string(path)));
  }
  if (method != "GET" && method != "HEAD") {
    HttpResponse response = Error(405, grpc::StatusCode::UNIMPLEMENTED,
                                  "method " + Sanitize(std::string(method)) + " is not served on " +
                                      Sanitize(std::string(path)));
    response.headers.emplace_back("Allow", "GET, HEAD");
    return response;
  }
  const DashboardFile& file = kDashboardFiles[found];
  const std::string& etag = ETags()[found];
  HttpResponse response;
  // A conditional request for the version the browser has: 304, no body (RFC 9110 13.1.2;
  // a list of tags or "*" is matched too).
  const bool unchanged = if_none_match != nullptr &&
                         (*if_none_match == "*" || if_none_match->find(etag) != std::string::npos);
  response.status = unchanged ? 304 : 200;
  response.content_type = DashboardContentType(file.path);
  if (!unchanged) response.body.assign(reinterpret_cast<const char*>(file.data), file.size);
  response.headers.emplace_back("ETag", etag);
  // Revalidated at each load (a 304 costs a round trip, not the bytes): a new server binary
  // must not leave an old page in the browser's cache.
  response.headers.emplace_back("Cache-Control", "no-cache");
  response.headers.emplace_back("X-Frame-Options", "DENY");
  AddSecurityHeaders(&response);
  return response;
}

}  // namespace drillbif::server
