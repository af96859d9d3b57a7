// Bearer tokens and the clients they identify. A server may have none (no authentication), one
// (--token: every caller is the client "default"), or a file of them (--tokens-file: one client
// per line), so that fairness and queue limits can tell clients apart.
//
// Tokens file: one "NAME TOKEN" per line; blank lines and lines starting with '#' are ignored.
// NAME is 1 to 64 of [A-Za-z0-9_.-]; TOKEN is 8 to 512 printable ASCII characters without
// spaces (make it long and random: `openssl rand -hex 32`). Names and tokens are unique.
// Kubernetes mounts it from a Secret (deploy/k8s).
#ifndef DRILLBIF_SERVER_TOKENS_H_
#define DRILLBIF_SERVER_TOKENS_H_

#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "drillbif/common/status.h"

namespace drillbif::server {

class TokenSet {
 public:
  // No tokens: every call is allowed, as the anonymous client "".
  TokenSet() = default;

  // The tokens of `single_token` (client "default", when not empty) and of the file at
  // `tokens_file` (when not empty). INVALID_ARGUMENT naming the line for a malformed file or a
  // duplicate, NOT_FOUND when the file cannot be read.
  static StatusOr<TokenSet> Load(const std::string& single_token, const std::string& tokens_file);

  // From (name, token) pairs, checked as a file's lines are.
  static StatusOr<TokenSet> FromPairs(std::vector<std::pair<std::string, std::string>> pairs);

  // True when no token is configured (no authentication).
  bool empty() const { return entries_.empty(); }

  // The client whose token `authorization` ("Bearer <token>") carries; "" when the set is empty.
  // UNAUTHENTICATED saying whether the token was missing (`present` false) or wrong. Every entry
  // is compared in constant time, so response times tell nothing about any token's bytes.
  StatusOr<std::string> Authenticate(bool present, std::string_view authorization) const;

 private:
  std::vector<std::pair<std::string, std::string>> entries_;  // (name, "Bearer " + token)
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_TOKENS_H_
