// drillbif-server: the service binary (flags in docs/service.md).
//
//   drillbif-server --grpc-port 50051 --http-port 8080 --db drillbif.db [--workers N] [--token T]
//                   [--config FILE]
//
// SIGTERM and SIGINT shut it down gracefully (Server::Shutdown); it exits 0 once done, or 3 when
// the shutdown did not finish within --shutdown-grace-ms or a second signal came first. The
// signals are blocked in every thread and taken by sigwait, so no work happens in a signal
// handler.
#include <signal.h>
#include <spdlog/spdlog.h>

#include <CLI/CLI.hpp>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <string>
#include <thread>
#include <vector>

#include "server/json_log.h"
#include "server/server.h"

int main(int argc, char** argv) {
  drillbif::server::ServerOptions options;
  std::string port_file;
  std::string log_level = "info";

  CLI::App app("drillbif-server: the drillbif computation service (gRPC, REST, /metrics)");
  app.set_config("--config", "", "Read flags from this TOML/INI file (flag names as keys)");
  app.add_option("--host", options.host, "Address to bind")->capture_default_str();
  app.add_option("--grpc-port", options.grpc_port, "gRPC port; 0 picks a free port")
      ->capture_default_str();
  app.add_option("--http-port", options.http_port,
                 "HTTP port: REST (JSON, Server-Sent Events) and /metrics; 0 picks a free port")
      ->capture_default_str();
  app.add_option("--http-threads", options.http_threads,
                 "HTTP event-loop threads (no waiting request or event stream holds one)")
      ->capture_default_str();
  // HTTP limits (RestOptions documents each default and its reason).
  drillbif::server::RestOptions& http = options.http;
  app.add_option("--http-connection-limit", http.connection_limit,
                 "Concurrent HTTP connections (lowered to fit RLIMIT_NOFILE)")
      ->capture_default_str();
  app.add_option("--http-listen-backlog", http.listen_backlog, "HTTP listen(2) backlog")
      ->capture_default_str();
  app.add_option("--http-connection-memory-bytes", http.connection_memory_bytes,
                 "Memory of one HTTP connection (request line, headers, buffers)")
      ->capture_default_str();
  app.add_option("--http-max-uri-bytes", http.max_uri_bytes, "Longest request target (else 414)")
      ->capture_default_str();
  app.add_option("--http-max-header-bytes", http.max_header_bytes,
                 "Longest request line and headers (else 431)")
      ->capture_default_str();
  app.add_option("--http-max-header-count", http.max_header_count,
                 "Most header fields in a request (else 431)")
      ->capture_default_str();
  app.add_option("--http-idle-timeout-ms", http.idle_timeout_ms,
                 "Close an HTTP connection with no byte read or written for this long")
      ->capture_default_str();
  app.add_option("--http-request-timeout-ms", http.request_timeout_ms,
                 "A whole HTTP request must arrive within this time")
      ->capture_default_str();
  app.add_option("--http-write-timeout-ms", http.write_timeout_ms,
                 "An HTTP answer must be taken by the socket within this time")
      ->capture_default_str();
  app.add_option("--cors-origins", http.cors_origins,
                 "Browser origins allowed to call the REST API (CORS), comma-separated, each "
                 "exact scheme://host[:port] (e.g. https://dash.example.com), or * alone for any "
                 "origin (never with credentials: no cookies are allowed, the token goes in the "
                 "Authorization header); none: no CORS headers")
      ->delimiter(',');
  app.add_option("--tls-cert", options.tls_cert_file,
                 "PEM certificate (chain): both ports use TLS (with --tls-key)");
  app.add_option("--tls-key", options.tls_key_file, "PEM private key of --tls-cert");
  app.add_option("--db", options.db_path, "SQLite file of the job store")->capture_default_str();
  app.add_option("--store", options.store_uri,
                 "A PostgreSQL job store shared by several server processes: a libpq URI "
                 "postgresql://USER@HOST:PORT/DB (without the password); replaces --db");
  app.add_option("--store-password-file", options.store_password_file,
                 "File whose first line is the PostgreSQL password (else PGPASSWORD or "
                 "~/.pgpass)");
  std::string role = "all";
  app.add_option("--role", role,
                 "all: serve the API and run jobs; api: serve the API only; worker: run jobs, "
                 "serve health and /metrics only (api and worker need --store)")
      ->check(CLI::IsMember({"all", "api", "worker"}))
      ->capture_default_str();
  app.add_option("--lease-ms", options.lease_ms,
                 "With --store: a worker that has not renewed a job's lease for this long "
                 "loses it to the others")
      ->capture_default_str();
  app.add_option("--watch-poll-ms", options.watch_poll_ms,
                 "Longest time between two reads of the jobs that Watch and WaitOperation calls "
                 "wait on (this process's own changes are delivered at once). With --store, "
                 "while the store's change feed (PostgreSQL LISTEN/NOTIFY) is up, other "
                 "processes' changes are too, and the hub polls every max(this, 1000) ms and "
                 "idle workers every 500 ms; without it, both every this/50 ms")
      ->capture_default_str();
  app.add_option("--trace-fan-out", options.trace_fan_out,
                 "With --store: the tasks of a trace (and of an optimum's trace) stored ahead as "
                 "child jobs for every worker process to run, e.g. 32 (pays for period-2 traces "
                 "on several workers); 0: a trace runs on the threads of its worker")
      ->capture_default_str();
  app.add_option("--trace-fan-out-batch", options.trace_fan_out_batch,
                 "With --trace-fan-out: the trace's tasks in one child job (1 .. 64); a child "
                 "costs a few ms of store calls, paid once for its batch")
      ->capture_default_str();
  app.add_option("--workers", options.workers, "Worker threads; 0: one per core")
      ->capture_default_str();
  app.add_option("--token", options.token,
                 "Bearer token required on every Jobs and Operations rpc, as the client "
                 "'default' (empty: none; prefer --tokens-file: a flag shows in ps)");
  app.add_option("--tokens-file", options.tokens_file,
                 "File of 'NAME TOKEN' lines, one client each (fair claims, per-client queue "
                 "limit); e.g. a Kubernetes Secret mounted as a file");
  app.add_flag("--allow-unauthenticated", options.allow_unauthenticated,
               "Allow listening on a non-loopback address without any token");
  app.add_option("--short-workers", options.short_workers,
                 "Worker threads that run short jobs only (a short job never waits behind long "
                 "ones)")
      ->capture_default_str();
  app.add_option("--short-job-seconds", options.short_job_seconds,
                 "Jobs estimated at most this long go to the short lane")
      ->capture_default_str();
  app.add_option("--max-queued-per-client", options.max_queued_per_client,
                 "Submits of one client are refused while this many of its jobs wait (0: none)")
      ->capture_default_str();
  app.add_option("--max-inline-result-bytes", options.max_inline_result_bytes,
                 "Operations carry results up to this size whole, else their summary")
      ->capture_default_str();
  app.add_option("--retention-max-age-ms", options.retention.max_age_ms,
                 "Finished jobs older than this are evicted (0: no age limit)")
      ->capture_default_str();
  app.add_option("--retention-max-db-bytes", options.retention.max_db_bytes,
                 "Finished jobs are evicted, oldest first, while the store's data is larger "
                 "(0: no size limit)")
      ->capture_default_str();
  int shutdown_grace_ms = 10000;
  app.add_option("--shutdown-grace-ms", shutdown_grace_ms,
                 "After SIGTERM, exit at the latest after this long even if a job has not "
                 "stopped (it is requeued at the next start)")
      ->capture_default_str();
  app.add_option("--max-request-bytes", options.max_request_bytes,
                 "Largest request accepted (gRPC message, REST body)")
      ->capture_default_str();
  app.add_option("--max-queued-jobs", options.max_queued_jobs,
                 "Submits are refused while this many jobs wait")
      ->capture_default_str();
  std::vector<std::string> job_limits;
  app.add_option("--job-limit", job_limits,
                 "A job kind's limit, KIND.NAME=VALUE (repeatable): NAME seconds, result-bytes or "
                 "memory-bytes, e.g. --job-limit trace.seconds=3600 (docs/service.md lists the "
                 "defaults)");
  app.add_option("--port-file", port_file,
                 "Write the ports chosen to this file once serving: the gRPC port on the first "
                 "line, the HTTP port on the second (for port 0)");
  app.add_option("--log-level", log_level, "trace, debug, info, warn, error")
      ->capture_default_str();
  std::string log_format = "text";
  app.add_option("--log-format", log_format,
                 "text, or json: one JSON object per line (time, level, thread, msg)")
      ->check(CLI::IsMember({"text", "json"}))
      ->capture_default_str();
  CLI11_PARSE(app, argc, argv);

  options.role = role == "api"      ? drillbif::server::ServerOptions::Role::kApi
                 : role == "worker" ? drillbif::server::ServerOptions::Role::kWorker
                                    : drillbif::server::ServerOptions::Role::kAll;
  for (const std::string& limit : job_limits) {
    if (drillbif::Status s = options.SetJobLimit(limit); !s.ok()) {
      std::fprintf(stderr, "invalid options: %s\n", s.message().c_str());
      return 2;
    }
  }
  spdlog::set_level(spdlog::level::from_str(log_level));
  if (log_format == "json") spdlog::set_formatter(drillbif::server::JsonLogFormatter());
  if (drillbif::Status s = options.Validate(); !s.ok()) {
    spdlog::error("invalid options: {}", s.ToString());
    return 2;
  }

  // Block the shutdown signals before any thread starts, so that every thread inherits the mask
  // and only sigwait below receives them.
  sigset_t signals;
  sigemptyset(&signals);
  sigaddset(&signals, SIGTERM);
  sigaddset(&signals, SIGINT);
  pthread_sigmask(SIG_BLOCK, &signals, nullptr);

  auto server = drillbif::server::Server::Start(options);
  if (!server.ok()) {
    spdlog::error("cannot start: {}", server.status().ToString());
    return 1;
  }
  spdlog::info("serving gRPC on {}, HTTP on {}:{}", (*server)->grpc_address(), options.host,
               (*server)->http_port());
  if (!port_file.empty()) {
    // Written to a temporary name and renamed, so a reader never sees a partial file.
    const std::string tmp = port_file + ".tmp";
    std::ofstream(tmp) << (*server)->grpc_port() << "\n" << (*server)->http_port() << "\n";
    std::rename(tmp.c_str(), port_file.c_str());
  }

  int received = 0;
  sigwait(&signals, &received);
  spdlog::info("signal {} received", received);
  // A second signal (an operator's second Ctrl-C or kill) cuts the graceful shutdown short. The
  // signals stay blocked in every thread, so this sigwait takes it even if it came already.
  std::thread([signals] {
    int again = 0;
    sigwait(&signals, &again);
    spdlog::warn(
        "signal {} received again; exiting now (running jobs are requeued at the next "
        "start)",
        again);
    spdlog::default_logger()->flush();
    std::_Exit(3);
  }).detach();
  // A watchdog: running jobs stop within milliseconds (their engines check for it), but whatever
  // happens the process ends within the grace period; the store recovers what was running.
  std::thread([shutdown_grace_ms] {
    std::this_thread::sleep_for(std::chrono::milliseconds(shutdown_grace_ms));
    spdlog::error(
        "shutdown did not finish within {} ms; exiting now (running jobs are requeued "
        "at the next start)",
        shutdown_grace_ms);
    spdlog::default_logger()->flush();
    std::_Exit(3);
  }).detach();
  (*server)->Shutdown();
  return 0;
}
