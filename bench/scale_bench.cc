// Throughput of the service spread over processes on one PostgreSQL store (a throwaway cluster,
// as tests/support/postgres_cluster.h makes it), side by side in one run, alternating:
// - traces: 8 small-box traces (each ~0.5 s of engine time on one core, boxes differing so that
//   none is a cache hit) through one API process, run by 1 and by 2 worker processes of one
//   worker thread each;
// - submits: 400 small simulations submitted by 8 client threads through 1 and through 2 API
//   processes (no worker: the submit path alone, admission and the store's insert).
// - one trace of the reference box, run by 1 worker process on its thread, and fanned out as
//   child jobs over 1 and 2 worker processes (each run's result must equal the first's).
// Medians of `runs` (default 3) and their ratio. Not a Google Benchmark: each measurement starts
// processes and a database.
//   build/bench/scale_bench [runs] [fan-out | fan-out-batch | fan-out-period2 | fan-out-optimum]
//   (fan-out: the reference box only; fan-out-batch: the same on 2 workers by tasks per child;
//   fan-out-period2: a period-2 box, unfanned on 1 worker
//   against fanned out on 2; fan-out-optimum: the reference box's optimum from scratch, the same)
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <memory>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "jobs/registry.h"
#include "support/operations.h"
#include "support/postgres_cluster.h"
#include "support/same_result.h"
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

  ServerProcess& Start(const std::string& role, int fan_out = 32, int batch = 4) {
    const std::string sub = dir + "/p" + std::to_string(processes.size());
    std::filesystem::create_directories(sub);
    processes.push_back(std::make_unique<ServerProcess>(
        sub, sub + "/unused.db",
        std::vector<std::string>{
            "--store", cluster.Uri("jobs"), "--role", role, "--workers", "1", "--short-workers",
            "0", "--log-level", role == "worker" ? "info" : "warn", "--trace-fan-out",
            std::to_string(fan_out), "--trace-fan-out-batch", std::to_string(batch)}));
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

// Seconds for one trace of the reference box (omega in [0.05, 2], a in [0.01, 8] at b = 0.15), or
// with `optimum` for the robust optimum over it from scratch (its trace, region and query; the
// default margin and grid), run by `workers` worker processes, the trace's tasks fanned out
// `fan_out` ahead (0: on the threads of the worker that claimed it, one thread each here).
// The result each run gives, times cleared: every run must give the first one's.
std::string first_result[2];

// The period-2 box: omega in [0.05, 0.6], a in [0.2, 1] with period 2 (~94 s on one core).
bool period_two = false;

// The result of a finished job, its times cleared, serialized; exits unless it SUCCEEDED.
template <typename Result>
std::string ResultBytes(const google::longrunning::Operation& done) {
  const v1::JobMetadata m = testing::MetadataOf(done);
  if (m.state() != v1::SUCCEEDED) {
    std::fprintf(stderr, "the job ended %s: %s\n", v1::JobState_Name(m.state()).c_str(),
                 done.error().message().c_str());
    std::exit(1);
  }
  Result result;
  if (!done.response().UnpackTo(&result)) std::exit(1);
  testing::ClearTimes(&result);
  return result.SerializeAsString();
}

double OneJobSeconds(int workers, int fan_out, bool optimum = false, int batch = 4) {
  Setup setup;
  ServerProcess& api = setup.Start("api");
  for (int w = 0; w < workers; ++w) setup.Start("worker", fan_out, batch);
  auto operations = google::longrunning::Operations::NewStub(api.channel());
  v1::OptimumRequest request;
  v1::TraceRequest& r = *request.mutable_trace();
  r.add_trace_params(std::string("omega"));
  r.add_trace_params(std::string("a"));
  r.add_min(0.05);
  r.add_min(period_two ? 0.2 : 0.01);
  r.add_max(period_two ? 0.6 : 2);
  r.add_max(period_two ? 1 : 8);
  r.set_period2(period_two);
  r.set_threads(1);
  const Clock::time_point t0 = Clock::now();
  google::longrunning::Operation op;
  const jobs::JobKindSpec* kind = jobs::FindKind(optimum ? v1::OPTIMUM : v1::TRACE);
  const google::protobuf::Message& submitted =
      optimum ? static_cast<const google::protobuf::Message&>(request) : r;
  if (!testing::Submit(api, *kind, submitted, &op).ok()) std::exit(1);
  const google::longrunning::Operation done = testing::WaitDone(*operations, op.name(), 600);
  const double seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  // Where a fanned-out trace's time went, as its worker logs it.
  for (const std::unique_ptr<ServerProcess>& p : setup.processes) {
    std::ifstream log(p->log_path());
    for (std::string line; std::getline(log, line);) {
      if (line.find(" trace tasks, ") != std::string::npos) {
        std::printf("  %s\n", line.substr(line.find("] job") + 2).c_str());
      }
    }
  }
  const std::string bytes =
      optimum ? ResultBytes<v1::OptimumResult>(done) : ResultBytes<v1::TraceResult>(done);
  std::string& first = first_result[optimum ? 1 : 0];
  if (first.empty()) first = bytes;
  if (bytes != first) {
    std::fprintf(stderr, "the reference box's %s differs from the first run's\n",
                 kind->name.c_str());
    std::exit(1);
  }
  return seconds;
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
  // "fan-out": only the reference box's trace, on 1 worker without fan-out and on 1 and 2
  // workers with it.
  const bool fan_out_only = argc > 2 && std::string(argv[2]) == "fan-out";
  // "fan-out-period2": the period-2 box instead, on 1 worker without fan-out and on 2 with it.
  drillbif::period_two = argc > 2 && std::string(argv[2]) == "fan-out-period2";
  // "fan-out-batch": the reference box's trace on 1 worker without fan-out, and on 2 with
  // batches of 1, 4 and 8 tasks.
  if (argc > 2 && std::string(argv[2]) == "fan-out-batch") {
    const std::vector<int> sizes = {1, 4, 8};
    std::vector<double> local;
    std::vector<std::vector<double>> fanned(sizes.size());
    for (int run = 0; run < runs; ++run) {
      local.push_back(drillbif::OneJobSeconds(1, 0));
      std::printf("run %d: the reference box %.2f s on 1 worker unfanned", run, local.back());
      for (size_t b = 0; b < sizes.size(); ++b) {
        fanned[b].push_back(drillbif::OneJobSeconds(2, 32, /*optimum=*/false, sizes[b]));
        std::printf(", %.2f s on 2 in batches of %d", fanned[b].back(), sizes[b]);
      }
      std::printf("\n");
      std::fflush(stdout);
    }
    const double l = drillbif::Median(local);
    std::printf("the reference box: 1 worker unfanned %.2f s", l);
    for (size_t b = 0; b < sizes.size(); ++b) {
      const double f = drillbif::Median(fanned[b]);
      std::printf("; 2 workers, batches of %d: %.2f s (%.2fx)", sizes[b], f, l / f);
    }
    std::printf("\n");
    return 0;
  }
  // "fan-out-optimum": the reference box's optimum from scratch, on 1 worker without fan-out and
  // on 2 with it.
  if (argc > 2 && std::string(argv[2]) == "fan-out-optimum") {
    std::vector<double> local, two;
    for (int run = 0; run < runs; ++run) {
      local.push_back(drillbif::OneJobSeconds(1, 0, /*optimum=*/true));
      two.push_back(drillbif::OneJobSeconds(2, 32, /*optimum=*/true));
      std::printf(
          "run %d: the reference box's optimum %.2f s on 1 worker, fanned out %.2f s on 2\n", run,
          local.back(), two.back());
      std::fflush(stdout);
    }
    const double l = drillbif::Median(local), t = drillbif::Median(two);
    std::printf(
        "the reference box's optimum: 1 worker unfanned %.2f s, fanned out on 2 workers %.2f s: "
        "%.2fx\n",
        l, t, l / t);
    return 0;
  }
  if (drillbif::period_two) {
    std::vector<double> local, two;
    for (int run = 0; run < runs; ++run) {
      local.push_back(drillbif::OneJobSeconds(1, 0));
      two.push_back(drillbif::OneJobSeconds(2, 32));
      std::printf("run %d: period-2 box %.2f s on 1 worker, fanned out %.2f s on 2\n", run,
                  local.back(), two.back());
      std::fflush(stdout);
    }
    const double l = drillbif::Median(local), t = drillbif::Median(two);
    std::printf(
        "the period-2 box: 1 worker unfanned %.2f s, fanned out on 2 workers %.2f s: %.2fx\n", l, t,
        l / t);
    return 0;
  }
  std::vector<double> trace1, trace2, submit1, submit2, box_local, box1, box2;
  for (int run = 0; run < runs; ++run) {
    if (!fan_out_only) {
      trace1.push_back(drillbif::TraceSeconds(1));
      trace2.push_back(drillbif::TraceSeconds(2));
      submit1.push_back(drillbif::SubmitsPerSecond(1, 2 * run));
      submit2.push_back(drillbif::SubmitsPerSecond(2, 2 * run + 1));
      std::printf("run %d: traces %.2f s / %.2f s, submits %.0f/s / %.0f/s\n", run, trace1.back(),
                  trace2.back(), submit1.back(), submit2.back());
    }
    box_local.push_back(drillbif::OneJobSeconds(1, 0));
    box1.push_back(drillbif::OneJobSeconds(1, 32));
    box2.push_back(drillbif::OneJobSeconds(2, 32));
    std::printf("run %d: reference box %.2f s on 1 worker, fanned out %.2f s on 1, %.2f s on 2\n",
                run, box_local.back(), box1.back(), box2.back());
    std::fflush(stdout);
  }
  if (!fan_out_only) {
    const double t1 = drillbif::Median(trace1), t2 = drillbif::Median(trace2);
    const double s1 = drillbif::Median(submit1), s2 = drillbif::Median(submit2);
    std::printf(
        "8 traces: 1 worker process %.2f s (%.2f traces/s), 2 worker processes %.2f s "
        "(%.2f traces/s): %.2fx\n",
        t1, 8 / t1, t2, 8 / t2, t1 / t2);
    std::printf("400 submits: 1 API process %.0f/s, 2 API processes %.0f/s: %.2fx\n", s1, s2,
                s2 / s1);
  }
  const double b0 = drillbif::Median(box_local), b1 = drillbif::Median(box1),
               b2 = drillbif::Median(box2);
  std::printf(
      "the reference box: 1 worker unfanned %.2f s, fanned out on 1 worker %.2f s, on 2 "
      "workers %.2f s: %.2fx against unfanned\n",
      b0, b1, b2, b0 / b2);
  return 0;
}
