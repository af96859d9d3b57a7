// Throughput of the service spread over processes on one PostgreSQL store (a throwaway cluster,
// as tests/support/postgres_cluster.h makes it), side by side in one run, alternating:
// - traces: 8 small-box traces (each ~0.5 s of engine time on one core, boxes differing so that
//   none is a cache hit) through one API process, run by 1 and by 2 worker processes of one
//   worker thread each;
// - submits: 400 small simulations submitted by 8 client threads through 1 and through 2 API
//   processes (no worker: the submit path alone, admission and the store's insert).
// Medians of `runs` (default 3) and their ratio. Not a Google Benchmark: each measurement starts
// processes and a database.
//   build/bench/scale_bench [runs]
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "support/postgres_cluster.h"
#include "support/server_process.h"
#include "support/small_requests.h"

namespace drillbif {
namespace {

using Clock = std::chrono::steady_clock;
using testing::PostgresCluster;
using testing::ServerProcess;

struct Setup {
  std::string dir;
  PostgresCluster cluster;
  std::vector<std::unique_ptr<ServerProcess>> processes;

  Setup() {
    std::string pattern =
        std::filesystem::temp_directory_path().string() + "/drillbif_scale_XXXXXX";
    if (mkdtemp(pattern.data()) != nullptr) dir = pattern;
    if (!cluster.ok() || !cluster.CreateDatabase("jobs")) {
      std::fprintf(stderr, "no PostgreSQL cluster: %s\n", cluster.error().c_str());
      std::exit(1);
    }
  }
  ~Setup() {
    processes.clear();  // killed before the cluster stops
    std::error_code ignored;
    std::filesystem::remove_all(dir, ignored);
  }

  ServerProcess& Start(const std::string& role) {
    const std::string sub = dir + "/p" + std::to_string(processes.size());
    std::filesystem::create_directories(sub);
    processes.push_back(std::make_unique<ServerProcess>(
        sub, sub + "/unused.db",
        std::vector<std::string>{"--store", cluster.Uri("jobs"), "--role", role, "--workers", "1",
                                 "--short-workers", "0", "--log-level", "warn"}));
    return *processes.back();
  }
};

// Seconds for 8 traces through one API process run by `workers` worker processes.
double TraceSeconds(int workers) {
  Setup setup;
  ServerProcess& api = setup.Start("api");
  for (int w = 0; w < workers; ++w) setup.Start("worker");
  auto jobs = v1::Jobs::NewStub(api.channel());
  auto operations = google::longrunning::Operations::NewStub(api.channel());
  const Clock::time_point t0 = Clock::now();
  std::vector<std::string> names;
  for (int i = 0; i < 8; ++i) {
    v1::SubmitTraceRequest submit;
    *submit.mutable_request() = testing::SmallBoxTrace();
    submit.mutable_request()->set_max(0, 0.15 + 0.001 * i);
    google::longrunning::Operation op;
    auto context = testing::ContextWithDeadline();
    if (!jobs->SubmitTrace(context.get(), submit, &op).ok()) std::exit(1);
    names.push_back(op.name());
  }
  for (const std::string& name : names) {
    if (!testing::WaitDone(*operations, name, 300).done()) std::exit(1);
  }
  return std::chrono::duration<double>(Clock::now() - t0).count();
}

// Submits per second of 8 clients, 50 simulations each, over `apis` API processes.
double SubmitsPerSecond(int apis, int run) {
  Setup setup;
  std::vector<ServerProcess*> servers;
  for (int a = 0; a < apis; ++a) servers.push_back(&setup.Start("api"));
  constexpr int kClients = 8, kEach = 50;
  std::vector<std::thread> clients;
  const Clock::time_point t0 = Clock::now();
  for (int c = 0; c < kClients; ++c) {
    clients.emplace_back([&, c] {
      auto jobs = v1::Jobs::NewStub(servers[c % apis]->channel());
      for (int k = 0; k < kEach; ++k) {
        v1::SubmitSimulateRequest submit;
        // Distinct requests (no cache hits): the transient differs.
        submit.mutable_request()->set_sample_periods(1);
        submit.mutable_request()->set_transient_periods(run * 1000 + c * kEach + k);
        google::longrunning::Operation op;
        auto context = testing::ContextWithDeadline();
        if (!jobs->SubmitSimulate(context.get(), submit, &op).ok()) std::exit(1);
      }
    });
  }
  for (std::thread& t : clients) t.join();
  return kClients * kEach / std::chrono::duration<double>(Clock::now() - t0).count();
}

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace
}  // namespace drillbif

int main(int argc, char** argv) {
  const int runs = argc > 1 ? std::max(1, std::atoi(argv[1])) : 3;
  std::vector<double> trace1, trace2, submit1, submit2;
  for (int run = 0; run < runs; ++run) {
    trace1.push_back(drillbif::TraceSeconds(1));
    trace2.push_back(drillbif::TraceSeconds(2));
    submit1.push_back(drillbif::SubmitsPerSecond(1, 2 * run));
    submit2.push_back(drillbif::SubmitsPerSecond(2, 2 * run + 1));
    std::printf("run %d: traces %.2f s / %.2f s, submits %.0f/s / %.0f/s\n", run, trace1.back(),
                trace2.back(), submit1.back(), submit2.back());
  }
  const double t1 = drillbif::Median(trace1), t2 = drillbif::Median(trace2);
  const double s1 = drillbif::Median(submit1), s2 = drillbif::Median(submit2);
  std::printf(
      "8 traces: 1 worker process %.2f s (%.2f traces/s), 2 worker processes %.2f s "
      "(%.2f traces/s): %.2fx\n",
      t1, 8 / t1, t2, 8 / t2, t1 / t2);
  std::printf("400 submits: 1 API process %.0f/s, 2 API processes %.0f/s: %.2fx\n", s1, s2,
              s2 / s1);
  return 0;
}
