#include "server/tokens.h"

#include <fstream>
#include <sstream>

namespace drillbif::server {
namespace {

bool ValidName(std::string_view name) {
  if (name.empty() || name.size() > 64) return false;
  for (char c : name) {
    const bool ok = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
                    c == '_' || c == '.' || c == '-';
    if (!ok) return false;
  }
  return true;
}

bool ValidToken(std::string_view token) {
  if (token.size() < 8 || token.size() > 512) return false;
  for (char c : token) {
    if (c <= ' ' || c > '~') return false;
  }
  return true;
}

// Equal strings, compared in time that depends only on their lengths.
bool ConstantTimeEqual(std::string_view a, std::string_view b) {
  unsigned char diff = a.size() == b.size() ? 0 : 1;
  for (size_t i = 0; i < b.size(); ++i) {
    diff |= static_cast<unsigned char>(b[i] ^ (i < a.size() ? a[i] : 0));
  }
  return diff == 0;
}

}  // namespace

StatusOr<TokenSet> TokenSet::FromPairs(std::vector<std::pair<std::string, std::string>> pairs) {
  TokenSet set;
  for (size_t i = 0; i < pairs.size(); ++i) {
    const auto& [name, token] = pairs[i];
    const std::string where = "token " + std::to_string(i + 1) + " ('" + name.substr(0, 64) + "')";
    if (!ValidName(name)) {
      return InvalidArgument(where + ": a client name is 1 to 64 of [A-Za-z0-9_.-]");
    }
    if (!ValidToken(token)) {
      return InvalidArgument(where + ": a token is 8 to 512 printable ASCII characters, no spaces");
    }
    for (const auto& [other_name, other_token] : set.entries_) {
      if (other_name == name) return InvalidArgument(where + ": client name given twice");
      if (other_token == "Bearer " + token) return InvalidArgument(where + ": token given twice");
    }
    set.entries_.emplace_back(name, "Bearer " + token);
  }
  return set;
}

StatusOr<TokenSet> TokenSet::Load(const std::string& single_token, const std::string& tokens_file) {
  std::vector<std::pair<std::string, std::string>> pairs;
  if (!single_token.empty()) pairs.emplace_back("default", single_token);
  if (!tokens_file.empty()) {
    std::ifstream in(tokens_file);
    if (!in) return NotFound("tokens file '" + tokens_file + "' cannot be read");
    std::string line;
    for (int number = 1; std::getline(in, line); ++number) {
      if (!line.empty() && line.back() == '\r') line.pop_back();
      const size_t start = line.find_first_not_of(" \t");
      if (start == std::string::npos || line[start] == '#') continue;
      std::istringstream fields(line);
      std::string name, token, extra;
      fields >> name >> token;
      if (token.empty() || (fields >> extra)) {
        return InvalidArgument("tokens file '" + tokens_file + "' line " + std::to_string(number) +
                               ": expected NAME TOKEN");
      }
      pairs.emplace_back(std::move(name), std::move(token));
    }
  }
  StatusOr<TokenSet> set = FromPairs(std::move(pairs));
  if (!set.ok() && !tokens_file.empty()) {
    return InvalidArgument("tokens file '" + tokens_file + "': " + set.status().message());
  }
  return set;
}

StatusOr<std::string> TokenSet::Authenticate(bool present, std::string_view authorization) const {
  if (entries_.empty()) return std::string();
  if (!present) {
    return Status(StatusCode::kUnauthenticated,
                  "missing bearer token (metadata \"authorization: Bearer <token>\")");
  }
  // Every entry is compared, whichever matches, so that the time does not depend on which.
  const std::string* match = nullptr;
  for (const auto& [name, expected] : entries_) {
    if (ConstantTimeEqual(authorization, expected)) match = &name;
  }
  if (match == nullptr) return Status(StatusCode::kUnauthenticated, "wrong bearer token");
  return *match;
}

}  // namespace drillbif::server
