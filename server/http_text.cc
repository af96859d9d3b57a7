#include "server/http_text.h"

#include <utf8cpp/utf8.h>

#include <algorithm>
#include <iterator>

namespace drillbif::server {
namespace {

int HexValue(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// Percent-decodes `text` into `out` ('+' becomes a space when `plus_is_space`). `what` names the
// part in errors.
Status Decode(std::string_view text, bool plus_is_space, const std::string& what,
              std::string* out) {
  out->clear();
  out->reserve(text.size());
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (c == '%') {
      const bool complete = i + 2 < text.size();
      const int high = complete ? HexValue(text[i + 1]) : -1;
      const int low = complete ? HexValue(text[i + 2]) : -1;
      if (high < 0 || low < 0) {
        return InvalidArgument(what + ": '%' at byte " + std::to_string(i) +
                               " is not followed by two hex digits");
      }
      const char decoded = static_cast<char>(high * 16 + low);
      if (decoded == '\0') {
        return InvalidArgument(what + ": a NUL byte (%00) at byte " + std::to_string(i));
      }
      out->push_back(decoded);
      i += 2;
    } else if (c == '+' && plus_is_space) {
      out->push_back(' ');
    } else {
      out->push_back(c);
    }
  }
  if (const size_t bad = FindInvalidUtf8(*out); bad != std::string_view::npos) {
    return InvalidArgument(what + ": not valid UTF-8 (at byte " + std::to_string(bad) +
                           " once decoded)");
  }
  return Status::Ok();
}

}  // namespace

size_t FindInvalidUtf8(std::string_view text) {
  const auto it = utf8::find_invalid(text.begin(), text.end());
  return it == text.end() ? std::string_view::npos
                          : static_cast<size_t>(std::distance(text.begin(), it));
}

std::string ValidUtf8(std::string_view text) {
  if (FindInvalidUtf8(text) == std::string_view::npos) return std::string(text);
  std::string valid;
  valid.reserve(text.size() + 16);
  utf8::replace_invalid(text.begin(), text.end(), std::back_inserter(valid));
  return valid;
}

std::string Sanitize(std::string_view text, size_t max_bytes) {
  std::string valid = ValidUtf8(text);
  for (char& c : valid) {
    const auto byte = static_cast<unsigned char>(c);
    if (byte < 0x20 || byte == 0x7F) c = '?';
  }
  if (valid.size() <= max_bytes) return valid;
  size_t cut = max_bytes;
  // Back to the first byte of a character (continuation bytes are 10xxxxxx).
  while (cut > 0 && (static_cast<unsigned char>(valid[cut]) & 0xC0) == 0x80) --cut;
  valid.resize(cut);
  return valid + "...";
}

StatusOr<RequestTarget> ParseRequestTarget(std::string_view raw) {
  if (raw.empty() || raw.front() != '/') {
    return InvalidArgument("request target: must start with '/', got '" + Sanitize(raw) + "'");
  }
  RequestTarget target;
  const size_t question = raw.find('?');
  const std::string_view path = raw.substr(0, question);
  if (Status s = Decode(path, /*plus_is_space=*/false, "path", &target.path); !s.ok()) return s;
  if (question == std::string_view::npos) return target;
  target.has_query = true;
  std::string_view query = raw.substr(question + 1);
  // A fragment is never sent by clients (RFC 9110 4.2.1); drop one if it is.
  query = query.substr(0, query.find('#'));
  size_t at = 0;
  while (at <= query.size()) {
    const size_t amp = std::min(query.find('&', at), query.size());
    const std::string_view item = query.substr(at, amp - at);
    at = amp + 1;
    if (item.empty()) continue;
    const size_t equals = item.find('=');
    std::string name;
    if (Status s = Decode(item.substr(0, equals), true, "query parameter name", &name); !s.ok()) {
      return s;
    }
    std::string value;
    if (equals != std::string_view::npos) {
      if (Status s = Decode(item.substr(equals + 1), true,
                            "query parameter '" + Sanitize(name) + "'", &value);
          !s.ok()) {
        return s;
      }
    }
    target.query.emplace_back(std::move(name), std::move(value));
  }
  return target;
}

}  // namespace drillbif::server
