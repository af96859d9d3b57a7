#include "server/metrics.h"

#include <google/protobuf/descriptor.h>
#include <prometheus/client_metric.h>
#include <prometheus/counter.h>
#include <prometheus/family.h>
#include <prometheus/histogram.h>
#include <prometheus/metric_family.h>
#include <prometheus/metric_type.h>
#include <prometheus/registry.h>
#include <prometheus/text_serializer.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <utility>

namespace drillbif::server {
namespace {

// The store's states in JobState order, as label values (the API's JobState names).
constexpr std::array<const char*, kJobStateCount> kStateLabels = {"QUEUED", "RUNNING", "SUCCEEDED",
                                                                  "FAILED", "CANCELLED"};

// The label value of everything outside a label's known values.
constexpr char kOther[] = "other";

// HTTP methods counted under their own name (RFC 9110 and PATCH); CONNECT and TRACE, which the
// gateway never serves, and anything else count as "other".
constexpr std::array<std::string_view, 7> kHttpMethods = {"GET",    "HEAD",  "POST",   "PUT",
                                                          "DELETE", "PATCH", "OPTIONS"};

// gRPC's own health service: implemented by gRPC without a generated descriptor.
constexpr std::array<std::string_view, 2> kHealthMethods = {"/grpc.health.v1.Health/Check",
                                                            "/grpc.health.v1.Health/Watch"};

std::string HttpMethodLabel(std::string_view method) {
  const bool known =
      std::find(kHttpMethods.begin(), kHttpMethods.end(), method) != kHttpMethods.end();
  return known ? std::string(method) : std::string(kOther);
}

std::string HttpStatusLabel(int status) {
  return status >= 100 && status <= 599 ? std::to_string(status) : std::string(kOther);
}

// `method` ("/package.Service/Method") when a service linked into the process declares it (its
// descriptor is in the generated pool) or it is a health method; "other" otherwise, so that a
// client sending made-up paths cannot create series.
std::string GrpcMethodLabel(std::string_view method) {
  if (std::find(kHealthMethods.begin(), kHealthMethods.end(), method) != kHealthMethods.end()) {
    return std::string(method);
  }
  const size_t slash = method.rfind('/');
  if (method.empty() || method.front() != '/' || slash == 0 || slash + 1 == method.size()) {
    return kOther;
  }
  std::string full_name(method.substr(1));  // "package.Service/Method"
  full_name[slash - 1] = '.';
  const google::protobuf::MethodDescriptor* descriptor =
      google::protobuf::DescriptorPool::generated_pool()->FindMethodByName(full_name);
  return descriptor != nullptr ? std::string(method) : std::string(kOther);
}

prometheus::MetricFamily Family(const char* name, const char* help, prometheus::MetricType type) {
  prometheus::MetricFamily family;
  family.name = name;
  family.help = help;
  family.type = type;
  return family;
}

// A sample of a counter or gauge family built at scrape time.
void AddSample(prometheus::MetricFamily* family, double value,
               std::vector<prometheus::ClientMetric::Label> labels = {}) {
  prometheus::ClientMetric metric;
  metric.label = std::move(labels);
  if (family->type == prometheus::MetricType::Counter) {
    metric.counter.value = value;
  } else {
    metric.gauge.value = value;
  }
  family->metric.push_back(std::move(metric));
}

// The families of the snapshot, in the order of the header's list.
std::vector<prometheus::MetricFamily> SnapshotFamilies(const MetricsSnapshot& snapshot) {
  using prometheus::MetricType;
  std::vector<prometheus::MetricFamily> families;
  families.reserve(7);

  prometheus::MetricFamily jobs =
      Family("drillbif_jobs", "Jobs in the store by state.", MetricType::Gauge);
  for (size_t s = 0; s < kStateLabels.size(); ++s) {
    AddSample(&jobs, static_cast<double>(snapshot.stats.jobs_by_state[s]),
              {{"state", kStateLabels[s]}});
  }
  families.push_back(std::move(jobs));

  prometheus::MetricFamily queue = Family(
      "drillbif_queue_depth",
      "Queued jobs a worker can claim, by cost lane (not counting jobs that follow an identical "
      "one).",
      MetricType::Gauge);
  for (int lane = 0; lane < kLaneCount; ++lane) {
    AddSample(&queue,
              static_cast<double>(snapshot.stats.queue_depth_by_lane[static_cast<size_t>(lane)]),
              {{"lane", LaneName(lane)}});
  }
  families.push_back(std::move(queue));

  families.push_back(Family("drillbif_cache_hits_total",
                            "Jobs that succeeded without running the engine (cache hits and "
                            "shared runs), over the store's life.",
                            MetricType::Counter));
  AddSample(&families.back(), static_cast<double>(snapshot.stats.cache_hits_total));
  families.push_back(Family("drillbif_engine_runs_total",
                            "Job runs started on the engine by this process.",
                            MetricType::Counter));
  AddSample(&families.back(), static_cast<double>(snapshot.engine_runs));
  families.push_back(
      Family("drillbif_watchers",
             "Calls waiting on jobs (Watch streams, WaitOperation, QueryOptimum computing).",
             MetricType::Gauge));
  AddSample(&families.back(), static_cast<double>(snapshot.watchers));
  families.push_back(Family("drillbif_store_healthy",
                            "1 when the job store can write, 0 after a write failed (until a "
                            "probe succeeds).",
                            MetricType::Gauge));
  AddSample(&families.back(), snapshot.store_healthy ? 1 : 0);
  families.push_back(Family("drillbif_store_bytes",
                            "Bytes of the job store's data (the size retention limits).",
                            MetricType::Gauge));
  AddSample(&families.back(), static_cast<double>(snapshot.stats.used_bytes));
  return families;
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

// The process's families. Registry::Collect and each family lock their own mutexes; counters
// are atomic, a histogram locks its own mutex, so events and Render need no lock of ours.
struct Metrics::Families {
  prometheus::Registry registry;
  prometheus::Family<prometheus::Histogram>& job_duration =
      prometheus::BuildHistogram()
          .Name("drillbif_job_duration_seconds")
          .Help("Wall time of the job runs of this process, by kind and outcome.")
          .Register(registry);
  prometheus::Family<prometheus::Counter>& http_requests =
      prometheus::BuildCounter()
          .Name("drillbif_http_requests_total")
          .Help("HTTP requests answered by the REST port, by method, route template and status.")
          .Register(registry);
  prometheus::Family<prometheus::Counter>& grpc_requests =
      prometheus::BuildCounter()
          .Name("drillbif_grpc_requests_total")
          .Help(
              "gRPC calls ended, by full method name and status code (REST calls included: the "
              "gateway calls the same services).")
          .Register(registry);
  prometheus::Family<prometheus::Counter>& refusals =
      prometheus::BuildCounter()
          .Name("drillbif_jobs_refused_total")
          .Help("Submits refused at admission by this process, by job kind and reason.")
          .Register(registry);
  // Unlabelled: exposed at 0 from the start, so that rate() has a first sample.
  prometheus::Counter& evicted_jobs =
      prometheus::BuildCounter()
          .Name("drillbif_store_evicted_jobs_total")
          .Help("Finished jobs deleted by the store's retention in this process.")
          .Register(registry)
          .Add({});
  prometheus::Counter& evicted_bytes =
      prometheus::BuildCounter()
          .Name("drillbif_store_evicted_bytes_total")
          .Help(
              "Bytes of store data freed by retention in this process (used size before minus "
              "after).")
          .Register(registry)
          .Add({});
};

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

Metrics::Metrics(MetricsOptions options)
    : options_(std::move(options)), families_(std::make_unique<Families>()) {}

Metrics::~Metrics() = default;

void Metrics::ObserveJob(std::string_view kind, std::string_view outcome, double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) seconds = 0;
  families_->job_duration
      .Add({{"kind", std::string(kind)}, {"outcome", std::string(outcome)}},
           options_.job_duration_buckets)
      .Observe(seconds);
}

void Metrics::CountHttpRequest(std::string_view method, std::string_view route, int status) {
  families_->http_requests
      .Add({{"method", HttpMethodLabel(method)},
            {"route", std::string(route)},
            {"code", HttpStatusLabel(status)}})
      .Increment();
}

void Metrics::CountGrpcRequest(std::string_view method, int code) {
  families_->grpc_requests.Add({{"method", GrpcMethodLabel(method)}, {"code", GrpcCodeName(code)}})
      .Increment();
}

void Metrics::CountAdmissionRefusal(std::string_view kind, std::string_view reason) {
  families_->refusals.Add({{"kind", std::string(kind)}, {"reason", std::string(reason)}})
      .Increment();
}

void Metrics::CountEvictions(int64_t jobs, int64_t bytes) {
  if (jobs > 0) families_->evicted_jobs.Increment(static_cast<double>(jobs));
  if (bytes > 0) families_->evicted_bytes.Increment(static_cast<double>(bytes));
}

std::string Metrics::Render(const MetricsSnapshot& snapshot) const {
  std::vector<prometheus::MetricFamily> families = SnapshotFamilies(snapshot);
  std::vector<prometheus::MetricFamily> events = families_->registry.Collect();
  for (prometheus::MetricFamily& family : events) {
    // A family keeps its series in a hash map: sort them for a stable, readable text.
    std::sort(family.metric.begin(), family.metric.end(),
              [](const prometheus::ClientMetric& a, const prometheus::ClientMetric& b) {
                return a.label < b.label;
              });
    families.push_back(std::move(family));
  }
  return prometheus::TextSerializer().Serialize(families);
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
