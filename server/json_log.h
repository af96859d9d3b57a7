// Structured logs: one JSON object per line ({"time", "level", "thread", "msg"}), for log
// collectors (drillbif-server --log-format json). spdlog has no JSON sink; this is a pattern with
// a custom flag that escapes the message as a JSON string.
#ifndef DRILLBIF_SERVER_JSON_LOG_H_
#define DRILLBIF_SERVER_JSON_LOG_H_

#include <spdlog/pattern_formatter.h>

#include <memory>
#include <string>
#include <string_view>

namespace drillbif::server {

// `text` as the body of a JSON string (quotes, backslashes and control characters escaped;
// other bytes, UTF-8 included, copied).
std::string JsonEscape(std::string_view text);

// The formatter of the JSON lines; spdlog::set_formatter(JsonLogFormatter()) switches every
// logger to it.
std::unique_ptr<spdlog::formatter> JsonLogFormatter();

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_JSON_LOG_H_
