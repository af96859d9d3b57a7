// REST gateway load: 50 concurrent HTTP clients reading one operation (GET /v1/operations/{id},
// a finished simulate job with its result, ~1.5 KB of JSON) from a real server (Server::Start,
// 127.0.0.1, port 0, a SQLite file in a temp dir). Run:
//   build/bench/http_bench --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
// Counters: p50_ms, p99_ms, p999_ms, max_ms, mean_ms (latency of each request, over 50 clients
// x 200 requests), req_per_s (all requests over the wall time of the iteration), errors (requests
// without a 200). With 50 clients in a closed loop, req_per_s = 50 / mean_ms: a tail beyond p99
// (a dropped SYN waits 1 s for its retry) shows in the mean and p999, not in p99.
// BM_GetOperationKeepAlive reuses one connection per client; BM_GetOperationNewConnections opens
// a connection per request (50 clients connecting at once: the listen backlog's case).
#include <benchmark/benchmark.h>
#include <google/protobuf/util/json_util.h>
#include <stdlib.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.pb.h"
#include "google/longrunning/operations.pb.h"
#include "server/server.h"

// Last: httplib.h includes <resolv.h>, whose macro _res breaks Eigen's headers.
#include <httplib.h>

namespace drillbif::server {
namespace {

using Clock = std::chrono::steady_clock;

constexpr int kClients = 50;
constexpr int kRequestsPerClient = 200;

// One server for the program, and one finished operation to read.
struct Service {
  std::string dir;
  std::unique_ptr<Server> server;
  std::string path;  // "/v1/operations/{id}"
};

Service& Shared() {
  static Service* s = [] {
    auto* service = new Service;
    std::string pattern =
        (std::filesystem::temp_directory_path() / "drillbif_http_bench_XXXXXX").string();
    service->dir = mkdtemp(pattern.data()) != nullptr ? pattern : std::string(".");
    ServerOptions options;
    options.grpc_port = 0;
    options.http_port = 0;
    options.db_path = service->dir + "/jobs.db";
    options.workers = 1;
    StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
    if (!server.ok()) return service;
    service->server = std::move(server).value();
    httplib::Client client("127.0.0.1", service->server->http_port());
    client.set_read_timeout(std::chrono::seconds(30));
    v1::SubmitSimulateRequest submit;
    submit.mutable_request()->set_sample_periods(10);
    std::string body;
    (void)google::protobuf::util::MessageToJsonString(submit, &body);
    httplib::Result result = client.Post("/v1/jobs:simulate", body, "application/json");
    google::longrunning::Operation op;
    if (result && result->status == 200 &&
        google::protobuf::util::JsonStringToMessage(result->body, &op).ok()) {
      service->path = "/v1/" + op.name();
      // Until done, so that every read returns the same finished operation.
      for (int i = 0; i < 1000 && !op.done(); ++i) {
        std::this_thread::sleep_for(std::chrono::milliseconds(10));
        httplib::Result got = client.Get(service->path.c_str());
        if (got && got->status == 200) {
          (void)google::protobuf::util::JsonStringToMessage(got->body, &op);
        }
      }
    }
    return service;
  }();
  return *s;
}

void RunClients(benchmark::State& state, bool keep_alive) {
  Service& service = Shared();
  if (service.server == nullptr || service.path.empty()) {
    state.SkipWithError("server did not start");
    return;
  }
  const int port = service.server->http_port();
  std::vector<double> latencies;
  int errors = 0;
  double seconds = 0;
  for (auto _ : state) {
    std::vector<std::vector<double>> per_client(kClients);
    std::atomic<int> failed{0};
    std::atomic<int> ready{0};
    std::atomic<bool> go{false};
    std::vector<std::thread> clients;
    for (int c = 0; c < kClients; ++c) {
      clients.emplace_back([&, c] {
        httplib::Client client("127.0.0.1", port);
        client.set_keep_alive(keep_alive);
        client.set_read_timeout(std::chrono::seconds(30));
        client.set_connection_timeout(std::chrono::seconds(30));
        per_client[c].reserve(kRequestsPerClient);
        ++ready;
        while (!go) std::this_thread::yield();
        for (int i = 0; i < kRequestsPerClient; ++i) {
          const auto start = Clock::now();
          httplib::Result result = client.Get(service.path.c_str());
          per_client[c].push_back(
              std::chrono::duration<double, std::milli>(Clock::now() - start).count());
          if (!result || result->status != 200) ++failed;
        }
      });
    }
    while (ready < kClients) std::this_thread::yield();
    const auto start = Clock::now();
    go = true;
    for (auto& t : clients) t.join();
    seconds = std::chrono::duration<double>(Clock::now() - start).count();
    latencies.clear();
    for (const auto& l : per_client) latencies.insert(latencies.end(), l.begin(), l.end());
    errors = failed.load();
  }
  std::sort(latencies.begin(), latencies.end());
  const size_t n = latencies.size();
  state.counters["p50_ms"] = latencies[n / 2];
  state.counters["p99_ms"] = latencies[n * 99 / 100];
  state.counters["p999_ms"] = latencies[n * 999 / 1000];
  state.counters["max_ms"] = latencies.back();
  double sum = 0;
  for (double l : latencies) sum += l;
  state.counters["mean_ms"] = sum / static_cast<double>(n);
  state.counters["req_per_s"] = static_cast<double>(n) / seconds;
  state.counters["errors"] = errors;
}

void BM_GetOperationKeepAlive(benchmark::State& state) { RunClients(state, true); }
BENCHMARK(BM_GetOperationKeepAlive)->Unit(benchmark::kMillisecond)->Iterations(1)->UseRealTime();

void BM_GetOperationNewConnections(benchmark::State& state) { RunClients(state, false); }
BENCHMARK(BM_GetOperationNewConnections)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->UseRealTime();

}  // namespace
}  // namespace drillbif::server

BENCHMARK_MAIN();
