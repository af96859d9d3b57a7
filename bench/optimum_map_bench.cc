// What an optimum map and a sweep cost in time, on the job's own threads and on a server's workers
// (the map's cells, the sweep's pieces as child jobs in the store).
// - The map: the small (omega, a) box (omega in [0.05, 0.15], a in [0.25, 0.6], margins 0.01,
//   0.02, grid 41 x 41) over b in [0.14, 0.16], 8 cells.
// - The sweep: b over [0.08, 0.2], BOTH directions, 500 values of 200 + 50 periods each, on one
//   thread (threads = 1): its two directions are its two pieces.
// Every iteration asks a map or a sweep never computed before (the range's end moved by 1e-9), so
// no cache answers it. Run:
//   build/bench/optimum_map_bench --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
// Counters: cells_per_s, values_per_s (both directions' values).
#include <benchmark/benchmark.h>
#include <grpcpp/grpcpp.h>
#include <stdlib.h>

#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "jobs/optimum_map_job.h"
#include "jobs/sweep_job.h"
#include "server/server.h"
#include "support/small_requests.h"

namespace drillbif {
namespace {

constexpr int kCells = 8;

v1::OptimumMapRequest Map(int round) {
  return testing::SmallBoxMap(0.14, 0.16 + 1e-9 * round, kCells);
}

int NextRound() {
  static int round = 0;
  return ++round;
}

// On the job's own threads (drillctl --local): range(0) threads.
void BM_MapOnThreads(benchmark::State& state) {
  for (auto _ : state) {
    v1::OptimumMapRequest request = Map(NextRound());
    request.set_threads(static_cast<int>(state.range(0)));
    StatusOr<v1::OptimumMapResult> r = jobs::RunOptimumMap(request);
    if (!r.ok() || r->cells_found() != kCells) state.SkipWithError("the map failed");
  }
  state.counters["cells_per_s"] =
      benchmark::Counter(kCells * state.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_MapOnThreads)->Arg(1)->Arg(2)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(1);

// Each iteration: a job submitted by `submit` (through the stub, its operation out) to a server
// with range(0) workers over a SQLite store (in this process), and waited for through gRPC.
// `what` names the job in errors.
void OnWorkers(benchmark::State& state, const char* what,
               const std::function<grpc::Status(v1::Jobs::Stub&, grpc::ClientContext*,
                                                google::longrunning::Operation*)>& submit) {
  std::string dir = (std::filesystem::temp_directory_path() / "drillbif_bench_XXXXXX").string();
  if (mkdtemp(dir.data()) == nullptr) {
    state.SkipWithError("no temp dir");
    return;
  }
  server::ServerOptions options;
  options.grpc_port = 0;
  options.http_port = 0;
  options.db_path = dir + "/jobs.db";
  options.workers = static_cast<int>(state.range(0));
  options.short_workers = 0;
  StatusOr<std::unique_ptr<server::Server>> server = server::Server::Start(options);
  if (!server.ok()) {
    state.SkipWithError("the server did not start");
    return;
  }
  auto channel = grpc::CreateChannel((*server)->grpc_address(), grpc::InsecureChannelCredentials());
  auto jobs = v1::Jobs::NewStub(channel);
  auto operations = google::longrunning::Operations::NewStub(channel);
  for (auto _ : state) {
    google::longrunning::Operation op;
    grpc::ClientContext submit_context;
    if (!submit(*jobs, &submit_context, &op).ok()) {
      state.SkipWithError("submit failed");
      break;
    }
    while (!op.done()) {
      google::longrunning::WaitOperationRequest wait;
      wait.set_name(op.name());
      wait.mutable_timeout()->set_seconds(60);
      grpc::ClientContext context;
      if (!operations->WaitOperation(&context, wait, &op).ok()) break;
    }
    if (!op.has_response()) state.SkipWithError((std::string("the ") + what + " failed").c_str());
  }
  server->reset();
  std::filesystem::remove_all(dir);
}

// On a server with range(0) workers (OnWorkers).
void BM_MapOnWorkers(benchmark::State& state) {
  OnWorkers(
      state, "map",
      [](v1::Jobs::Stub& jobs, grpc::ClientContext* context, google::longrunning::Operation* op) {
        v1::SubmitOptimumMapRequest submit;
        *submit.mutable_request() = Map(NextRound());
        return jobs.SubmitOptimumMap(context, submit, op);
      });
  state.counters["cells_per_s"] =
      benchmark::Counter(kCells * state.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_MapOnWorkers)->Arg(1)->Arg(2)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(1);

constexpr int kSweepSteps = 500;

v1::SweepRequest BothSweep(int round) {
  v1::SweepRequest sweep = testing::SmallSweep(0.08, kSweepSteps);
  sweep.set_max(0.2 + 1e-9 * round);
  sweep.set_direction(v1::SweepRequest::BOTH);
  sweep.set_transient_periods(200);
  sweep.set_sample_periods(50);
  return sweep;
}

// On the job's own threads: range(0) threads (1: one direction after the other).
void BM_SweepOnThreads(benchmark::State& state) {
  for (auto _ : state) {
    v1::SweepRequest request = BothSweep(NextRound());
    request.set_threads(static_cast<int>(state.range(0)));
    StatusOr<v1::SweepResult> r = jobs::RunSweep(request);
    if (!r.ok() || r->status() != "COMPLETED") state.SkipWithError("the sweep failed");
  }
  state.counters["values_per_s"] =
      benchmark::Counter(2 * kSweepSteps * state.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_SweepOnThreads)
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);

// On a server with range(0) workers (OnWorkers); the request asks threads = 1, so that on its
// own the job would sweep one direction after the other.
void BM_SweepOnWorkers(benchmark::State& state) {
  OnWorkers(
      state, "sweep",
      [](v1::Jobs::Stub& jobs, grpc::ClientContext* context, google::longrunning::Operation* op) {
        v1::SubmitSweepRequest submit;
        *submit.mutable_request() = BothSweep(NextRound());
        return jobs.SubmitSweep(context, submit, op);
      });
  state.counters["values_per_s"] =
      benchmark::Counter(2 * kSweepSteps * state.iterations(), benchmark::Counter::kIsRate);
}
BENCHMARK(BM_SweepOnWorkers)
    ->Arg(1)
    ->Arg(2)
    ->Unit(benchmark::kSecond)
    ->UseRealTime()
    ->Iterations(1);

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
