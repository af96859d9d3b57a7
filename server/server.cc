#include "server/server.h"

#include <grpcpp/ext/proto_server_reflection_plugin.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/health_check_service_interface.h>
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <sstream>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "drillbif/common/threads.h"
#include "jobs/trace_task_codec.h"
#include "server/rest_gateway.h"
#include "server/services.h"
#include "server/store/postgres_job_store.h"
#include "server/store/sqlite_job_store.h"
#include "server/watch_hub.h"
#include "server/worker_pool.h"

namespace drillbif::server {
namespace {

// Whether a libpq connection string carries a password: a password= parameter (key=value or a
// URI's query), or a URI's user:password@.
bool UriHoldsPassword(const std::string& uri) {
  if (uri.find("password=") != std::string::npos) return true;
  const size_t scheme = uri.find("://");
  if (scheme == std::string::npos) return false;
  const size_t authority = scheme + 3;
  const size_t end = uri.find_first_of("/?", authority);
  const std::string userinfo_and_host = uri.substr(authority, end - authority);
  const size_t at = userinfo_and_host.rfind('@');
  return at != std::string::npos && userinfo_and_host.substr(0, at).find(':') != std::string::npos;
}

const char* RoleName(ServerOptions::Role role) {
  switch (role) {
    case ServerOptions::Role::kApi:
      return "api";
    case ServerOptions::Role::kWorker:
      return "worker";
    case ServerOptions::Role::kAll:
      break;
  }
  return "all";
}

// The store the options name: the PostgreSQL database of store_uri (its password read from
// store_password_file), else the SQLite file db_path. The stores' own error details (SQL,
// SQLite's and PostgreSQL's messages) go to the log, never to clients.
StatusOr<std::unique_ptr<JobStore>> OpenStore(const ServerOptions& o) {
  auto log = [](std::string_view detail) { spdlog::warn("job store: {}", detail); };
  if (o.store_uri.empty()) {
    SqliteJobStoreOptions options;
    options.full_sync = o.full_sync;
    options.log = log;
    return SqliteJobStore::Open(o.db_path, options);
  }
  PostgresJobStoreOptions options;
  options.log = log;
  if (!o.store_password_file.empty()) {
    std::ifstream file(o.store_password_file);
    if (!file || !std::getline(file, options.password)) {
      return InvalidArgument("store_password_file: cannot read '" + o.store_password_file + "'");
    }
    if (!options.password.empty() && options.password.back() == '\r') options.password.pop_back();
  }
  return PostgresJobStore::Open(o.store_uri, options);
}

// The gateway's options: the HTTP limits, and what ServerOptions sets for both ports.
RestOptions RestOptionsOf(const ServerOptions& o) {
  RestOptions rest = o.http;
  rest.host = o.host;
  rest.port = o.http_port;
  rest.max_body_bytes = o.max_request_bytes;
  rest.threads = o.http_threads;
  rest.tls_cert_file = o.tls_cert_file;
  rest.tls_key_file = o.tls_key_file;
  return rest;
}

// gRPC's credentials: TLS with the PEM files when given.
StatusOr<std::shared_ptr<grpc::ServerCredentials>> GrpcCredentialsOf(const ServerOptions& o) {
  if (o.tls_cert_file.empty()) return grpc::InsecureServerCredentials();
  grpc::SslServerCredentialsOptions::PemKeyCertPair pair;
  for (auto [path, text] : {std::pair{&o.tls_cert_file, &pair.cert_chain},
                            std::pair{&o.tls_key_file, &pair.private_key}}) {
    std::ifstream in(*path, std::ios::binary);
    std::ostringstream content;
    content << in.rdbuf();
    if (!in || content.str().empty()) {
      return InvalidArgument("TLS: cannot read '" + *path + "'");
    }
    *text = content.str();
  }
  grpc::SslServerCredentialsOptions ssl;
  ssl.pem_key_cert_pairs.push_back(std::move(pair));
  return grpc::SslServerCredentials(ssl);
}

}  // namespace

Status ServerOptions::Validate() const {
  if (host.empty()) return InvalidArgument("host: must not be empty");
  if (grpc_port < 0 || grpc_port > 65535) {
    return InvalidArgument("grpc_port: must be in [0, 65535], got " + std::to_string(grpc_port));
  }
  if (http_port < 0 || http_port > 65535) {
    return InvalidArgument("http_port: must be in [0, 65535], got " + std::to_string(http_port));
  }
  if (db_path.empty()) return InvalidArgument("db_path: must not be empty");
  if (role != Role::kAll && store_uri.empty()) {
    return InvalidArgument(
        "role: api and worker processes share a store; give store_uri (--store postgresql://...)");
  }
  if (!store_uri.empty() && UriHoldsPassword(store_uri)) {
    return InvalidArgument(
        "store_uri: must not hold the password (it would show in the process list); use "
        "store_password_file (--store-password-file) or PGPASSWORD");
  }
  if (trace_fan_out < 0 || trace_fan_out > kMaxTraceFanOut) {
    return InvalidArgument("trace_fan_out: must be 0 (off) .. " + std::to_string(kMaxTraceFanOut) +
                           ", got " + std::to_string(trace_fan_out));
  }
  if (trace_fan_out_batch < 1 || trace_fan_out_batch > jobs::kMaxTraceTaskBatch) {
    return InvalidArgument("trace_fan_out_batch: must be 1 .. " +
                           std::to_string(jobs::kMaxTraceTaskBatch) + ", got " +
                           std::to_string(trace_fan_out_batch));
  }
  if (!store_uri.empty() && lease_ms < 300) {
    return InvalidArgument("lease_ms: must be >= 300 with a shared store, got " +
                           std::to_string(lease_ms));
  }
  if (workers < 0 || workers > 1024) {
    return InvalidArgument("workers: must be in [0, 1024], got " + std::to_string(workers));
  }
  if (max_request_bytes < 1024) {
    return InvalidArgument("max_request_bytes: must be >= 1024, got " +
                           std::to_string(max_request_bytes));
  }
  if (max_queued_jobs < 1) {
    return InvalidArgument("max_queued_jobs: must be >= 1, got " + std::to_string(max_queued_jobs));
  }
  if (Status s = executor.Validate(); !s.ok()) return InvalidArgument("executor." + s.message());
  if (progress_interval_ms < 1) {
    return InvalidArgument("progress_interval_ms: must be >= 1, got " +
                           std::to_string(progress_interval_ms));
  }
  if (watch_poll_ms < 1) {
    return InvalidArgument("watch_poll_ms: must be >= 1, got " + std::to_string(watch_poll_ms));
  }
  if (http_threads < 1 || http_threads > 1024) {
    return InvalidArgument("http_threads: must be in [1, 1024], got " +
                           std::to_string(http_threads));
  }
  if (Status s = metrics.Validate(); !s.ok()) return InvalidArgument("metrics." + s.message());
  if (Status s = RestOptionsOf(*this).Validate(); !s.ok()) {
    return InvalidArgument("http." + s.message());
  }
  if (short_workers < 0 || short_workers > 1024) {
    return InvalidArgument("short_workers: must be in [0, 1024], got " +
                           std::to_string(short_workers));
  }
  if (!(short_job_seconds >= 0 && short_job_seconds < 1e9)) {
    return InvalidArgument("short_job_seconds: must be a number >= 0");
  }
  if (max_queued_per_client < 0) {
    return InvalidArgument("max_queued_per_client: must be >= 0, got " +
                           std::to_string(max_queued_per_client));
  }
  if (max_inline_result_bytes < 1024 || pages.max_page_bytes < 1024 ||
      pages.max_whole_bytes < 1024) {
    return InvalidArgument(
        "max_inline_result_bytes, pages.max_page_bytes, pages.max_whole_bytes: must be >= 1024");
  }
  if (Status s = retention.Validate(); !s.ok()) return InvalidArgument("retention." + s.message());
  if (retention_interval_ms < 1 || store_probe_ms < 1) {
    return InvalidArgument("retention_interval_ms, store_probe_ms: must be >= 1");
  }
  for (const auto& [name, limits] : job_limits) {
    if (jobs::FindKind(name) == nullptr) {
      return InvalidArgument("job_limits: unknown job kind '" + name + "'");
    }
    if (Status s = limits.Validate(); !s.ok()) {
      return InvalidArgument("job_limits." + name + "." + s.message());
    }
  }
  return Status::Ok();
}

jobs::KindLimits ServerOptions::LimitsOf(const jobs::JobKindSpec& kind) const {
  auto it = job_limits.find(kind.name);
  return it != job_limits.end() ? it->second : kind.default_limits;
}

Status ServerOptions::SetJobLimit(std::string_view spec) {
  const size_t dot = spec.find('.');
  const size_t eq = spec.find('=');
  if (dot == std::string_view::npos || eq == std::string_view::npos || eq < dot) {
    return InvalidArgument("job limit '" + std::string(spec) +
                           "': expected KIND.NAME=VALUE, e.g. trace.seconds=3600");
  }
  const std::string kind_name(spec.substr(0, dot));
  const std::string name(spec.substr(dot + 1, eq - dot - 1));
  const std::string value_text(spec.substr(eq + 1));
  const jobs::JobKindSpec* kind = jobs::FindKind(kind_name);
  if (kind == nullptr) {
    return InvalidArgument("job limit '" + std::string(spec) + "': unknown job kind '" + kind_name +
                           "'");
  }
  char* end = nullptr;
  const double value = std::strtod(value_text.c_str(), &end);
  // Bytes up to 2^62: far above any machine, and the conversion to int64_t cannot overflow.
  if (value_text.empty() || *end != '\0' || !(value >= 0) || !(value <= 4.6e18)) {
    return InvalidArgument("job limit '" + std::string(spec) +
                           "': the value must be a number in [0, 4.6e18]");
  }
  jobs::KindLimits limits = LimitsOf(*kind);
  if (name == "seconds") {
    limits.max_seconds = value;
  } else if (name == "result-bytes") {
    limits.max_result_bytes = static_cast<int64_t>(value);
  } else if (name == "memory-bytes") {
    limits.max_memory_bytes = static_cast<int64_t>(value);
  } else {
    return InvalidArgument("job limit '" + std::string(spec) + "': unknown limit '" + name +
                           "' (seconds, result-bytes, memory-bytes)");
  }
  job_limits[kind_name] = limits;
  return Status::Ok();
}

// Whether `host` is a loopback address (only this machine can connect).
bool IsLoopback(const std::string& host) {
  return host == "localhost" || host == "::1" || host == "[::1]" || host.rfind("127.", 0) == 0;
}

struct Server::Impl {
  explicit Impl(const MetricsOptions& metrics_options) : metrics(metrics_options) {}

  ServiceState state;
  Metrics metrics;
  std::unique_ptr<JobStore> store;
  std::unique_ptr<WatchHub> hub;
  std::unique_ptr<WorkerPool> pool;
  // A shared store's change feed: other processes' changes wake the hub and the workers. After
  // hub and pool, so that it stops before they go.
  std::unique_ptr<JobChangeFeed> feed;
  // Set once hub and pool exist: the feed's thread may call OnChange before.
  std::atomic<bool> feed_targets_ready{false};
  std::unique_ptr<BoundedExecutor> executor;
  std::unique_ptr<JobsService> jobs;
  std::unique_ptr<OperationsService> operations;
  std::unique_ptr<grpc::Server> grpc_server;
  std::unique_ptr<RestGateway> rest;
  int port = 0;
  // The maintenance thread: the store's health (probed while it reports a fault; the health
  // service says NOT_SERVING meanwhile) and retention (evictions).
  std::thread maintenance;
  bool serving = true;  // what the health service says now (maintenance thread only)

  std::mutex mutex;
  std::condition_variable cv;
  bool shutdown_started = false;
  bool shutdown_done = false;

  void SetServing(bool serving_now) {
    if (serving_now == serving) return;
    serving = serving_now;
    grpc_server->GetHealthCheckService()->SetServingStatus(serving_now);
  }

  // Runs until Shutdown: every store_probe_ms, the store's health (and a probe while it is
  // faulty); every retention_interval_ms, an eviction.
  void Maintain() {
    const ServerOptions& o = state.options;
    auto next_eviction = std::chrono::steady_clock::now();
    std::unique_lock<std::mutex> lock(mutex);
    while (!shutdown_started) {
      lock.unlock();
      Status health = store->Health();
      if (!health.ok() && store->Probe().ok()) health = store->Health();
      if (!health.ok() && serving) spdlog::error("job store fault: {}", health.ToString());
      if (health.ok() && !serving) spdlog::info("job store recovered");
      if (!state.shutting_down.load()) SetServing(health.ok());
      if (health.ok() && std::chrono::steady_clock::now() >= next_eviction) {
        Evict();
        next_eviction =
            std::chrono::steady_clock::now() + std::chrono::milliseconds(o.retention_interval_ms);
      }
      lock.lock();
      cv.wait_for(lock, std::chrono::milliseconds(o.store_probe_ms),
                  [this] { return shutdown_started; });
    }
  }

  void Evict() {
    const int64_t now_ms = std::chrono::duration_cast<std::chrono::milliseconds>(
                               std::chrono::system_clock::now().time_since_epoch())
                               .count();
    StatusOr<EvictionReport> report = store->Evict(state.options.retention, now_ms);
    if (!report.ok()) {
      spdlog::warn("retention: eviction failed: {}", report.status().ToString());
      return;
    }
    metrics.CountEvictions(report->jobs_deleted,
                           report->used_bytes_before - report->used_bytes_after);
    if (report->jobs_deleted > 0) {
      spdlog::info("retention: evicted {} jobs and {} results, store {} -> {} bytes",
                   report->jobs_deleted, report->results_deleted, report->used_bytes_before,
                   report->used_bytes_after);
      // Evicted optimum results must not be answered from memory any more.
      if (Status s = state.optimum_index.Load(*store); !s.ok()) {
        spdlog::warn("retention: the optimum index was not reloaded: {}", s.ToString());
      }
      state.map_index.Clear();  // reloaded by the next query that needs a map
    }
  }

  // A change another process (or this one) made, from the store's change feed.
  void OnChange(const JobChange& change) {
    if (!feed_targets_ready.load(std::memory_order_acquire)) return;
    switch (change.kind) {
      case JobChange::Kind::kQueued:
        pool->Wake();
        hub->NotifyJob(change.id);
        break;
      case JobChange::Kind::kChanged:
        hub->NotifyJob(change.id);
        break;
      case JobChange::Kind::kResync:
        // Notices were lost: a job may be waiting, a watched job may have moved.
        pool->Wake();
        hub->Notify();
        break;
    }
  }

  StatusOr<std::string> RenderMetrics() {
    MetricsSnapshot snapshot;
    StatusOr<StoreStats> stats = store->Stats();
    if (!stats.ok()) return stats.status();
    snapshot.stats = *stats;
    snapshot.store_healthy = store->Health().ok();
    snapshot.engine_runs = pool->engine_runs();
    snapshot.watchers = hub->size();
    return metrics.Render(snapshot);
  }
};

Server::Server(std::unique_ptr<Impl> impl) : impl_(std::move(impl)) {}

Server::~Server() { Shutdown(); }

StatusOr<std::unique_ptr<Server>> Server::Start(const ServerOptions& options) {
  if (Status s = options.Validate(); !s.ok()) return s;
  auto impl = std::make_unique<Impl>(options.metrics);
  impl->state.options = options;
  if (impl->state.options.workers == 0) {
    impl->state.options.workers = Cores();
  }
  const ServerOptions& o = impl->state.options;
  StatusOr<TokenSet> tokens = TokenSet::Load(o.token, o.tokens_file);
  if (!tokens.ok()) return tokens.status();
  impl->state.tokens = std::make_shared<const TokenSet>(std::move(tokens).value());
  if (impl->state.tokens->empty() && !IsLoopback(o.host) && !o.allow_unauthenticated) {
    return InvalidArgument("host: listening on " + o.host +
                           " without a token would let anyone who can reach it run jobs; give "
                           "--token or --tokens-file (or --allow-unauthenticated)");
  }

  StatusOr<std::unique_ptr<JobStore>> store = OpenStore(o);
  if (!store.ok()) return store.status();
  impl->store = std::move(store).value();
  if (o.store_uri.empty()) {
    // This process owns the file: every RUNNING job was interrupted by the end of the last one.
    // (A shared store's jobs are taken back by lease instead: others may be running them.)
    StatusOr<RecoveryReport> recovered = impl->store->RecoverAfterRestart();
    if (!recovered.ok()) return recovered.status();
    spdlog::info("store {}: recovered {} requeued, {} cancelled, {} failed", o.db_path,
                 recovered->requeued, recovered->cancelled, recovered->failed);
  }
  if (Status s = impl->state.optimum_index.Load(*impl->store); !s.ok()) return s;

  Impl* raw = impl.get();
  if (!o.store_uri.empty()) {
    StatusOr<std::unique_ptr<JobChangeFeed>> feed =
        impl->store->OpenChangeFeed([raw](const JobChange& change) { raw->OnChange(change); });
    if (feed.ok()) {
      impl->feed = std::move(feed).value();
    } else {
      spdlog::warn(
          "job store: no change feed ({}): other processes' changes are seen by polling, the "
          "watch hub every {} ms and idle workers every 50 ms",
          feed.status().ToString(), o.watch_poll_ms);
    }
  }
  // With the feed, the polls are a safety net (for what a notice cannot say, and a feed that
  // is reconnecting); 1 s bounds a WaitOperation timeout's delay.
  const int watch_poll_ms = impl->feed ? std::max(o.watch_poll_ms, 1000) : o.watch_poll_ms;
  impl->hub = std::make_unique<WatchHub>(impl->store.get(), watch_poll_ms);
  WorkerPoolOptions pool_options;
  pool_options.workers = o.workers;
  pool_options.short_workers = o.short_workers;
  pool_options.progress_interval_ms = o.progress_interval_ms;
  pool_options.lease_ms = o.store_uri.empty() ? 0 : o.lease_ms;
  pool_options.trace_fan_out = o.store_uri.empty() ? 0 : o.trace_fan_out;
  pool_options.trace_fan_out_batch = o.trace_fan_out_batch;
  // With a shared store, submits by other processes (a trace's tasks among them) wake the
  // workers here through the change feed; without the feed nothing does, and an idle worker
  // looks every 50 ms instead of 500, so that a fanned-out trace's tasks wait ~25 ms for it
  // rather than ~250; each look is one claim query (~0.5 ms on PostgreSQL).
  if (!o.store_uri.empty() && !impl->feed) pool_options.idle_poll_ms = 50;
  if (!o.store_uri.empty()) {
    // Worker ids in a shared store name the machine and the process that claimed.
    char host[256] = {};
    gethostname(host, sizeof(host) - 1);
    pool_options.worker_prefix = std::string(host) + "-" + std::to_string(getpid()) + "-worker";
  }
  for (const jobs::JobKindSpec* kind : jobs::AllKinds()) {
    pool_options.limits[kind->name] = o.LimitsOf(*kind);
  }
  impl->pool = std::make_unique<WorkerPool>(
      impl->store.get(), impl->hub.get(), pool_options,
      [raw](const std::string& id, const std::string& key) {
        raw->state.optimum_index.Add(key, id);
      },
      [raw](const JobRecord& job, std::string_view outcome, double seconds) {
        raw->metrics.ObserveJob(job.kind, outcome, seconds);
        if (outcome == "succeeded" && job.kind == jobs::FindKind(v1::OPTIMUM_MAP)->name) {
          raw->state.map_index.MarkStale();
        }
      });
  impl->feed_targets_ready.store(true, std::memory_order_release);
  impl->executor = std::make_unique<BoundedExecutor>(o.executor);
  impl->state.store = impl->store.get();
  impl->state.hub = impl->hub.get();
  impl->state.pool = impl->pool.get();
  impl->state.executor = impl->executor.get();
  impl->state.metrics = &impl->metrics;
  impl->jobs = std::make_unique<JobsService>(&impl->state);
  impl->operations = std::make_unique<OperationsService>(&impl->state);

  // Process-wide switches, read by the builder: idempotent.
  grpc::EnableDefaultHealthCheckService(true);
  grpc::reflection::InitProtoReflectionServerBuilderPlugin();
  grpc::ServerBuilder builder;
  const std::string address = o.host + ":" + std::to_string(o.grpc_port);
  StatusOr<std::shared_ptr<grpc::ServerCredentials>> credentials = GrpcCredentialsOf(o);
  if (!credentials.ok()) {
    impl->executor->Stop();
    impl->hub->Stop();
    return credentials.status();
  }
  builder.AddListeningPort(address, *credentials, &impl->port);
  builder.SetMaxReceiveMessageSize(o.max_request_bytes);
  if (o.role != ServerOptions::Role::kWorker) {
    builder.RegisterService(impl->jobs.get());
    builder.RegisterService(impl->operations.get());
  }
  std::vector<std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface>> interceptors;
  interceptors.push_back(MakeGrpcMetricsInterceptor(&impl->metrics));
  builder.experimental().SetInterceptorCreators(std::move(interceptors));
  impl->grpc_server = builder.BuildAndStart();
  if (impl->grpc_server == nullptr || impl->port == 0) {
    impl->executor->Stop();
    impl->hub->Stop();
    return Status(StatusCode::kUnavailable, "cannot listen on " + address);
  }

  // REST: the same services through an in-process channel (no socket, no second copy of the
  // logic). Results can be larger than gRPC's default 4 MB receive limit; the HTTP client reads
  // them whole anyway.
  RestOptions rest = RestOptionsOf(o);
  rest.tokens = impl->state.tokens;
  grpc::ChannelArguments channel_args;
  channel_args.SetMaxReceiveMessageSize(-1);
  StatusOr<std::unique_ptr<RestGateway>> gateway =
      RestGateway::Start(rest, impl->grpc_server->InProcessChannel(channel_args), &impl->metrics,
                         [raw] { return raw->RenderMetrics(); });
  if (!gateway.ok()) {
    impl->grpc_server->Shutdown(std::chrono::system_clock::now());
    impl->executor->Stop();
    impl->hub->Stop();
    impl->grpc_server->Wait();
    return gateway.status();
  }
  impl->rest = std::move(gateway).value();

  impl->grpc_server->GetHealthCheckService()->SetServingStatus(true);
  if (o.role != ServerOptions::Role::kApi) impl->pool->Start();
  impl->maintenance = std::thread([raw] { raw->Maintain(); });
  spdlog::info("drillbif-server: gRPC on {}:{}, HTTP on {}:{} (role {}, {} workers, store {})",
               o.host, impl->port, o.host, impl->rest->port(), RoleName(o.role),
               o.role == ServerOptions::Role::kApi ? 0 : o.workers,
               o.store_uri.empty() ? o.db_path : "PostgreSQL");
  return std::unique_ptr<Server>(new Server(std::move(impl)));
}

int Server::grpc_port() const { return impl_->port; }

std::string Server::grpc_address() const {
  return impl_->state.options.host + ":" + std::to_string(impl_->port);
}

void Server::Shutdown() {
  {
    std::unique_lock<std::mutex> lock(impl_->mutex);
    if (impl_->shutdown_started) {
      impl_->cv.wait(lock, [this] { return impl_->shutdown_done; });
      return;
    }
    impl_->shutdown_started = true;
  }
  impl_->cv.notify_all();  // The maintenance thread ends.
  if (impl_->maintenance.joinable()) impl_->maintenance.join();
  spdlog::info("drillbif-server: shutting down");
  impl_->feed.reset();  // Within ~50 ms (postgres_change_feed.h).
  const auto started = std::chrono::steady_clock::now();
  const auto elapsed_ms = [&started] {
    return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - started)
        .count();
  };
  impl_->state.shutting_down = true;
  impl_->grpc_server->GetHealthCheckService()->SetServingStatus(false);
  // Running jobs stop at their next progress callback and go back to the queue.
  impl_->pool->Shutdown();
  spdlog::info("drillbif-server: workers stopped after {:.0f} ms", elapsed_ms());
  // Open Watch and Wait calls end with UNAVAILABLE (REST event streams with them).
  impl_->hub->Stop();
  // REST requests in progress finish (their calls are answered: no watch waits any more).
  impl_->rest->Stop();
  spdlog::info("drillbif-server: HTTP stopped after {:.0f} ms", elapsed_ms());
  // In-flight unary calls finish on the executor (still running); then gRPC cancels the rest.
  impl_->grpc_server->Shutdown(std::chrono::system_clock::now() + std::chrono::seconds(2));
  spdlog::info("drillbif-server: gRPC stopped after {:.0f} ms", elapsed_ms());
  impl_->executor->Stop();
  impl_->grpc_server->Wait();
  spdlog::info("drillbif-server: stopped after {:.0f} ms", elapsed_ms());
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->shutdown_done = true;
  }
  impl_->cv.notify_all();
}

void Server::Wait() {
  std::unique_lock<std::mutex> lock(impl_->mutex);
  impl_->cv.wait(lock, [this] { return impl_->shutdown_done; });
}

int Server::http_port() const { return impl_->rest->port(); }

int64_t Server::engine_runs() const { return impl_->pool->engine_runs(); }

StatusOr<std::string> Server::MetricsText() { return impl_->RenderMetrics(); }

JobStore& Server::store() { return *impl_->store; }

}  // namespace drillbif::server
