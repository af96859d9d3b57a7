// RestGateway: the service's API as JSON over HTTP/1.1 (cpp-httplib), on the server's second
// port, following the google.api.http annotations of proto/drillbif/v1/service.proto and
// proto/google/longrunning/operations.proto, with protobuf's JSON mapping. Also serves
// Prometheus metrics at GET /metrics.
//
// The gateway holds no service logic: every API route becomes one call of the generated gRPC
// stubs over an in-process channel to the same Jobs and Operations services that gRPC clients
// reach (grpc::Server::InProcessChannel), with the request's bearer token passed on as the
// "authorization" metadata. So validation, the cache, tokens and errors are the services'; the
// gateway only maps JSON <-> messages, paths and query parameters -> fields, and status codes ->
// HTTP statuses (HttpStatusOf). Errors are JSON bodies {"code": "INVALID_ARGUMENT", "message":
// "...", "details": [...]} with the gRPC code's name.
//
// Routes (docs/service.md has the table with examples):
//   POST   /v1/jobs:{simulate,sweep,continue,trace,optimum}   body: Submit*Request
//   GET    /v1/{name=operations/*}:result                     query: page_size, page_token
//   POST   /v1/optimum:query                                  body: QueryOptimumRequest
//   GET    /v1/{name=operations/*}:watch                      Server-Sent Events of JobMetadata
//   GET    /v1/operations                                     query: filter, page_size, page_token
//   GET    /v1/{name=operations/**}                           GetOperation
//   DELETE /v1/{name=operations/**}                           DeleteOperation
//   POST   /v1/{name=operations/**}:cancel                    body: {} (CancelOperation)
//   GET    /metrics                                           Prometheus text format 0.0.4
//
// Threads: the gateway's own pool (RestOptions::threads) parses, calls the in-process channel and
// waits for the answer; the services do their work on their executor and the worker pool, so no
// engine work ever runs on an HTTP thread. An open event stream holds one HTTP thread until its
// job finishes (or the client goes away, noticed at the next event).
#ifndef DRILLBIF_SERVER_REST_GATEWAY_H_
#define DRILLBIF_SERVER_REST_GATEWAY_H_

#include <grpcpp/grpcpp.h>

#include <functional>
#include <memory>
#include <string>

#include "drillbif/common/status.h"
#include "server/metrics.h"

namespace drillbif::server {

// How the gateway serves.
struct RestOptions {
  // Address to bind. 127.0.0.1: local unless asked otherwise (as the gRPC port).
  std::string host = "127.0.0.1";
  // Port; 0 picks a free port (RestGateway::port() tells which).
  int port = 8080;
  // Bearer token the API routes need ("Authorization: Bearer <token>"); empty: none. Checked here
  // first (so a request without it is refused before its body is parsed) and again by the
  // services, which receive it as metadata. /metrics is open, like gRPC health.
  std::string token;
  // Largest request body, in bytes; larger ones get 413 RESOURCE_EXHAUSTED before they are read
  // (by Content-Length). 4 MiB, the gRPC port's limit.
  int max_body_bytes = 4 << 20;
  // HTTP threads. Each request holds one while its call runs, and each open event stream holds
  // one until its job ends, so this bounds the concurrent Watch streams too. 8: a few dashboards
  // watching plus requests; raise it for more streams.
  int threads = 8;
  // Deadline of each call into the services, in milliseconds, unless the request sets the
  // header "X-Server-Timeout: <seconds>" (at most 600 s). It bounds a QueryOptimum that computes.
  // 60 s: longer than any call except a computing QueryOptimum.
  int deadline_ms = 60000;
  // How long a connection may take to send a request (and stay idle between keep-alive
  // requests), in milliseconds. 5 s: a slow client cannot hold a thread for long.
  int read_timeout_ms = 5000;
  // How long Stop lets open event streams end by themselves, in milliseconds, before it cancels
  // them. The server stops its watches first, so streams end at once with their error event;
  // 1 s only bounds a stream whose client does not read.
  int stop_grace_ms = 1000;

  // INVALID_ARGUMENT naming the field when a value is out of range.
  Status Validate() const;
};

// Renders /metrics (the server's Metrics with a fresh snapshot); an error gives 500.
using MetricsTextFunction = std::function<StatusOr<std::string>()>;

// The running gateway. Thread-safe.
class RestGateway {
 public:
  // Binds host:port and starts serving on its own threads. `channel` reaches the Jobs and
  // Operations services (an in-process channel of the server); `metrics` (not null, outliving
  // the gateway) counts the HTTP requests; `metrics_text` renders /metrics. Errors:
  // INVALID_ARGUMENT for bad options, UNAVAILABLE when the port cannot be bound.
  static StatusOr<std::unique_ptr<RestGateway>> Start(const RestOptions& options,
                                                      std::shared_ptr<grpc::Channel> channel,
                                                      Metrics* metrics,
                                                      MetricsTextFunction metrics_text);

  // Stop().
  ~RestGateway();

  RestGateway(const RestGateway&) = delete;
  RestGateway& operator=(const RestGateway&) = delete;

  // The port bound (the free port picked when RestOptions::port was 0).
  int port() const;

  // Stops accepting event streams, waits up to stop_grace_ms for the open ones to end (the
  // server stops its watches first, so they end with their error event) and cancels the rest,
  // then stops accepting connections, lets the requests in progress finish (their calls end when
  // the services answer) and joins the threads. Idempotent.
  void Stop();

 private:
  struct Impl;
  explicit RestGateway(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// The HTTP status of a gRPC code: OK 200, INVALID_ARGUMENT / FAILED_PRECONDITION 400,
// UNAUTHENTICATED 401, PERMISSION_DENIED 403, NOT_FOUND 404, ALREADY_EXISTS / ABORTED 409,
// RESOURCE_EXHAUSTED 429, UNAVAILABLE 503, DEADLINE_EXCEEDED 504, others 500. (An oversize body
// is 413 RESOURCE_EXHAUSTED: the gateway refuses it before any call.)
int HttpStatusOf(grpc::StatusCode code);

// The JSON error body {"code": "<gRPC code name>", "message": ..., "details": [...]}: `details`
// holds the google.rpc.Status details carried by `status` (error_details), each in the JSON
// mapping of its Any, or is empty.
std::string ErrorJson(const grpc::Status& status);

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_REST_GATEWAY_H_
