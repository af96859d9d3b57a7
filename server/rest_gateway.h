// RestGateway: the service's API as JSON over HTTP/1.1 on the server's second port, following the
// google.api.http annotations of proto/drillbif/v1/service.proto and
// proto/google/longrunning/operations.proto, with protobuf's JSON mapping. Also serves
// Prometheus metrics at GET /metrics. HTTPS when given a certificate and key.
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
//   GET    /openapi.json                                      OpenAPI 3.0 (server/openapi.h)
//   OPTIONS any of these                                       CORS preflight (server/cors.h)
//   GET    / and the dashboard's files                        static, no token (dashboard.h)
//
// Threads: HTTP is served by libmicrohttpd (server/http_server.h) on a few epoll threads that
// only move bytes and convert JSON; no thread waits for an answer. A call into the services uses
// gRPC's callback API and suspends its connection until the callback resumes it; an event stream
// (a grpc::ClientReadReactor) suspends its connection between events. So a slow client, an open
// event stream or a computing QueryOptimum costs a socket and a bounded amount of memory, never a
// thread. /metrics is rendered on a thread of its own (it reads the store). A client that goes
// away cancels its call or its stream.
#ifndef DRILLBIF_SERVER_REST_GATEWAY_H_
#define DRILLBIF_SERVER_REST_GATEWAY_H_

#include <grpcpp/grpcpp.h>

#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "drillbif/common/status.h"
#include "server/metrics.h"
#include "server/tokens.h"

namespace drillbif::server {

// How the gateway serves, and the limits it enforces on every client. Each limit is a flag of
// drillbif-server ("--http-" and the name with dashes); what a client gets when it crosses one is
// in docs/service.md.
struct RestOptions {
  // Address to bind. 127.0.0.1: local unless asked otherwise (as the gRPC port).
  std::string host = "127.0.0.1";
  // Port; 0 picks a free port (RestGateway::port() tells which).
  int port = 8080;
  // The bearer tokens the API routes need ("Authorization: Bearer <token>"; server/tokens.h);
  // empty: none. Checked here first (so a request without one is refused before its body is
  // read) and again by the services, which receive it as metadata. /metrics, /healthz and
  // /openapi.json are open, like gRPC health, and so are CORS preflights. Never null.
  std::shared_ptr<const TokenSet> tokens = std::make_shared<TokenSet>();
  // PEM file of the server's certificate (chain). With tls_key_file (both or neither), the port
  // serves HTTPS only (GnuTLS through libmicrohttpd); empty: plain HTTP.
  std::string tls_cert_file;
  // PEM file of the certificate's private key (unencrypted).
  std::string tls_key_file;
  // Browser origins allowed to call the API from scripts (CORS, server/cors.h): each exact,
  // "scheme://host[:port]" as browsers send it, or "*" alone for any origin (never with
  // credentials: the gateway allows no cookies, the token goes in the Authorization header).
  // Empty: no CORS header at all, and OPTIONS is not served.
  std::vector<std::string> cors_origins;
  // Event-loop (epoll) threads. They parse requests, print answers and move bytes; no request
  // ever waits on one, so a few suffice whatever the number of clients. 2: one per core of the
  // machines the service is sized for.
  int threads = 2;

  // --- Limits (each crossing is answered with a JSON error unless said otherwise) ------------
  // Concurrent connections, open event streams included; at the limit the server stops
  // accepting, and new connections wait in the listen queue until one closes. 1024: far above the
  // expected dashboards and clients, and each costs only a socket and at most
  // connection_memory_bytes. Lowered at start to RLIMIT_NOFILE minus 256 (gRPC, SQLite and log
  // descriptors) when the process may not open that many files.
  int connection_limit = 1024;
  // The kernel's queue of connections not yet accepted (listen(2) backlog, capped by
  // net.core.somaxconn). 1024: a burst of clients connecting at once is queued instead of having
  // its SYNs dropped and retried a second later.
  int listen_backlog = 1024;
  // Memory of one connection in libmicrohttpd, in bytes: the request line, the headers and the
  // read and write buffers (MHD_OPTION_CONNECTION_MEMORY_LIMIT). A request whose line and
  // headers do not fit is answered by libmicrohttpd itself with 431 (414 when the request line
  // alone does not fit) and a fixed HTML body, before the gateway sees it; the limits below are
  // smaller so that the gateway answers (in JSON) everything up to this one. 64 KiB: four times
  // max_header_bytes, and 64 MiB for 1024 connections at worst.
  int connection_memory_bytes = 64 << 10;
  // Longest request target (path and query, as sent), in bytes: longer is 414 URI Too Long.
  // 8 KiB: an operation name is 43 bytes and a query a few tens; browsers and proxies allow 8 KiB.
  int max_uri_bytes = 8 << 10;
  // Longest request line and headers together, in bytes: longer is 431 Request Header Fields Too
  // Large. 16 KiB: a bearer token and the usual headers take well under 1 KiB.
  int max_header_bytes = 16 << 10;
  // Most header fields in a request: more is 431. 100: curl sends 3 to 5, browsers about 15.
  int max_header_count = 100;
  // Largest request body, in bytes; a larger Content-Length is 413 RESOURCE_EXHAUSTED before the
  // body is read (and the bytes received are counted too). Bodies without Content-Length
  // (chunked) are refused with 411. 4 MiB, the gRPC port's limit.
  int max_body_bytes = 4 << 20;
  // A connection on which no byte is read or written for this long is closed, in milliseconds
  // (MHD_OPTION_CONNECTION_TIMEOUT, rounded up to whole seconds): an idle keep-alive connection,
  // a stalled upload, a client that stopped reading its answer. A connection waiting for the
  // services (suspended) does not time out. 30 s: above any client's pause between requests of
  // one session.
  int idle_timeout_ms = 30000;
  // The whole request (line, headers and body) must arrive within this time of the connection's
  // opening, or of the end of the previous answer on a kept-alive connection, in milliseconds;
  // else the socket is shut down without an answer. A client sending one byte per second
  // (slowloris) resets the idle timeout forever, not this deadline. 30 s: a 4 MiB body at
  // 150 KB/s.
  int request_timeout_ms = 30000;
  // An answer must be taken by the socket within this time of being ready, in milliseconds (an
  // event of a stream: within this time of the previous one being taken); else the socket is
  // shut down. It bounds a client that reads a large answer slowly; idle_timeout_ms bounds one
  // that stops reading. 60 s: a 4 MB result at 70 KB/s.
  int write_timeout_ms = 60000;

  // Deadline of each call into the services, in milliseconds, unless the request sets the
  // header "X-Server-Timeout: <seconds>" (at most 600 s). It bounds a QueryOptimum that computes.
  // 60 s: longer than any call except a computing QueryOptimum.
  int deadline_ms = 60000;
  // How long Stop lets open event streams end by themselves, then calls in progress, then
  // answers being sent, in milliseconds, before it cancels or cuts them. The server stops its
  // watches first, so streams end at once with their error event; 1 s only bounds a client that
  // does not read.
  int stop_grace_ms = 1000;

  // INVALID_ARGUMENT naming the field when a value is out of range or two limits contradict.
  Status Validate() const;
};

// Renders /metrics (the server's Metrics with a fresh snapshot); an error gives 500.
using MetricsTextFunction = std::function<StatusOr<std::string>()>;

// The running gateway. Thread-safe.
class RestGateway {
 public:
  // Binds host:port and starts serving on its own threads. `channel` reaches the Jobs and
  // Operations services (an in-process channel of the server); `metrics` (not null, outliving
  // the gateway) counts the HTTP requests; `metrics_text` renders /metrics (on a thread of the
  // gateway's: it may block). Errors: INVALID_ARGUMENT for bad options or an unreadable
  // certificate or key, UNAVAILABLE when the port cannot be bound.
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

  // Refuses new requests (503), waits up to stop_grace_ms for the open event streams to end
  // (the server stops its watches first, so they end with their error event) and cancels the
  // rest, waits up to stop_grace_ms for the calls in progress and cancels the rest, stops
  // accepting connections, lets the answers be sent for up to stop_grace_ms, then closes every
  // connection and joins the threads. Idempotent.
  void Stop();

 private:
  struct Impl;
  explicit RestGateway(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

// The HTTP status of a gRPC code: OK 200, INVALID_ARGUMENT / FAILED_PRECONDITION 400,
// UNAUTHENTICATED 401, PERMISSION_DENIED 403, NOT_FOUND 404, ALREADY_EXISTS / ABORTED 409,
// RESOURCE_EXHAUSTED 429, UNAVAILABLE 503, DEADLINE_EXCEEDED 504, others 500. (The gateway's own
// limits answer 411, 413, 414 and 431 with the codes of docs/service.md before any call.)
int HttpStatusOf(grpc::StatusCode code);

// The JSON error body {"code": "<gRPC code name>", "message": ..., "details": [...]}: `details`
// holds the google.rpc.Status details carried by `status` (error_details), each in the JSON
// mapping of its Any, or is empty. Always valid JSON: a message that is not valid UTF-8 has the
// invalid bytes replaced by U+FFFD.
std::string ErrorJson(const grpc::Status& status);

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_REST_GATEWAY_H_
