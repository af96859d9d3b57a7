// The drillbif server: the gRPC services (drillbif.v1.Jobs and google.longrunning.Operations,
// proto/drillbif/v1/service.proto), health checking (grpc.health.v1) and server reflection on
// one port, the same API as JSON (REST, with progress as Server-Sent Events) and Prometheus
// metrics on a second port, over the SQLite job store, a bounded executor for the RPCs' store
// work, a worker pool for the engine and a watch hub for progress. docs/service.md describes the
// whole.
//
//   auto server = Server::Start(options);      // recovers the store, starts serving
//   ... (*server)->grpc_port(), (*server)->http_port() ...
//   (*server)->Shutdown();                     // graceful: NOT_SERVING, requeue, stop
#ifndef DRILLBIF_SERVER_SERVER_H_
#define DRILLBIF_SERVER_SERVER_H_

#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <string_view>

#include "drillbif/common/status.h"
#include "jobs/job_cost.h"
#include "jobs/registry.h"
#include "server/executor.h"
#include "server/metrics.h"
#include "server/rest_gateway.h"
#include "server/store/job_store.h"
#include "server/stored_results.h"

namespace drillbif::server {

// Everything the server can be configured with (the flags of drillbif-server).
struct ServerOptions {
  // Address to bind. 127.0.0.1 by default: the service is local unless asked otherwise.
  std::string host = "127.0.0.1";
  // gRPC port; 0 picks a free port (Server::grpc_port() tells which).
  int grpc_port = 50051;
  // HTTP port of the REST gateway and /metrics; 0 picks a free port (Server::http_port() tells
  // which).
  int http_port = 8080;
  // HTTP event-loop threads (RestOptions::threads): they move bytes and convert JSON; no REST
  // call or event stream holds one while it waits.
  int http_threads = 2;
  // HTTP limits and timeouts (RestOptions: connections, backlog, header and body sizes, idle,
  // read and write deadlines). Its host, port, token, max_body_bytes, threads and TLS files are
  // ignored: the fields of this struct set them.
  RestOptions http;
  // PEM files of the server's certificate (chain) and private key, both or neither. Given, both
  // ports use TLS: gRPC with grpc::SslServerCredentials, HTTP serves HTTPS only.
  std::string tls_cert_file;
  // See tls_cert_file.
  std::string tls_key_file;
  // SQLite file of the job store (created if missing), unless store_uri is given.
  std::string db_path = "drillbif.db";
  // A PostgreSQL job store shared by several server processes (a libpq connection URI,
  // postgresql://USER@HOST:PORT/DB?...); empty: the SQLite file db_path, owned by this process.
  // Never holds the password (it would show in the process list): see store_password_file.
  std::string store_uri;
  // A file whose first line is the PostgreSQL password (e.g. a Kubernetes Secret mounted as a
  // file); empty: libpq's own sources (PGPASSWORD, ~/.pgpass) or none.
  std::string store_password_file;
  // What this process does: kAll serves the API and runs jobs; kApi serves the API and runs no
  // jobs; kWorker runs jobs and serves health and /metrics only (its Jobs and Operations rpcs
  // answer UNIMPLEMENTED). Roles other than kAll need a shared store (store_uri).
  enum class Role { kAll, kApi, kWorker };
  Role role = Role::kAll;
  // With a shared store, claims are leases of this many milliseconds (WorkerPoolOptions::
  // lease_ms): a worker that dies or loses the database loses its jobs to the others once it
  // has not renewed them for this long. 15 s: renewed every 5 s (a third), so two renewals may
  // fail before the lease goes; long enough that a database failover or a pause of a few seconds
  // does not take running jobs away, short enough that a crashed worker's jobs start again
  // within about 20 s.
  int64_t lease_ms = 15000;
  // With a shared store, a trace job offers its tasks, up to this many ahead of the one it
  // applies, to every worker process as child jobs (WorkerPoolOptions::trace_fan_out,
  // server/trace_fan_out.h; an optimum's trace too); 0: each trace runs on the threads of the
  // worker that claimed it.
  // Off by default: on this 2-core machine the reference box took 19.0 s fanned out on 1
  // worker and 16.6 s on 2, against 17.7 s not fanned out (docs/scale.md); it is meant for
  // traces of long tasks (period 2) on workers of their own machines. 32 where it is used.
  // Unused with the SQLite file (one process: its threads do the same work without the store).
  int trace_fan_out = 0;
  // The trace's tasks in one child job (WorkerPoolOptions::trace_fan_out_batch): each child costs
  // ~3 ms of store calls, paid once for its batch (docs/scale.md).
  int trace_fan_out_batch = 4;
  // Worker threads running jobs of any cost lane; 0: one per core
  // (std::thread::hardware_concurrency).
  int workers = 0;
  // More worker threads that run short jobs only (WorkerPoolOptions::short_workers), so that a
  // short job never waits behind long ones.
  int short_workers = 1;
  // A job whose estimated time (jobs/job_cost.h) is at most this goes to the short lane.
  // Seconds. 2: a simulation of ~200000 periods, a small sweep or continuation.
  double short_job_seconds = 2.0;
  // Bearer token every Jobs and Operations rpc must carry ("authorization: Bearer <token>"), as
  // the client "default"; empty: none. Health and reflection are always open (probes carry no
  // token).
  std::string token;
  // A file of tokens, one client each ("NAME TOKEN" lines, server/tokens.h), in addition to
  // `token`: clients are told apart for fair claims and max_queued_per_client.
  std::string tokens_file;
  // Listening on an address other than loopback without any token is refused unless this is
  // set: an open port on a network must not run anyone's jobs by accident.
  bool allow_unauthenticated = false;
  // Largest request message accepted, in bytes; a larger one fails with RESOURCE_EXHAUSTED
  // before it is parsed (REST: a larger body, 413). 4 MiB (gRPC's default): requests are
  // parameters, not data.
  int max_request_bytes = 4 << 20;
  // Submits are refused with RESOURCE_EXHAUSTED while this many jobs wait in the store's queue
  // (the bound of the job queue; jobs are persistent, so the bound protects the disk and the
  // latency of the jobs already waiting).
  int max_queued_jobs = 10000;
  // Submits of one client are refused with RESOURCE_EXHAUSTED while this many of its jobs wait,
  // so that one client filling the queue does not refuse everybody else (all callers are one
  // client without tokens). 0: no per-client limit.
  int max_queued_per_client = 1000;
  // Operation.response carries the whole result when it is at most this large, else its
  // summary (JobMetadata.response_summary_only; GetResult pages through the items). Bytes.
  int64_t max_inline_result_bytes = 4 << 20;
  // GetResult's page limits (server/stored_results.h).
  PageOptions pages;
  // Finished jobs older than max_age_ms, or beyond max_db_bytes of data, are evicted, oldest
  // first (JobStore::Evict), every retention_interval_ms. 30 days and 8 GB by default.
  RetentionOptions retention{30LL * 86400 * 1000, 8'000'000'000};
  int retention_interval_ms = 60000;
  // While the store reports a fault, it is probed this often (health turns back to SERVING
  // once a probe succeeds). Milliseconds.
  int store_probe_ms = 1000;
  // Limits of each job kind by name (jobs/job_cost.h): a request estimated above one is refused
  // at submit with RESOURCE_EXHAUSTED naming the field, its value and the limit; a run that
  // reaches its time limit fails with DEADLINE_EXCEEDED, one whose result reaches its size limit
  // with RESOURCE_EXHAUSTED. Kinds not here keep their registry defaults
  // (JobKindSpec::default_limits); SetJobLimit changes one value.
  std::map<std::string, jobs::KindLimits> job_limits;
  // The executor that runs the RPCs' store work (its queue bound gives RESOURCE_EXHAUSTED).
  ExecutorOptions executor;
  // Shortest time between two progress writes of one job (and store cancel polls).
  // Milliseconds. See WorkerPoolOptions.
  int progress_interval_ms = 250;
  // Longest time between two looks of the watch hub at the jobs being watched or waited on.
  // Milliseconds. Changes made by this process are delivered at once anyway; this bounds the
  // delay of timeouts. With a shared store whose change feed is up (other processes' changes
  // are delivered at once too), the hub looks every max(watch_poll_ms, 1000) ms.
  int watch_poll_ms = 50;
  // The store's PRAGMA synchronous = FULL (see SqliteJobStoreOptions::full_sync).
  bool full_sync = true;
  // Buckets of the job duration histogram (/metrics).
  MetricsOptions metrics;

  // INVALID_ARGUMENT naming the field when a value is out of range.
  Status Validate() const;

  // The limits that apply to `kind`.
  jobs::KindLimits LimitsOf(const jobs::JobKindSpec& kind) const;

  // Sets one limit from "KIND.NAME=VALUE": KIND a job kind (simulate, sweep, continue, trace,
  // optimum), NAME seconds, result-bytes or memory-bytes, VALUE a number >= 0 (0: no limit;
  // "1e9" accepted). INVALID_ARGUMENT saying what is wrong otherwise.
  Status SetJobLimit(std::string_view spec);
};

// A running server. Thread-safe.
class Server {
 public:
  // Opens the store, recovers the jobs of a previous run (RecoverAfterRestart: running jobs are
  // queued again), starts the workers and serves gRPC on host:grpc_port and REST and /metrics on
  // host:http_port. Errors: INVALID_ARGUMENT for bad options; the store's errors; UNAVAILABLE
  // when a port cannot be bound.
  static StatusOr<std::unique_ptr<Server>> Start(const ServerOptions& options);

  // Shutdown().
  ~Server();

  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;

  // The gRPC port bound (the free port picked when grpc_port was 0).
  int grpc_port() const;

  // "host:port" of the gRPC service.
  std::string grpc_address() const;

  // The HTTP port bound (REST and /metrics; the free port picked when http_port was 0).
  int http_port() const;

  // Graceful shutdown: health reports NOT_SERVING, submits fail with UNAVAILABLE, running jobs
  // are interrupted and requeued in the store (they resume at the next start; a job that
  // finishes first is recorded), open Watch and Wait calls end with UNAVAILABLE (REST event
  // streams with an error event), the HTTP port closes after its requests in progress, in-flight
  // RPCs get up to 2 s, then the server stops. Idempotent.
  void Shutdown();

  // Blocks until Shutdown() has been called and completed.
  void Wait();

  // Job runs started by the worker pool (each a call of a job runner): a cache hit adds none.
  int64_t engine_runs() const;

  // The job store (for tests and metrics).
  JobStore& store();

  // The /metrics text now (the store's counts read in one transaction).
  StatusOr<std::string> MetricsText();

 private:
  struct Impl;
  explicit Server(std::unique_ptr<Impl> impl);
  std::unique_ptr<Impl> impl_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_SERVER_H_
