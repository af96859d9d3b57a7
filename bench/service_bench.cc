// Service load (docs/performance.md): latency of a cached QueryOptimum at 1000 requests per second,
// of QueryOptimum answered from an optimum map at the same rate, and throughput of small simulate
// jobs, against a real server (Server::Start, 127.0.0.1, port 0, a SQLite file in a temp dir, 2
// workers). Run:
//   build/bench/service_bench --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
// Counters: p50_ms, p99_ms (latency of the 1000 queries of one iteration, sent open-loop at 1 ms
// intervals by 4 client threads), stored (queries answered from the store: all of them);
// jobs_per_s (distinct small simulate jobs submitted at once and waited for); median_ms, max_ms
// (from a CancelOperation of a running sweep to its state CANCELLED, over 10 jobs).
#include <benchmark/benchmark.h>
#include <grpcpp/grpcpp.h>
#include <stdlib.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "server/server.h"

namespace drillbif::server {
namespace {

using Clock = std::chrono::steady_clock;

// One server for the program, over a SQLite file in a fresh temp directory.
struct Service {
  std::string dir;
  std::unique_ptr<Server> server;
  std::shared_ptr<grpc::Channel> channel;
};

Service& Shared() {
  static Service* s = [] {
    auto* service = new Service;
    std::string pattern =
        (std::filesystem::temp_directory_path() / "drillbif_bench_XXXXXX").string();
    service->dir = mkdtemp(pattern.data()) != nullptr ? pattern : std::string(".");
    ServerOptions options;
    options.grpc_port = 0;
    options.http_port = 0;
    options.db_path = service->dir + "/jobs.db";
    options.workers = 2;
    StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
    if (server.ok()) {
      service->server = std::move(server).value();
      service->channel =
          grpc::CreateChannel(service->server->grpc_address(), grpc::InsecureChannelCredentials());
    }
    return service;
  }();
  return *s;
}

std::unique_ptr<grpc::ClientContext> Context(double seconds) {
  auto context = std::make_unique<grpc::ClientContext>();
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(static_cast<int>(seconds * 1000)));
  return context;
}

// The optimum of the small box (omega in [0.05, 0.15], a in [0.25, 0.6], margins 0.01, 0.02,
// a 21 x 21 grid): computed once, then answered from the store.
v1::QueryOptimumRequest Query() {
  v1::QueryOptimumRequest q;
  v1::OptimumRequest* r = q.mutable_request();
  v1::TraceRequest* t = r->mutable_trace();
  t->add_trace_params(std::string("omega"));
  t->add_trace_params(std::string("a"));
  t->add_min(0.05);
  t->add_min(0.25);
  t->add_max(0.15);
  t->add_max(0.6);
  r->add_margin(0.01);
  r->add_margin(0.02);
  r->add_grid(21);
  r->add_grid(21);
  return q;
}

void BM_CachedQueryOptimumAt1000PerSecond(benchmark::State& state) {
  Service& service = Shared();
  if (!service.server) {
    state.SkipWithError("server did not start");
    return;
  }
  auto jobs = v1::Jobs::NewStub(service.channel);
  {
    v1::QueryOptimumRequest first = Query();
    first.set_compute(true);
    v1::QueryOptimumResponse response;
    auto context = Context(120);
    if (!jobs->QueryOptimum(context.get(), first, &response).ok() || !response.has_optimum()) {
      state.SkipWithError("the optimum could not be computed");
      return;
    }
  }
  constexpr int kRequests = 1000, kThreads = 4;
  std::vector<double> latencies;
  std::atomic<int> stored{0}, failed{0};
  for (auto _ : state) {
    latencies.assign(kRequests, 0.0);
    stored = 0;
    const auto start = Clock::now();
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) {
      threads.emplace_back([&, t] {
        auto stub = v1::Jobs::NewStub(service.channel);
        const v1::QueryOptimumRequest query = Query();
        // Request i leaves at start + i ms, whatever the previous ones took (open loop).
        for (int i = t; i < kRequests; i += kThreads) {
          std::this_thread::sleep_until(start + std::chrono::microseconds(1000 * i));
          const auto sent = Clock::now();
          v1::QueryOptimumResponse response;
          auto context = Context(10);
          if (!stub->QueryOptimum(context.get(), query, &response).ok()) ++failed;
          if (response.stored()) ++stored;
          latencies[i] = std::chrono::duration<double, std::milli>(Clock::now() - sent).count();
        }
      });
    }
    for (std::thread& th : threads) th.join();
  }
  std::sort(latencies.begin(), latencies.end());
  state.counters["p50_ms"] = latencies[kRequests / 2];
  state.counters["p99_ms"] = latencies[kRequests * 99 / 100];
  state.counters["stored"] = stored.load();
  if (failed > 0) state.SkipWithError("some queries failed");
}
BENCHMARK(BM_CachedQueryOptimumAt1000PerSecond)->Unit(benchmark::kMillisecond)->Iterations(1);

// The optimum map of the small box over b in [0.14, 0.16] (5 cells; margins 0.01, 0.02, a 41 x 41
// grid), computed once; `b` the condition of a query.
v1::QueryOptimumRequest MapQuery(double b) {
  v1::QueryOptimumRequest q = Query();
  q.mutable_request()->clear_grid();
  q.mutable_request()->add_grid(41);
  q.mutable_request()->add_grid(41);
  q.mutable_request()->mutable_trace()->mutable_params()->set_b(b);
  return q;
}

bool ComputeMap(Service& service) {
  static const bool done = [&] {
    auto jobs = v1::Jobs::NewStub(service.channel);
    auto operations = google::longrunning::Operations::NewStub(service.channel);
    v1::SubmitOptimumMapRequest submit;
    *submit.mutable_request()->mutable_optimum() = MapQuery(0.15).request();
    submit.mutable_request()->add_over(std::string("b"));
    submit.mutable_request()->add_from(0.14);
    submit.mutable_request()->add_to(0.16);
    submit.mutable_request()->add_steps(5);
    google::longrunning::Operation op;
    if (!jobs->SubmitOptimumMap(Context(30).get(), submit, &op).ok()) return false;
    google::longrunning::WaitOperationRequest wait;
    wait.set_name(op.name());
    wait.mutable_timeout()->set_seconds(120);
    return operations->WaitOperation(Context(150).get(), wait, &op).ok() && op.has_response();
  }();
  return done;
}

// QueryOptimum answered from the map at 1000 requests per second (open loop, 4 client threads):
// at one condition between cells (range(0) = 0: the kept answer after the first), or each at its
// own condition (range(0) = 1: b spread over the map, every answer interpolated and verified
// afresh). Counters as for the cached query, and `verified` (answers from the map, verified).
void BM_MapQueryAt1000PerSecond(benchmark::State& state) {
  Service& service = Shared();
  if (!service.server || !ComputeMap(service)) {
    state.SkipWithError("the server or the map failed");
    return;
  }
  const bool distinct = state.range(0) == 1;
  constexpr int kRequests = 1000, kThreads = 4;
  std::vector<double> latencies;
  std::atomic<int> verified{0}, failed{0};
  static int round = 0;
  for (auto _ : state) {
    ++round;
    latencies.assign(kRequests, 0.0);
    verified = 0;
    const auto start = Clock::now();
    std::vector<std::thread> threads;
    for (int t = 0; t < kThreads; ++t) {
      threads.emplace_back([&, t] {
        auto stub = v1::Jobs::NewStub(service.channel);
        for (int i = t; i < kRequests; i += kThreads) {
          // Distinct conditions never asked before (a new offset each round).
          const double b =
              distinct ? 0.1401 + 0.0198 * (i + 0.5 * round / kRequests) / kRequests : 0.1475;
          const v1::QueryOptimumRequest query = MapQuery(b);
          std::this_thread::sleep_until(start + std::chrono::microseconds(1000 * i));
          const auto sent = Clock::now();
          v1::QueryOptimumResponse response;
          auto context = Context(10);
          if (!stub->QueryOptimum(context.get(), query, &response).ok()) ++failed;
          if (response.from_map().verified()) ++verified;
          latencies[i] = std::chrono::duration<double, std::milli>(Clock::now() - sent).count();
        }
      });
    }
    for (std::thread& th : threads) th.join();
  }
  std::sort(latencies.begin(), latencies.end());
  state.counters["p50_ms"] = latencies[kRequests / 2];
  state.counters["p99_ms"] = latencies[kRequests * 99 / 100];
  state.counters["verified"] = verified.load();
  if (failed > 0) state.SkipWithError("some queries failed");
}
BENCHMARK(BM_MapQueryAt1000PerSecond)->Arg(0)->Arg(1)->Unit(benchmark::kMillisecond)->Iterations(1);

void BM_SmallSimulateJobs(benchmark::State& state) {
  Service& service = Shared();
  if (!service.server) {
    state.SkipWithError("server did not start");
    return;
  }
  auto jobs = v1::Jobs::NewStub(service.channel);
  auto operations = google::longrunning::Operations::NewStub(service.channel);
  constexpr int kJobs = 200;
  static int round = 0;  // distinct requests in every iteration: no cache hits
  double seconds = 0.0;
  for (auto _ : state) {
    ++round;
    const auto start = Clock::now();
    std::vector<std::string> names;
    for (int k = 0; k < kJobs; ++k) {
      v1::SubmitSimulateRequest submit;
      submit.mutable_request()->mutable_params()->set_a(0.2 + 1e-4 * k + 1e-7 * round);
      submit.mutable_request()->set_transient_periods(100);
      submit.mutable_request()->set_sample_periods(20);
      google::longrunning::Operation op;
      auto context = Context(30);
      if (jobs->SubmitSimulate(context.get(), submit, &op).ok()) names.push_back(op.name());
    }
    for (const std::string& name : names) {
      google::longrunning::Operation op;
      while (!op.done()) {
        google::longrunning::WaitOperationRequest wait;
        wait.set_name(name);
        wait.mutable_timeout()->set_seconds(10);
        auto context = Context(15);
        if (!operations->WaitOperation(context.get(), wait, &op).ok()) break;
      }
    }
    seconds = std::chrono::duration<double>(Clock::now() - start).count();
    if (static_cast<int>(names.size()) != kJobs) state.SkipWithError("submits failed");
  }
  state.counters["jobs_per_s"] = kJobs / seconds;
}
BENCHMARK(BM_SmallSimulateJobs)->Unit(benchmark::kMillisecond)->Iterations(1);

// Cancel latency: a long sweep (1e5 values of b) is submitted, followed until RUNNING, then
// cancelled; the time from the CancelOperation call until GetOperation shows CANCELLED (polled
// every 1 ms, so up to 1 ms of it is polling), for 10 jobs. Target: within 100 ms.
void BM_CancelRunningSweep(benchmark::State& state) {
  Service& service = Shared();
  if (!service.server) {
    state.SkipWithError("server did not start");
    return;
  }
  auto jobs = v1::Jobs::NewStub(service.channel);
  auto operations = google::longrunning::Operations::NewStub(service.channel);
  std::vector<double> ms;
  static int round = 0;
  auto metadata = [&](const std::string& name) {
    google::longrunning::GetOperationRequest get;
    get.set_name(name);
    google::longrunning::Operation op;
    auto context = Context(10);
    v1::JobMetadata m;
    if (operations->GetOperation(context.get(), get, &op).ok()) op.metadata().UnpackTo(&m);
    return m;
  };
  for (auto _ : state) {
    ms.clear();
    for (int k = 0; k < 10; ++k) {
      v1::SubmitSweepRequest submit;
      v1::SweepRequest* sweep = submit.mutable_request();
      sweep->set_param(std::string("b"));
      sweep->set_min(0.0);
      sweep->set_max(0.2 + 1e-6 * (++round));  // distinct: never a cache hit
      sweep->set_steps(100000);
      sweep->set_sample_periods(1);  // long, but well inside the result-size limit
      sweep->set_threads(1);
      google::longrunning::Operation op;
      auto context = Context(10);
      if (!jobs->SubmitSweep(context.get(), submit, &op).ok()) continue;
      while (metadata(op.name()).state() != v1::RUNNING) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
      google::longrunning::CancelOperationRequest cancel;
      cancel.set_name(op.name());
      google::protobuf::Empty empty;
      auto cancel_context = Context(10);
      const auto sent = Clock::now();
      if (!operations->CancelOperation(cancel_context.get(), cancel, &empty).ok()) continue;
      while (metadata(op.name()).state() != v1::CANCELLED &&
             Clock::now() - sent < std::chrono::seconds(10)) {
        std::this_thread::sleep_for(std::chrono::milliseconds(1));
      }
      ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - sent).count());
    }
  }
  if (ms.size() != 10) {
    state.SkipWithError("submit or cancel failed");
    return;
  }
  std::sort(ms.begin(), ms.end());
  state.counters["median_ms"] = 0.5 * (ms[4] + ms[5]);
  state.counters["max_ms"] = ms.back();
}
BENCHMARK(BM_CancelRunningSweep)->Unit(benchmark::kMillisecond)->Iterations(1);

}  // namespace
}  // namespace drillbif::server

BENCHMARK_MAIN();
