// Text checks of the HTTP side of the REST gateway: UTF-8 validity (utf8cpp), user input made safe
// to echo in an error message, and the request target (path and query) split and
// percent-decoded strictly.
//
// Every string the gateway hands to the services (the path's operation name, query parameters,
// JSON strings, the Authorization header) must be valid UTF-8: protobuf refuses to serialize a
// proto3 string field that is not, which would surface as an INTERNAL error instead of the
// client's INVALID_ARGUMENT. These functions find such input first and name where it is.
#ifndef DRILLBIF_SERVER_HTTP_TEXT_H_
#define DRILLBIF_SERVER_HTTP_TEXT_H_

#include <cstddef>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "drillbif/common/status.h"

namespace drillbif::server {

// Longest piece of user input echoed in an error message, in bytes (before the "..." mark).
inline constexpr size_t kMaxEchoBytes = 64;

// The byte offset of the first byte that is not part of well-formed UTF-8 (RFC 3629: no overlong
// forms, no surrogates, nothing above U+10FFFF), or std::string_view::npos when all is valid.
size_t FindInvalidUtf8(std::string_view text);

// `text` with every byte that is not part of well-formed UTF-8 replaced by U+FFFD.
std::string ValidUtf8(std::string_view text);

// `text` made safe to quote in a message: invalid UTF-8 replaced by U+FFFD, control characters
// (below 0x20 and 0x7F) by '?', and cut after `max_bytes` (on a character boundary) with "..."
// appended when it was longer.
std::string Sanitize(std::string_view text, size_t max_bytes = kMaxEchoBytes);

// The request target of an HTTP request ("/v1/operations?filter=kind%3Dsweep"), split and
// decoded.
struct RequestTarget {
  // The path, percent-decoded ("/v1/operations").
  std::string path;
  // The query parameters in their order, names and values percent-decoded, '+' read as a space
  // (the form encoding browsers and curl use). A name without '=' has an empty value.
  std::vector<std::pair<std::string, std::string>> query;
  // Whether the target has a '?' at all (a body route refuses any query string, even empty).
  bool has_query = false;
};

// Splits `raw` (as received: origin form, starting with '/') at the first '?' and the query at
// '&' and '=', and decodes each part. INVALID_ARGUMENT naming the part ("path", "query parameter
// 'page_size'") for: a target that does not start with '/', a '%' not followed by two hex digits,
// a decoded NUL byte, or a result that is not valid UTF-8 (with the byte offset).
StatusOr<RequestTarget> ParseRequestTarget(std::string_view raw);

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_HTTP_TEXT_H_
