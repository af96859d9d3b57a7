// Prometheus metrics of the server, served at GET /metrics on the HTTP port in the text
// exposition format 0.0.4 (https://prometheus.io/docs/instrumenting/exposition_formats/).
//
// Written by hand: prometheus-cpp is not packaged in Debian 12, and the server needs only a few
// counters, one histogram family and gauges read at scrape time, which this file renders.
//
// Two kinds of values:
// - State read at scrape time (MetricsSnapshot): jobs by state, queue depth and the cache hits
//   from the store's Stats (one read transaction), engine runs and watchers from the process.
// - Events counted by the process (Metrics): job durations (histogram by kind and outcome), HTTP
//   requests by route and status, gRPC requests by method and code (a server interceptor; the
//   REST gateway's own calls through the in-process channel are counted there too).
//
// Names (docs/service.md lists them with their meaning):
//   drillbif_jobs{state}                                      gauge
//   drillbif_queue_depth                                      gauge
//   drillbif_cache_hits_total                                 counter (the store's, monotonic)
//   drillbif_engine_runs_total                                counter (this process)
//   drillbif_watchers                                         gauge
//   drillbif_job_duration_seconds{kind,outcome}               histogram (this process)
//   drillbif_http_requests_total{method,route,code}           counter (this process)
//   drillbif_grpc_requests_total{method,code}                 counter (this process)
#ifndef DRILLBIF_SERVER_METRICS_H_
#define DRILLBIF_SERVER_METRICS_H_

#include <grpcpp/support/server_interceptor.h>

#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <tuple>
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
  // The store's counts (jobs by state, queue depth, cache hits).
  StoreStats stats;
  // Job runs started by this process's worker pool (WorkerPool::engine_runs).
  int64_t engine_runs = 0;
  // Calls waiting on jobs in the watch hub (Watch streams, WaitOperation, QueryOptimum).
  int64_t watchers = 0;
};

// The counters and histograms of one server process. Thread-safe; each event costs one mutex
// and a map lookup, which is small beside the RPC that caused it.
class Metrics {
 public:
  // `options` must be valid (the caller checks Validate()).
  explicit Metrics(MetricsOptions options = {});

  // A job run of `kind` ("simulate", ...) ended after `seconds` with `outcome` ("succeeded",
  // "failed", "cancelled", "requeued").
  void ObserveJob(std::string_view kind, std::string_view outcome, double seconds);

  // An HTTP request answered with `status`. `route` is the route template
  // ("/v1/{name=operations/*}:result") or "other" for paths no route serves, so that the
  // number of series stays bounded.
  void CountHttpRequest(std::string_view method, std::string_view route, int status);

  // A gRPC call of `method` ("/drillbif.v1.Jobs/SubmitSweep") ended with `code`.
  void CountGrpcRequest(std::string_view method, int code);

  // The whole exposition: the snapshot's gauges and counters, then this object's families.
  // Every family has its # HELP and # TYPE lines; the text ends with a newline.
  std::string Render(const MetricsSnapshot& snapshot) const;

 private:
  struct Histogram {
    std::vector<int64_t> counts;  // Per bucket (not cumulative), the last one for +Inf.
    double sum = 0;
    int64_t count = 0;
  };

  const MetricsOptions options_;
  mutable std::mutex mutex_;
  std::map<std::pair<std::string, std::string>, Histogram> jobs_;      // kind, outcome
  std::map<std::tuple<std::string, std::string, int>, int64_t> http_;  // method, route
  std::map<std::pair<std::string, int>, int64_t> grpc_;                // method, code
};

// The Content-Type of the exposition.
inline constexpr char kMetricsContentType[] = "text/plain; version=0.0.4; charset=utf-8";

// A label value escaped for the text format (backslash, double quote and newline).
std::string EscapeLabelValue(std::string_view value);

// A sample value in the text format: integers without a decimal point, "+Inf", "-Inf", "NaN",
// other values with the digits to read them back exactly.
std::string FormatSampleValue(double value);

// The gRPC code's canonical name ("INVALID_ARGUMENT"); "UNKNOWN" for a number outside 0..16.
const char* GrpcCodeName(int code);

// A gRPC server interceptor factory that counts every call's final status in `metrics`
// (Metrics::CountGrpcRequest). `metrics` must outlive the server.
std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> MakeGrpcMetricsInterceptor(
    Metrics* metrics);

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_METRICS_H_
