// CORS (Cross-Origin Resource Sharing, the Fetch standard) for the REST gateway: which browser
// origins may call the API (RestOptions::cors_origins, the --cors-origins flag), the headers an
// answer to an allowed origin carries, and the answer to a preflight (OPTIONS) request.
//
// An allowed origin is exact ("https://dash.example.com", "http://127.0.0.1:8080": scheme, host,
// port as a browser sends them in the Origin header), or "*": any origin. The gateway never sets
// Access-Control-Allow-Credentials, so browsers send no cookies or HTTP authentication of their
// own; the bearer token goes in the Authorization header, which a preflight allows explicitly
// (that works with "*" too). With no origin configured no CORS header is ever sent.
#ifndef DRILLBIF_SERVER_CORS_H_
#define DRILLBIF_SERVER_CORS_H_

#include <string>
#include <vector>

#include "drillbif/common/status.h"
#include "server/http_server.h"

namespace drillbif::server {

// How long a browser may cache a preflight's answer, in seconds (Access-Control-Max-Age).
// 600: Chromium's cap; a changed --cors-origins reaches browsers within 10 minutes.
inline constexpr int kCorsMaxAgeSeconds = 600;

// The request headers a preflight allows (lower case): the bearer token, the JSON body's type,
// and the gateway's per-request deadline.
inline constexpr char kCorsAllowedHeaders[] = "authorization, content-type, x-server-timeout";

// The answer headers a script may read besides the CORS-safelisted ones.
inline constexpr char kCorsExposedHeaders[] = "Retry-After, WWW-Authenticate";

// INVALID_ARGUMENT naming the flag (--cors-origins) and the value at fault unless every entry is
// "*" alone or an origin http[s]://host[:port] in lower case (host: letters, digits, '-' and
// '.', or a bracketed IPv6 address; port 1 to 65535; no path, not even "/").
Status ValidateCorsOrigins(const std::vector<std::string>& origins);

// The Access-Control-Allow-Origin value for a request whose Origin header is `origin` (nullptr:
// none): "*" in "*" mode, `origin` itself when it is one of `allowed` exactly, else empty (not
// allowed: no CORS header). Never echoes anything that is not an exact match.
std::string CorsAllowOrigin(const std::vector<std::string>& allowed, const std::string* origin);

// Adds to `response` (for a request with Origin `origin`) Vary: Origin when CORS is on, and
// Access-Control-Allow-Origin and -Expose-Headers when the origin is allowed and the response
// has no Access-Control-Allow-Origin yet (a preflight's answer has its own).
void AddCorsHeaders(const std::vector<std::string>& allowed, const std::string* origin,
                    HttpResponse* response);

// The answer to a preflight from `origin` for a path served with `methods` ("GET, DELETE"):
// 204 with Access-Control-Allow-Origin, -Allow-Methods, -Allow-Headers and -Max-Age when the
// origin is allowed; 403 PERMISSION_DENIED (JSON error body naming the origin, sanitized) and no
// Access-Control-* header otherwise.
HttpResponse CorsPreflight(const std::vector<std::string>& allowed, const std::string& origin,
                           const std::string& methods);

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_CORS_H_
