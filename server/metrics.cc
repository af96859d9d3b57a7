#include "server/metrics.h"

#include <algorithm>
#include <array>
#include <charconv>
#include <cmath>
#include <system_error>
#include <utility>

namespace drillbif::server {
namespace {

// The store's states in JobState order, as label values (the API's JobState names).
constexpr std::array<const char*, kJobStateCount> kStateLabels = {"QUEUED", "RUNNING", "SUCCEEDED",
                                                                  "FAILED", "CANCELLED"};

void Family(std::string* out, const char* name, const char* type, const char* help) {
  out->append("# HELP ").append(name).append(" ").append(help).append("\n");
  out->append("# TYPE ").append(name).append(" ").append(type).append("\n");
}

void Sample(std::string* out, std::string_view name, std::string_view labels, double value) {
  out->append(name);
  if (!labels.empty()) out->append("{").append(labels).append("}");
  out->append(" ").append(FormatSampleValue(value)).append("\n");
}

std::string Label(std::string_view name, std::string_view value) {
  std::string s(name);
  s.append("=\"").append(EscapeLabelValue(value)).append("\"");
  return s;
}

// Counts every call's final status (PRE_SEND_STATUS: the status the server is about to send,
// whichever handler or gRPC itself produced it).
class GrpcMetricsInterceptor : public grpc::experimental::Interceptor {
 public:
  GrpcMetricsInterceptor(Metrics* metrics, const char* method)
      : metrics_(metrics), method_(method != nullptr ? method : "") {}

  void Intercept(grpc::experimental::InterceptorBatchMethods* methods) override {
    if (methods->QueryInterceptionHookPoint(
            grpc::experimental::InterceptionHookPoints::PRE_SEND_STATUS)) {
      metrics_->CountGrpcRequest(method_, static_cast<int>(methods->GetSendStatus().error_code()));
    }
    methods->Proceed();
  }

 private:
  Metrics* const metrics_;
  const std::string method_;
};

class GrpcMetricsInterceptorFactory : public grpc::experimental::ServerInterceptorFactoryInterface {
 public:
  explicit GrpcMetricsInterceptorFactory(Metrics* metrics) : metrics_(metrics) {}

  grpc::experimental::Interceptor* CreateServerInterceptor(
      grpc::experimental::ServerRpcInfo* info) override {
    return new GrpcMetricsInterceptor(metrics_, info->method());
  }

 private:
  Metrics* const metrics_;
};

}  // namespace

Status MetricsOptions::Validate() const {
  if (job_duration_buckets.empty()) {
    return InvalidArgument("job_duration_buckets: must not be empty");
  }
  for (size_t i = 0; i < job_duration_buckets.size(); ++i) {
    const double b = job_duration_buckets[i];
    if (!std::isfinite(b) || b <= 0) {
      return InvalidArgument("job_duration_buckets[" + std::to_string(i) +
                             "]: must be finite and > 0");
    }
    if (i > 0 && b <= job_duration_buckets[i - 1]) {
      return InvalidArgument("job_duration_buckets[" + std::to_string(i) +
                             "]: must be larger than the previous bound");
    }
  }
  return Status::Ok();
}

Metrics::Metrics(MetricsOptions options) : options_(std::move(options)) {}

void Metrics::ObserveJob(std::string_view kind, std::string_view outcome, double seconds) {
  const std::vector<double>& bounds = options_.job_duration_buckets;
  // First bucket whose bound is >= seconds (Prometheus buckets are "le"); +Inf otherwise.
  const size_t bucket =
      static_cast<size_t>(std::lower_bound(bounds.begin(), bounds.end(), seconds) - bounds.begin());
  std::lock_guard<std::mutex> lock(mutex_);
  Histogram& h = jobs_[{std::string(kind), std::string(outcome)}];
  if (h.counts.empty()) h.counts.assign(bounds.size() + 1, 0);
  ++h.counts[bucket];
  h.sum += seconds;
  ++h.count;
}

void Metrics::CountHttpRequest(std::string_view method, std::string_view route, int status) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++http_[{std::string(method), std::string(route), status}];
}

void Metrics::CountGrpcRequest(std::string_view method, int code) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++grpc_[{std::string(method), code}];
}

std::string Metrics::Render(const MetricsSnapshot& snapshot) const {
  std::string out;
  out.reserve(4096);
  Family(&out, "drillbif_jobs", "gauge", "Jobs in the store by state.");
  for (int s = 0; s < kJobStateCount; ++s) {
    Sample(&out, "drillbif_jobs", Label("state", kStateLabels[static_cast<size_t>(s)]),
           static_cast<double>(snapshot.stats.jobs_by_state[static_cast<size_t>(s)]));
  }
  Family(&out, "drillbif_queue_depth", "gauge",
         "Queued jobs a worker can claim (not counting jobs that follow an identical one).");
  Sample(&out, "drillbif_queue_depth", "", static_cast<double>(snapshot.stats.queue_depth));
  Family(&out, "drillbif_cache_hits_total", "counter",
         "Jobs that succeeded without running the engine (cache hits and shared runs), over the "
         "store's life.");
  Sample(&out, "drillbif_cache_hits_total", "",
         static_cast<double>(snapshot.stats.cache_hits_total));
  Family(&out, "drillbif_engine_runs_total", "counter",
         "Job runs started on the engine by this process.");
  Sample(&out, "drillbif_engine_runs_total", "", static_cast<double>(snapshot.engine_runs));
  Family(&out, "drillbif_watchers", "gauge",
         "Calls waiting on jobs (Watch streams, WaitOperation, QueryOptimum computing).");
  Sample(&out, "drillbif_watchers", "", static_cast<double>(snapshot.watchers));

  std::lock_guard<std::mutex> lock(mutex_);
  Family(&out, "drillbif_job_duration_seconds", "histogram",
         "Wall time of the job runs of this process, by kind and outcome.");
  for (const auto& [key, h] : jobs_) {
    const std::string labels = Label("kind", key.first) + "," + Label("outcome", key.second);
    int64_t cumulative = 0;
    for (size_t i = 0; i < h.counts.size(); ++i) {
      cumulative += h.counts[i];
      const std::string le = i < options_.job_duration_buckets.size()
                                 ? FormatSampleValue(options_.job_duration_buckets[i])
                                 : std::string("+Inf");
      Sample(&out, "drillbif_job_duration_seconds_bucket", labels + "," + Label("le", le),
             static_cast<double>(cumulative));
    }
    Sample(&out, "drillbif_job_duration_seconds_sum", labels, h.sum);
    Sample(&out, "drillbif_job_duration_seconds_count", labels, static_cast<double>(h.count));
  }
  Family(&out, "drillbif_http_requests_total", "counter",
         "HTTP requests answered by the REST port, by method, route template and status.");
  for (const auto& [key, n] : http_) {
    const auto& [method, route, status] = key;
    Sample(&out, "drillbif_http_requests_total",
           Label("method", method) + "," + Label("route", route) + "," +
               Label("code", std::to_string(status)),
           static_cast<double>(n));
  }
  Family(&out, "drillbif_grpc_requests_total", "counter",
         "gRPC calls ended, by full method name and status code (REST calls included: the gateway "
         "calls the same services).");
  for (const auto& [key, n] : grpc_) {
    Sample(&out, "drillbif_grpc_requests_total",
           Label("method", key.first) + "," + Label("code", GrpcCodeName(key.second)),
           static_cast<double>(n));
  }
  return out;
}

std::string EscapeLabelValue(std::string_view value) {
  std::string out;
  out.reserve(value.size());
  for (char c : value) {
    switch (c) {
      case '\\':
        out += "\\\\";
        break;
      case '"':
        out += "\\\"";
        break;
      case '\n':
        out += "\\n";
        break;
      default:
        out += c;
    }
  }
  return out;
}

std::string FormatSampleValue(double value) {
  if (std::isnan(value)) return "NaN";
  if (std::isinf(value)) return value > 0 ? "+Inf" : "-Inf";
  // Integers below 2^53 are exact in a double: print them without exponent or point.
  if (value == std::floor(value) && std::fabs(value) < 9007199254740992.0) {
    return std::to_string(static_cast<int64_t>(value));
  }
  // The shortest text that reads back as the same double.
  char buffer[32];
  const auto [end, error] = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return error == std::errc() ? std::string(buffer, end) : std::string("NaN");
}

const char* GrpcCodeName(int code) {
  static constexpr std::array<const char*, 17> kNames = {"OK",
                                                         "CANCELLED",
                                                         "UNKNOWN",
                                                         "INVALID_ARGUMENT",
                                                         "DEADLINE_EXCEEDED",
                                                         "NOT_FOUND",
                                                         "ALREADY_EXISTS",
                                                         "PERMISSION_DENIED",
                                                         "RESOURCE_EXHAUSTED",
                                                         "FAILED_PRECONDITION",
                                                         "ABORTED",
                                                         "OUT_OF_RANGE",
                                                         "UNIMPLEMENTED",
                                                         "INTERNAL",
                                                         "UNAVAILABLE",
                                                         "DATA_LOSS",
                                                         "UNAUTHENTICATED"};
  if (code < 0 || code >= static_cast<int>(kNames.size())) return "UNKNOWN";
  return kNames[static_cast<size_t>(code)];
}

std::unique_ptr<grpc::experimental::ServerInterceptorFactoryInterface> MakeGrpcMetricsInterceptor(
    Metrics* metrics) {
  return std::make_unique<GrpcMetricsInterceptorFactory>(metrics);
}

}  // namespace drillbif::server
