// Prometheus metrics of the server, served at GET /metrics on the HTTP port in the text
// exposition format 0.0.4 (https://prometheus.io/docs/instrumenting/exposition_formats/).
//
// Built on prometheus-cpp's core library (Debian 12: prometheus-cpp-dev, 1.0.1): its Registry
// keeps the process's counters and histograms and its TextSerializer writes the text. Only the
// core library is used: /metrics is served by the REST gateway, not by prometheus-cpp's exposer.
//
// Two kinds of values:
// - State read at scrape time (MetricsSnapshot): jobs by state, queue depth by lane, cache hits,
//   store size and health from the store; engine runs and watchers from the process. These are
//   built afresh from the snapshot by each Render (the "collector" pattern of the Prometheus
//   guide for exporters: values owned by another system are not mirrored into live metrics).
// - Events counted by the process (Metrics): job durations (histogram by kind and outcome), HTTP
//   requests by route and status, gRPC requests by method and code (a server interceptor; the
//   REST gateway's own calls through the in-process channel are counted there too), admission
//   refusals, and evictions from the store.
//
// Names (docs/service.md lists them with their meaning):
//   drillbif_jobs{state}                                      gauge
//   drillbif_queue_depth{lane}                                gauge
//   drillbif_cache_hits_total                                 counter (the store's, monotonic)
//   drillbif_engine_runs_total                                counter (this process)
//   drillbif_watchers                                         gauge
//   drillbif_store_healthy                                    gauge (1 healthy, 0 not)
//   drillbif_store_bytes                                      gauge
//   drillbif_job_duration_seconds{kind,outcome}               histogram (this process)
//   drillbif_http_requests_total{method,route,code}           counter (this process)
//   drillbif_grpc_requests_total{method,code}                 counter (this process)
//   drillbif_jobs_refused_total{kind,reason}                  counter (this process)
//   drillbif_store_evicted_jobs_total                         counter (this process)
//   drillbif_store_evicted_bytes_total                        counter (this process)
//
// Label values stay bounded: HTTP methods other than the standard ones, HTTP statuses outside
// 100..599 and gRPC methods that no compiled-in service declares are counted as "other".
#ifndef DRILLBIF_SERVER_METRICS_H_
#define DRILLBIF_SERVER_METRICS_H_

#include <grpcpp/support/server_interceptor.h>

#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "drillbif/common/status.h"
#include "server/store/job_store.h"

namespace drillbif::server {

// How the metrics are kept.
struct MetricsOptions {
  // Upper bounds of the job duration histogram's buckets, in seconds, strictly increasing and
  // finite (+Inf is always added). From 10 ms (a cached or tiny simulation) to 1 h (a large
  // trace): jobs span five decades, so roughly three buckets per decade.
  std::vector<double> job_duration_buckets = {0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1,   2.5,
                                              5,    10,    25,   60,  150,  300, 900, 3600};

  // INVALID_ARGUMENT naming the field when the buckets are empty, not finite, not positive or
  // not increasing.
  Status Validate() const;
};

// The values read at scrape time.
struct MetricsSnapshot {
  // The store's counts: jobs by state, queue depth by lane, cache hits, used bytes.
  StoreStats stats;
  // Job runs started by this process's worker pool (WorkerPool::engine_runs).
  int64_t engine_runs = 0;
  // Calls waiting on jobs in the watch hub (Watch streams, WaitOperation, QueryOptimum).
  int64_t watchers = 0;
  // Whether the store can currently write (JobStore::Health().ok()). False by default so that a
  // snapshot that forgot to ask reports a fault rather than hiding one.
  bool store_healthy = false;
};

// The counters and histograms of one server process, in a prometheus-cpp Registry. Thread-safe:
// events and Render may run concurrently from any thread. An event costs a lookup of its label
// set under the family's mutex and an atomic add, small beside the RPC that caused it.
class Metrics {
 public:
  // `options` must be valid (the caller checks Validate()).
  explicit Metrics(MetricsOptions options = {});
  ~Metrics();
  Metrics(const Metrics&) = delete;
  Metrics& operator=(const Metrics&) = delete;

  // A job run of `kind` ("simulate", ...) ended after `seconds` with `outcome` ("succeeded",
  // "failed", "cancelled", "requeued", "deadline_exceeded", ...; any string from a fixed set of
  // the caller's). A negative or non-finite `seconds` (a clock fault) is counted as 0 so that
  // the sum stays a number.
  void ObserveJob(std::string_view kind, std::string_view outcome, double seconds);

  // An HTTP request answered with `status`. `route` is the route template
  // ("/v1/{name=operations/*}:result") or "other" for paths no route serves, so that the
  // number of series stays bounded. A method other than GET, HEAD, POST, PUT, DELETE, PATCH and
  // OPTIONS, and a status outside 100..599, are counted as "other".
  void CountHttpRequest(std::string_view method, std::string_view route, int status);

  // A gRPC call of `method` ("/drillbif.v1.Jobs/SubmitSweep") ended with `code`. A method that
  // no service linked into the process declares (a client may send any path) is counted as
  // "other"; gRPC's own health service counts under its name.
  void CountGrpcRequest(std::string_view method, int code);

  // A submit of `kind` ("simulate", ...) refused at admission for `reason` ("invalid_argument",
  // "resource_exhausted", "queue_full", ...; a fixed set of the caller's).
  void CountAdmissionRefusal(std::string_view kind, std::string_view reason);

  // Retention evicted `jobs` jobs and `bytes` bytes of the store's data. Negative values are
  // ignored (a counter never decreases).
  void CountEvictions(int64_t jobs, int64_t bytes);

  // The whole exposition: the snapshot's gauges and counters, then this object's counters and
  // histograms (families with no event yet are left out). Every family has its # HELP and
  // # TYPE lines, its samples sorted by labels; the text ends with a newline.
  std::string Render(const MetricsSnapshot& snapshot) const;

 private:
  struct Families;  // The registry and its families (prometheus-cpp types, kept out of here).

  const MetricsOptions options_;
  const std::unique_ptr<Families> families_;
};

// The Content-Type of the exposition.
inline constexpr char kMetricsContentType[] = "text/plain; version=0.0.4; charset=utf-8";

// The gRPC code's canonical name ("INVALID_ARGUMENT"); "UNKNOWN" for a number outside 0..16.
const char* GrpcCodeName(int code);

// A gRPC server interceptor factory that counts every call's final status in `metrics`
// (Metrics::CountGrpcRequest). `metrics` must outlive the server.
std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> MakeGrpcMetricsInterceptor(
    Metrics* metrics);

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_METRICS_H_
