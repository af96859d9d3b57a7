#include "server/http_server.h"

#include <arpa/inet.h>
#include <microhttpd.h>
#include <netdb.h>
#include <spdlog/spdlog.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <condition_variable>
#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <mutex>
#include <sstream>
#include <thread>

#include "server/cors.h"
#include "server/http_guard.h"
#include "server/rest_gateway.h"

namespace drillbif::server {
namespace {

using Clock = std::chrono::steady_clock;

constexpr char kJson[] = "application/json";
// Descriptors kept for everything but HTTP connections when the connection limit is fitted to
// RLIMIT_NOFILE: gRPC's sockets and pipes, SQLite's files, epoll and event descriptors, logs.
constexpr rlim_t kReservedDescriptors = 256;

HttpResponse ErrorResponse(int http_status, grpc::StatusCode code, const std::string& message) {
  HttpResponse response;
  response.status = http_status;
  response.content_type = kJson;
  response.body = ErrorJson(grpc::Status(code, message));
  return response;
}

std::string Lower(std::string_view text) {
  std::string out(text);
  for (char& c : out) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return out;
}

StatusOr<std::string> ReadFile(const std::string& path, const char* what) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return InvalidArgument(std::string(what) + ": cannot read '" + path + "'");
  std::ostringstream text;
  text << in.rdbuf();
  if (text.str().empty()) return InvalidArgument(std::string(what) + ": '" + path + "' is empty");
  return text.str();
}

// MHD's messages (a refused request, a TLS handshake that failed) at debug level: they are about
// clients, and a hostile client must not be able to flood the log.
void LogFromMhd(void*, const char* format, va_list args) {
  char line[512];
  std::vsnprintf(line, sizeof(line), format, args);
  std::string text(line);
  while (!text.empty() && (text.back() == '\n' || text.back() == '\r')) text.pop_back();
  spdlog::debug("HTTP (libmicrohttpd): {}", Sanitize(text, 400));
}

}  // namespace

// ---------------------------------------------------------------------------------------------

struct HttpServer::Impl {
  class Exchange;

  // What the server keeps per connection (MHD's socket context).
  struct Connection {
    // The request target of the request being read, as sent (MHD's URI log callback).
    std::string raw_target;
  };

  RestOptions options;
  HttpHandler* handler = nullptr;
  Metrics* metrics = nullptr;
  std::unique_ptr<ConnectionGuard> guard;
  MHD_Daemon* daemon = nullptr;
  std::string tls_cert;  // PEM text, kept for the daemon's life.
  std::string tls_key;
  int port = 0;
  int connection_limit = 0;

  std::mutex mutex;
  std::condition_variable changed;
  int exchanges = 0;  // Requests whose headers are in and that have not completed.
  int parked = 0;     // Exchanges suspended in MHD and not yet run again.
  bool stopped = false;

  void CountParked(int delta) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      parked += delta;
    }
    changed.notify_all();
  }

  // MHD callbacks.
  static void OnConnection(void* cls, MHD_Connection* connection, void** socket_context,
                           MHD_ConnectionNotificationCode code);
  static void* OnUri(void* cls, const char* uri, MHD_Connection* connection);
  static MHD_Result OnAccess(void* cls, MHD_Connection* connection, const char* url,
                             const char* method, const char* version, const char* upload_data,
                             size_t* upload_data_size, void** request_context);
  static void OnCompleted(void* cls, MHD_Connection* connection, void** request_context,
                          MHD_RequestTerminationCode code);

  MHD_Result Begin(MHD_Connection* connection, const char* method, void** request_context);
  std::optional<HttpResponse> CheckHeaders(MHD_Connection* connection, Exchange& exchange);
};

// One request: MHD's side (the connection, suspension) and the handler's (HttpExchange).
class HttpServer::Impl::Exchange final : public HttpExchange,
                                         public std::enable_shared_from_this<Exchange> {
 public:
  Exchange(Impl* server, MHD_Connection* connection, std::string method)
      : server_(server), connection_(connection), method_(std::move(method)) {}

  const std::string& method() const override { return method_; }
  const RequestTarget& target() const override { return target_; }
  const std::string* header(std::string_view name) const override {
    const std::string lower = Lower(name);
    for (const auto& [key, value] : headers_) {
      if (key == lower) return &value;
    }
    return nullptr;
  }
  const std::string& body() const override { return body_; }
  void set_route_label(const char* label) override { label_ = label; }

  void Respond(HttpResponse response) override { Answer(std::move(response), nullptr); }
  void RespondStream(HttpResponse head, std::shared_ptr<HttpStream> stream) override {
    Answer(std::move(head), std::move(stream));
  }

  void Wake() override {
    bool resume = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (finished_) return;
      if (waiting_for_stream_) {
        waiting_for_stream_ = false;
        resume = true;
      } else {
        wake_pending_ = true;
      }
    }
    if (resume) MHD_resume_connection(connection_);
  }

  void OnClientGone(std::function<void()> on_gone) override {
    std::lock_guard<std::mutex> lock(mutex_);
    if (!finished_) on_gone_ = std::move(on_gone);
  }

  // --- The server's side (MHD threads unless said otherwise) ----------------------------------

  void set_target(RequestTarget target) { target_ = std::move(target); }
  std::vector<std::pair<std::string, std::string>>& headers() { return headers_; }
  const char* label() const { return label_; }

  // Body bytes as they arrive: kept up to the limit; beyond it they are counted only (the
  // answer is then 413 once the body has been read).
  void AppendBody(const char* data, size_t size) {
    if (too_large_ || body_.size() + size > static_cast<size_t>(server_->options.max_body_bytes)) {
      too_large_ = true;
      body_.clear();
      return;
    }
    body_.append(data, size);
  }
  bool too_large() const { return too_large_; }

  // MHD runs this exchange again after a suspension (the access handler or the stream reader).
  void Unpark() {
    bool was_parked = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      was_parked = parked_;
      parked_ = false;
    }
    if (was_parked) server_->CountParked(-1);
  }

  // Called by the access handler once the request is whole (and again after each resume):
  // queues the answer if there is one, else hands the request to the handler (the first time)
  // and suspends until Respond.
  MHD_Result Serve() {
    Unpark();
    std::optional<HttpResponse> answer;
    std::shared_ptr<HttpStream> stream;
    bool first = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (answer_) {
        answer.swap(answer_);
        stream = stream_;
      } else {
        first = !handed_;
        handed_ = true;
        // Suspended before the handler runs, so that an answer given at once (even inline, on
        // this thread) finds the connection suspended and resumes it.
        SuspendLocked();
      }
    }
    if (answer) return Queue(std::move(*answer), std::move(stream));
    if (first) {
      std::weak_ptr<Exchange> weak = weak_from_this();
      server_->guard->WatchHangup(connection_, [weak] {
        if (auto exchange = weak.lock()) exchange->Gone();
      });
      server_->handler->OnRequest(shared_from_this());
    }
    return MHD_YES;
  }

  // Queues an answer on the connection (MHD thread, from the access handler).
  MHD_Result Queue(HttpResponse answer, std::shared_ptr<HttpStream> stream) {
    MHD_Response* response;
    if (stream) {
      // The reader's closure keeps the exchange alive until MHD destroys the response.
      response = MHD_create_response_from_callback(
          MHD_SIZE_UNKNOWN, 16 * 1024, &Exchange::Read,
          new std::shared_ptr<Exchange>(shared_from_this()),
          [](void* cls) { delete static_cast<std::shared_ptr<Exchange>*>(cls); });
    } else {
      response = MHD_create_response_from_buffer(answer.body.size(), answer.body.data(),
                                                 MHD_RESPMEM_MUST_COPY);
    }
    if (response == nullptr) return MHD_NO;
    // Every answer, the server's own errors included, so that a browser script can read them.
    AddCorsHeaders(server_->options.cors_origins, header("Origin"), &answer);
    if (!answer.content_type.empty()) {
      MHD_add_response_header(response, MHD_HTTP_HEADER_CONTENT_TYPE, answer.content_type.c_str());
    }
    for (const auto& [name, value] : answer.headers) {
      MHD_add_response_header(response, name.c_str(), value.c_str());
    }
    const MHD_Result queued =
        MHD_queue_response(connection_, static_cast<unsigned>(answer.status), response);
    MHD_destroy_response(response);
    server_->metrics->CountHttpRequest(method_, label_, answer.status);
    server_->guard->SetDeadline(
        connection_, Clock::now() + std::chrono::milliseconds(server_->options.write_timeout_ms));
    return queued;
  }

  // The request completed (MHD thread): sent whole (`ok`) or cut (client gone, error, timeout,
  // shutdown). Runs the on-gone callback in the latter case.
  void Finish(bool ok) {
    std::function<void()> on_gone;
    bool was_parked = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      finished_ = true;
      on_gone.swap(on_gone_);
      was_parked = parked_;
      parked_ = false;
    }
    if (was_parked) server_->CountParked(-1);
    if (!ok && on_gone) on_gone();
  }

 private:
  // Sets the answer and resumes the connection if it waits for it (any thread).
  void Answer(HttpResponse response, std::shared_ptr<HttpStream> stream) {
    bool resume = false;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (finished_ || answered_) return;
      answered_ = true;
      answer_ = std::move(response);
      stream_ = std::move(stream);
      resume = suspended_for_answer_;
      suspended_for_answer_ = false;
    }
    if (resume) MHD_resume_connection(connection_);
  }

  void SuspendLocked() {
    suspended_for_answer_ = true;
    parked_ = true;
    server_->CountParked(1);
    MHD_suspend_connection(connection_);
  }

  // The peer closed its socket (guard thread).
  void Gone() {
    std::function<void()> on_gone;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      on_gone.swap(on_gone_);
    }
    if (on_gone) on_gone();
  }

  // MHD's content reader of a streamed answer.
  static ssize_t Read(void* cls, uint64_t, char* buffer, size_t max) {
    return (*static_cast<std::shared_ptr<Exchange>*>(cls))->ReadStream(buffer, max);
  }

  ssize_t ReadStream(char* buffer, size_t max) {
    Unpark();
    for (;;) {
      if (pending_offset_ < pending_.size()) {
        const size_t n = std::min(max, pending_.size() - pending_offset_);
        pending_.copy(buffer, n, pending_offset_);
        pending_offset_ += n;
        server_->guard->SetDeadline(
            connection_,
            Clock::now() + std::chrono::milliseconds(server_->options.write_timeout_ms));
        return static_cast<ssize_t>(n);
      }
      pending_.clear();
      pending_offset_ = 0;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        wake_pending_ = false;
      }
      switch (stream_->Next(&pending_)) {
        case HttpStream::Pull::kData:
          continue;
        case HttpStream::Pull::kEnd:
          return MHD_CONTENT_READER_END_OF_STREAM;
        case HttpStream::Pull::kAbort:
          return MHD_CONTENT_READER_END_WITH_ERROR;
        case HttpStream::Pull::kWait:
          break;
      }
      std::lock_guard<std::mutex> lock(mutex_);
      if (wake_pending_) continue;  // Woken between Next and here: pull again.
      waiting_for_stream_ = true;
      parked_ = true;
      server_->CountParked(1);
      // Waiting for the producer is not writing: no write deadline meanwhile.
      server_->guard->SetDeadline(connection_, Clock::time_point::max());
      MHD_suspend_connection(connection_);
      return 0;
    }
  }

  Impl* const server_;
  MHD_Connection* const connection_;
  const std::string method_;
  RequestTarget target_;
  std::vector<std::pair<std::string, std::string>> headers_;  // Names in lower case.
  std::string body_;
  bool too_large_ = false;
  const char* label_ = "other";
  // The stream's bytes taken by Next and not yet copied to MHD (MHD threads only).
  std::string pending_;
  size_t pending_offset_ = 0;

  std::mutex mutex_;
  bool handed_ = false;                 // OnRequest was called.
  bool answered_ = false;               // Respond or RespondStream was called.
  std::optional<HttpResponse> answer_;  // Given and not yet queued.
  std::shared_ptr<HttpStream> stream_;
  bool suspended_for_answer_ = false;
  bool waiting_for_stream_ = false;
  bool wake_pending_ = false;
  bool parked_ = false;
  bool finished_ = false;
  std::function<void()> on_gone_;
};

// ---------------------------------------------------------------------------------------------

void HttpServer::Impl::OnConnection(void* cls, MHD_Connection* connection, void** socket_context,
                                    MHD_ConnectionNotificationCode code) {
  Impl* impl = static_cast<Impl*>(cls);
  if (code == MHD_CONNECTION_NOTIFY_STARTED) {
    *socket_context = new Connection();
    const MHD_ConnectionInfo* info =
        MHD_get_connection_info(connection, MHD_CONNECTION_INFO_CONNECTION_FD);
    impl->guard->Add(connection, info != nullptr ? info->connect_fd : -1);
    impl->guard->SetDeadline(
        connection, Clock::now() + std::chrono::milliseconds(impl->options.request_timeout_ms));
  } else {
    // Before MHD closes the socket: the guard must not touch its number afterwards.
    impl->guard->Remove(connection);
    delete static_cast<Connection*>(*socket_context);
    *socket_context = nullptr;
  }
}

void* HttpServer::Impl::OnUri(void*, const char* uri, MHD_Connection* connection) {
  const MHD_ConnectionInfo* info =
      MHD_get_connection_info(connection, MHD_CONNECTION_INFO_SOCKET_CONTEXT);
  if (info != nullptr && info->socket_context != nullptr) {
    static_cast<Connection*>(info->socket_context)->raw_target = uri;
  }
  return nullptr;
}

MHD_Result HttpServer::Impl::OnAccess(void* cls, MHD_Connection* connection, const char*,
                                      const char* method, const char*, const char* upload_data,
                                      size_t* upload_data_size, void** request_context) {
  Impl* impl = static_cast<Impl*>(cls);
  if (*request_context == nullptr) return impl->Begin(connection, method, request_context);
  Exchange& exchange = **static_cast<std::shared_ptr<Exchange>*>(*request_context);
  if (*upload_data_size != 0) {
    exchange.AppendBody(upload_data, *upload_data_size);
    *upload_data_size = 0;
    return MHD_YES;
  }
  if (exchange.too_large()) {
    return exchange.Queue(
        ErrorResponse(413, grpc::StatusCode::RESOURCE_EXHAUSTED,
                      "request body: larger than the limit of " +
                          std::to_string(impl->options.max_body_bytes) + " bytes"),
        nullptr);
  }
  // The request is whole: its read deadline no longer applies.
  impl->guard->SetDeadline(connection, Clock::time_point::max());
  return exchange.Serve();
}

void HttpServer::Impl::OnCompleted(void* cls, MHD_Connection* connection, void** request_context,
                                   MHD_RequestTerminationCode code) {
  Impl* impl = static_cast<Impl*>(cls);
  if (*request_context == nullptr) return;
  auto* holder = static_cast<std::shared_ptr<Exchange>*>(*request_context);
  *request_context = nullptr;
  impl->guard->UnwatchHangup(connection);
  (*holder)->Finish(code == MHD_REQUEST_TERMINATED_COMPLETED_OK);
  delete holder;
  // A kept-alive connection: the next request must come whole within the read deadline.
  impl->guard->SetDeadline(
      connection, Clock::now() + std::chrono::milliseconds(impl->options.request_timeout_ms));
  {
    std::lock_guard<std::mutex> lock(impl->mutex);
    --impl->exchanges;
  }
  impl->changed.notify_all();
}

MHD_Result HttpServer::Impl::Begin(MHD_Connection* connection, const char* method,
                                   void** request_context) {
  auto exchange = std::make_shared<Exchange>(this, connection, method);
  *request_context = new std::shared_ptr<Exchange>(exchange);
  {
    std::lock_guard<std::mutex> lock(mutex);
    ++exchanges;
  }
  std::optional<HttpResponse> refusal = CheckHeaders(connection, *exchange);
  if (!refusal) refusal = handler->OnHeaders(*exchange);
  if (!refusal) return MHD_YES;  // Read the body.
  // Answered before a body is read: MHD discards it and closes the connection; say so. A
  // request over a size limit is closed too (its headers may be only the start of a flood).
  const std::string* length = exchange->header("content-length");
  const int status = refusal->status;
  if (status == 411 || status == 413 || status == 414 || status == 431 ||
      exchange->header("transfer-encoding") != nullptr || (length != nullptr && *length != "0")) {
    refusal->headers.emplace_back(MHD_HTTP_HEADER_CONNECTION, "close");
  }
  return exchange->Queue(std::move(*refusal), nullptr);
}

std::optional<HttpResponse> HttpServer::Impl::CheckHeaders(MHD_Connection* connection,
                                                           Exchange& exchange) {
  const MHD_ConnectionInfo* context =
      MHD_get_connection_info(connection, MHD_CONNECTION_INFO_SOCKET_CONTEXT);
  const std::string raw_target = context != nullptr && context->socket_context != nullptr
                                     ? static_cast<Connection*>(context->socket_context)->raw_target
                                     : std::string();
  const auto too_large = [](int status, const std::string& message) {
    return ErrorResponse(status, grpc::StatusCode::RESOURCE_EXHAUSTED, message);
  };
  if (raw_target.size() > static_cast<size_t>(options.max_uri_bytes)) {
    return too_large(414, "request target: " + std::to_string(raw_target.size()) +
                              " bytes, longer than the limit of " +
                              std::to_string(options.max_uri_bytes));
  }
  const MHD_ConnectionInfo* size =
      MHD_get_connection_info(connection, MHD_CONNECTION_INFO_REQUEST_HEADER_SIZE);
  if (size != nullptr && size->header_size > static_cast<size_t>(options.max_header_bytes)) {
    return too_large(431, "request line and headers: " + std::to_string(size->header_size) +
                              " bytes, more than the limit of " +
                              std::to_string(options.max_header_bytes));
  }
  const int count = MHD_get_connection_values(connection, MHD_HEADER_KIND, nullptr, nullptr);
  if (count > options.max_header_count) {
    return too_large(431, "headers: " + std::to_string(count) + " fields, more than the limit of " +
                              std::to_string(options.max_header_count));
  }
  MHD_get_connection_values_n(
      connection, MHD_HEADER_KIND,
      [](void* cls, MHD_ValueKind, const char* key, size_t key_size, const char* value,
         size_t value_size) {
        static_cast<Exchange*>(cls)->headers().emplace_back(
            Lower(std::string_view(key, key_size)),
            value != nullptr ? std::string(value, value_size) : std::string());
        return MHD_YES;
      },
      &exchange);

  StatusOr<RequestTarget> target = ParseRequestTarget(raw_target);
  if (!target.ok()) {
    return ErrorResponse(400, grpc::StatusCode::INVALID_ARGUMENT, target.status().message());
  }
  exchange.set_target(std::move(target).value());

  // Bodies: Content-Length only (one value), within the limit; chunked bodies are refused since
  // their size is unknown until read.
  std::optional<std::string> length;
  for (const auto& [name, value] : exchange.headers()) {
    if (name != "content-length") continue;
    if (length && *length != value) {
      return ErrorResponse(400, grpc::StatusCode::INVALID_ARGUMENT,
                           "header Content-Length: given twice with different values");
    }
    length = value;
  }
  if (exchange.header("transfer-encoding") != nullptr) {
    return ErrorResponse(411, grpc::StatusCode::INVALID_ARGUMENT,
                         "Content-Length required: chunked bodies are not accepted (bodies are "
                         "limited to " +
                             std::to_string(options.max_body_bytes) + " bytes)");
  }
  if (length) {
    const bool digits =
        !length->empty() && length->size() <= 18 &&
        std::all_of(length->begin(), length->end(), [](char c) { return c >= '0' && c <= '9'; });
    if (!digits) {
      return ErrorResponse(400, grpc::StatusCode::INVALID_ARGUMENT,
                           "header Content-Length: not a byte count: '" + Sanitize(*length) + "'");
    }
    const long long bytes = std::stoll(*length);
    if (bytes > options.max_body_bytes) {
      return too_large(413, "request body: Content-Length " + *length +
                                " is larger than the limit of " +
                                std::to_string(options.max_body_bytes) + " bytes");
    }
  }
  {
    std::lock_guard<std::mutex> lock(mutex);
    if (stopped) {
      return ErrorResponse(503, grpc::StatusCode::UNAVAILABLE, "the server is shutting down");
    }
  }
  return std::nullopt;
}

// ---------------------------------------------------------------------------------------------

HttpServer::HttpServer(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

HttpServer::~HttpServer() { Stop(0); }

int HttpServer::port() const { return impl_->port; }

int HttpServer::connection_limit() const { return impl_->connection_limit; }

StatusOr<std::unique_ptr<HttpServer>> HttpServer::Start(const RestOptions& options,
                                                        HttpHandler* handler, Metrics* metrics) {
  if (Status s = options.Validate(); !s.ok()) return s;
  auto impl = std::make_unique<Impl>();
  impl->options = options;
  impl->handler = handler;
  impl->metrics = metrics;
  StatusOr<std::unique_ptr<ConnectionGuard>> guard = ConnectionGuard::Start();
  if (!guard.ok()) return guard.status();
  impl->guard = std::move(guard).value();

  unsigned int flags = MHD_USE_EPOLL_INTERNAL_THREAD | MHD_ALLOW_SUSPEND_RESUME | MHD_USE_ERROR_LOG;
  const bool tls = !options.tls_cert_file.empty();
  if (tls) {
    StatusOr<std::string> cert = ReadFile(options.tls_cert_file, "tls_cert_file");
    if (!cert.ok()) return cert.status();
    StatusOr<std::string> key = ReadFile(options.tls_key_file, "tls_key_file");
    if (!key.ok()) return key.status();
    impl->tls_cert = std::move(cert).value();
    impl->tls_key = std::move(key).value();
    flags |= MHD_USE_TLS;
  }

  // The address: a numeric address or a name, resolved once.
  addrinfo hints{};
  hints.ai_family = AF_UNSPEC;
  hints.ai_socktype = SOCK_STREAM;
  hints.ai_flags = AI_PASSIVE;
  addrinfo* found = nullptr;
  if (getaddrinfo(options.host.c_str(), nullptr, &hints, &found) != 0 || found == nullptr) {
    return Status(StatusCode::kUnavailable, "cannot resolve HTTP host '" + options.host + "'");
  }
  sockaddr_storage address{};
  std::memcpy(&address, found->ai_addr, found->ai_addrlen);
  freeaddrinfo(found);
  if (address.ss_family == AF_INET6) {
    flags |= MHD_USE_IPv6;
    reinterpret_cast<sockaddr_in6*>(&address)->sin6_port =
        htons(static_cast<uint16_t>(options.port));
  } else {
    reinterpret_cast<sockaddr_in*>(&address)->sin_port = htons(static_cast<uint16_t>(options.port));
  }

  // Each connection is a descriptor: keep the limit within what the process may open.
  impl->connection_limit = options.connection_limit;
  rlimit files{};
  if (getrlimit(RLIMIT_NOFILE, &files) == 0 && files.rlim_cur != RLIM_INFINITY) {
    const rlim_t room = files.rlim_cur > 2 * kReservedDescriptors
                            ? files.rlim_cur - kReservedDescriptors
                            : files.rlim_cur / 2;
    if (static_cast<rlim_t>(impl->connection_limit) > room) {
      impl->connection_limit = static_cast<int>(room);
      spdlog::warn("HTTP connection limit lowered from {} to {} (RLIMIT_NOFILE {})",
                   options.connection_limit, impl->connection_limit, files.rlim_cur);
    }
  }

  std::vector<MHD_OptionItem> items = {
      {MHD_OPTION_EXTERNAL_LOGGER, reinterpret_cast<intptr_t>(&LogFromMhd), nullptr},
      {MHD_OPTION_SOCK_ADDR, 0, &address},
      {MHD_OPTION_CONNECTION_LIMIT, impl->connection_limit, nullptr},
      {MHD_OPTION_LISTEN_BACKLOG_SIZE, options.listen_backlog, nullptr},
      {MHD_OPTION_CONNECTION_MEMORY_LIMIT, options.connection_memory_bytes, nullptr},
      {MHD_OPTION_CONNECTION_TIMEOUT, (options.idle_timeout_ms + 999) / 1000, nullptr},
      {MHD_OPTION_NOTIFY_CONNECTION, reinterpret_cast<intptr_t>(&Impl::OnConnection), impl.get()},
      {MHD_OPTION_URI_LOG_CALLBACK, reinterpret_cast<intptr_t>(&Impl::OnUri), impl.get()},
      {MHD_OPTION_NOTIFY_COMPLETED, reinterpret_cast<intptr_t>(&Impl::OnCompleted), impl.get()},
  };
  if (options.threads > 1) {
    items.push_back({MHD_OPTION_THREAD_POOL_SIZE, options.threads, nullptr});
  }
  if (tls) {
    items.push_back({MHD_OPTION_HTTPS_MEM_CERT, 0, impl->tls_cert.data()});
    items.push_back({MHD_OPTION_HTTPS_MEM_KEY, 0, impl->tls_key.data()});
  }
  items.push_back({MHD_OPTION_END, 0, nullptr});
  impl->daemon =
      MHD_start_daemon(flags, static_cast<uint16_t>(options.port), nullptr, nullptr,
                       &Impl::OnAccess, impl.get(), MHD_OPTION_ARRAY, items.data(), MHD_OPTION_END);
  if (impl->daemon == nullptr) {
    // MHD says why only through its log; a bad certificate is the likely cause with TLS.
    return Status(
        StatusCode::kUnavailable,
        "cannot serve HTTP on " + options.host + ":" + std::to_string(options.port) +
            (tls ? " (port in use, or the TLS certificate or key is invalid)" : " (port in use?)"));
  }
  const MHD_DaemonInfo* bound = MHD_get_daemon_info(impl->daemon, MHD_DAEMON_INFO_BIND_PORT);
  impl->port = bound != nullptr ? bound->port : options.port;
  return std::unique_ptr<HttpServer>(new HttpServer(std::move(impl)));
}

void HttpServer::Stop(int grace_ms) {
  Impl& impl = *impl_;
  {
    std::lock_guard<std::mutex> lock(impl.mutex);
    if (impl.stopped || impl.daemon == nullptr) {
      impl.stopped = true;
      return;
    }
    impl.stopped = true;
  }
  const MHD_socket listener = MHD_quiesce_daemon(impl.daemon);
  {
    std::unique_lock<std::mutex> lock(impl.mutex);
    // Answers being sent (an event stream's last event) get the grace time.
    impl.changed.wait_for(lock, std::chrono::milliseconds(grace_ms),
                          [&impl] { return impl.exchanges == 0; });
    // MHD must not stop with a suspended connection: the caller ended every call, so each
    // suspended exchange is resumed and about to run again.
    while (!impl.changed.wait_for(lock, std::chrono::seconds(5),
                                  [&impl] { return impl.parked == 0; })) {
      spdlog::warn("HTTP stop: {} requests still suspended", impl.parked);
    }
  }
  MHD_stop_daemon(impl.daemon);
  impl.daemon = nullptr;
  if (listener != MHD_INVALID_SOCKET) close(listener);
  impl.guard->Stop();
}

}  // namespace drillbif::server
