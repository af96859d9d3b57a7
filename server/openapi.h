// The REST gateway's contract as an OpenAPI 3.0 document, generated at run time from the protos:
// the paths and operations from the google.api.http annotations of every rpc (drillbif.v1.Jobs,
// google.longrunning.Operations), the schemas from the messages they reach, in protobuf's JSON
// mapping, and the descriptions from the proto comments (proto/descriptor_set.h). Nothing of it
// is written by hand but the gateway's own routes (/healthz, /metrics, /openapi.json), the
// error body and the bearer-token scheme, so an rpc added to a service appears without a change
// here. Served by the gateway at GET /openapi.json.
//
//   StatusOr<std::string> json = OpenApiJson();  // {"components": ..., "openapi": "3.0.3", ...}
#ifndef DRILLBIF_SERVER_OPENAPI_H_
#define DRILLBIF_SERVER_OPENAPI_H_

#include <google/protobuf/descriptor.h>

#include <string>
#include <vector>

#include "drillbif/common/status.h"

namespace drillbif::server {

// One google.api.http binding of an rpc (its main rule or one of its additional_bindings).
struct HttpBinding {
  // The rpc, in the generated descriptor pool.
  const google::protobuf::MethodDescriptor* method = nullptr;
  // "GET", "POST", "PUT", "PATCH", "DELETE" or a custom rule's kind.
  std::string verb;
  // The path template as annotated ("/v1/{name=operations/*}:result").
  std::string path_template;
  // The rule's body: "*" (every field not in the path), a field name, or empty (no body: the
  // fields not in the path are query parameters).
  std::string body;
};

// Every http binding of every rpc of the services served by the gateway (drillbif.v1.Jobs,
// google.longrunning.Operations), in declaration order. Rpcs without an annotation
// (WaitOperation) have none.
std::vector<HttpBinding> AnnotatedBindings();

// The OpenAPI 3.0.3 document as JSON text (keys sorted, indented). Built once, on the first call
// (thread-safe); INTERNAL if the embedded descriptor set cannot be read (a broken build).
StatusOr<std::string> OpenApiJson();

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_OPENAPI_H_
