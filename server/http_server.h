// HttpServer: the HTTP/1.1 side of the REST gateway on GNU libmicrohttpd (Debian's
// libmicrohttpd 0.9.75), event-driven: a few epoll threads serve every connection, and no thread
// ever waits for a request's answer. A request whose answer comes later (a call into the
// services, an event stream waiting for the next change) is *suspended* in MHD: its connection
// costs its socket and its bounded memory, nothing else, until HttpExchange::Respond or Wake
// resumes it from whatever thread has the answer.
//
// It enforces the limits of RestOptions (connections, backlog, request target, header bytes and
// count, body, idle time, whole-request read deadline, write deadline) and answers their
// violations itself with the gateway's JSON error body. One answer is not the gateway's: a
// request line and headers that do not fit in the connection's memory
// (RestOptions::connection_memory_bytes) are answered by MHD itself, before any callback, with
// 431 (414 for an oversize request line) and a fixed HTML body, and the connection is closed.
//
// The handler (the gateway) sees each request twice: OnHeaders before the body is read (to
// refuse it early: authentication, unknown routes), and OnRequest once it is whole.
#ifndef DRILLBIF_SERVER_HTTP_SERVER_H_
#define DRILLBIF_SERVER_HTTP_SERVER_H_

#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "drillbif/common/status.h"
#include "server/http_text.h"
#include "server/metrics.h"

namespace drillbif::server {

struct RestOptions;

// An answer (or the head of a streamed one).
struct HttpResponse {
  // HTTP status.
  int status = 200;
  // Content-Type header.
  std::string content_type;
  // The body (ignored for a streamed answer).
  std::string body;
  // Other headers.
  std::vector<std::pair<std::string, std::string>> headers;
};

// A response body produced over time (Server-Sent Events), pulled by the server as the socket
// takes it.
class HttpStream {
 public:
  enum class Pull {
    kData,   // *out holds the next bytes.
    kWait,   // Nothing yet: the server waits for HttpExchange::Wake.
    kEnd,    // The body is complete.
    kAbort,  // Cut the connection (the client is gone or the producer failed).
  };
  virtual ~HttpStream() = default;
  // Called on a server thread, never concurrently: the next bytes, or why there are none.
  virtual Pull Next(std::string* out) = 0;
};

// One request and its answer. The request's fields are fixed once OnHeaders is called (the body
// once OnRequest is); the answering methods are thread-safe.
class HttpExchange {
 public:
  virtual ~HttpExchange() = default;

  // "GET", "POST", ...
  virtual const std::string& method() const = 0;
  // The decoded path and query.
  virtual const RequestTarget& target() const = 0;
  // The value of the header `name` (case-insensitive; the first if repeated), or nullptr.
  virtual const std::string* header(std::string_view name) const = 0;
  // The body (empty until OnRequest).
  virtual const std::string& body() const = 0;
  // The route template counted in drillbif_http_requests_total ("other" until set).
  virtual void set_route_label(const char* label) = 0;

  // Answers. Once; from any thread, at any time after OnRequest was called (later calls and
  // calls after the client left are ignored).
  virtual void Respond(HttpResponse response) = 0;
  // Answers with `head` (status and headers) and then the bytes of `stream`.
  virtual void RespondStream(HttpResponse head, std::shared_ptr<HttpStream> stream) = 0;
  // The stream has something new (data or its end): the server pulls again. Any thread.
  virtual void Wake() = 0;
  // `on_gone` runs once, on some thread, if the client goes away (or the server stops) before
  // the answer was sent whole: it should cancel what works for the answer. Replaces a previous
  // one; never runs after the exchange completed normally.
  virtual void OnClientGone(std::function<void()> on_gone) = 0;
};

// What the server calls for each request.
class HttpHandler {
 public:
  virtual ~HttpHandler() = default;
  // The request line and headers are in, the body is not read yet. A response refuses the
  // request at once (the body is then never read and the connection closes after the answer);
  // nullopt reads the body and goes on to OnRequest. Called on a server thread: must not block.
  virtual std::optional<HttpResponse> OnHeaders(HttpExchange& exchange) = 0;
  // The whole request is in: answer through exchange->Respond / RespondStream, now or later.
  // Called on a server thread: must not block.
  virtual void OnRequest(std::shared_ptr<HttpExchange> exchange) = 0;
};

// The running server. Thread-safe.
class HttpServer {
 public:
  // Binds options.host:options.port and serves with options.threads epoll threads; TLS when
  // options has a certificate. `handler` and `metrics` must outlive the server. Errors:
  // INVALID_ARGUMENT (unreadable or bad certificate or key), UNAVAILABLE (cannot bind or start).
  static StatusOr<std::unique_ptr<HttpServer>> Start(const RestOptions& options,
                                                     HttpHandler* handler, Metrics* metrics);

  // Stop(0).
  ~HttpServer();

  HttpServer(const HttpServer&) = delete;
  HttpServer& operator=(const HttpServer&) = delete;

  // The port bound.
  int port() const;

  // The connection limit in force: RestOptions::connection_limit, lowered to fit RLIMIT_NOFILE.
  int connection_limit() const;

  // Stops accepting connections, lets the requests in progress end for up to `grace_ms`, waits
  // until no request is suspended (the caller has ended every call that would resume one), then
  // closes every connection and joins the threads. Idempotent.
  void Stop(int grace_ms);

 private:
  struct Impl;
  explicit HttpServer(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_HTTP_SERVER_H_
