// The bytes a request is stored and keyed by: its deterministic serialization, and the content
// address (cache key) of its result.
#ifndef DRILLBIF_JOBS_REQUEST_BYTES_H_
#define DRILLBIF_JOBS_REQUEST_BYTES_H_

#include <google/protobuf/message.h>

#include <string>
#include <string_view>

namespace drillbif::jobs {

// The deterministic serialization of a message: the same message gives the same bytes in this
// build (map entries sorted, fields in number order). The cache key and the store's request
// bytes use it.
std::string DeterministicBytes(const google::protobuf::Message& message);

// Hex SHA-256 (64 lowercase digits) of the kind's name, the engine version (EngineVersion()) and
// the request bytes, each length-prefixed so that no two different triples hash the same input:
// the content address of a result. The request_id is never part of `request_bytes`.
std::string CacheKey(std::string_view kind_name, std::string_view request_bytes);

// Hex SHA-256 of `data` (64 lowercase digits).
std::string Sha256Hex(std::string_view data);

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_REQUEST_BYTES_H_
