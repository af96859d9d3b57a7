// The dashboard: the static files of web/ (a page that lists jobs, submits them and plots their
// results through the REST API), served by the REST gateway at "/" from the bytes embedded in the
// binary (server/dashboard_files.h), so a deployed server needs no file beside it.
//
// The files hold no data, so they are served without a token (the page's own API calls carry
// the token the user types). GET and HEAD only. Every answer forbids external sources
// (Content-Security-Policy default-src 'self') and is revalidated by the browser (ETag,
// Cache-Control: no-cache), so a new server binary is seen at the next load.
#ifndef DRILLBIF_SERVER_DASHBOARD_H_
#define DRILLBIF_SERVER_DASHBOARD_H_

#include <optional>
#include <string>
#include <string_view>

#include "server/http_server.h"

namespace drillbif::server {

// The Content-Security-Policy of every dashboard answer: scripts, styles, images and API calls
// from the server itself only; no plugins, no framing, no <base> or form posts elsewhere.
inline constexpr char kDashboardCsp[] =
    "default-src 'self'; script-src 'self'; style-src 'self'; img-src 'self'; "
    "connect-src 'self'; object-src 'none'; base-uri 'none'; form-action 'self'; "
    "frame-ancestors 'none'";

// The answer of the dashboard to `method` `path`, or nullopt when the path is none of its:
// paths under "/v1/" are the API's. "/" is "/index.html". An embedded file: 200 with its bytes
// to GET and HEAD (304 without them when `if_none_match` (the If-None-Match header, or null)
// names its ETag), 405 to other methods. Any other path: 404. Errors have the gateway's JSON
// error body.
std::optional<HttpResponse> ServeDashboard(std::string_view method, std::string_view path,
                                           const std::string* if_none_match);

// The Content-Type of a served file by its extension ("application/octet-stream" if unknown).
std::string DashboardContentType(std::string_view path);

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_DASHBOARD_H_
