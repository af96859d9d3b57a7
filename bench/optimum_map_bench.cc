// What an optimum map costs in time, on the job's own threads and on a server's workers (its cells
// as child jobs in the store): the small (omega, a) box (omega in [0.05, 0.15], a in [0.25, 0.6],
// margins 0.01, 0.02, grid 41 x 41) over b in [0.14, 0.16], 8 cells. Every iteration asks a map
// never computed before (the range's end moved by 1e-9), so no cache answers it. Run:
//   build/bench/optimum_map_bench --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
// Counters: cells_per_s.
#include <benchmark/benchmark.h>
#include <grpcpp/grpcpp.h>
#include <stdlib.h>

#include <chrono>
#include <filesystem>
#include <memory>
#include <string>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "jobs/optimum_map_job.h"
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

// On a server with range(0) workers over a SQLite store (in this process), submitted and waited
// for through gRPC.
void BM_MapOnWorkers(benchmark::State& state) {
  std::string dir = (std::filesystem::temp_directory_path() / "drillbif_map_XXXXXX").string();
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
    v1::SubmitOptimumMapRequest submit;
    *submit.mutable_request() = Map(NextRound());
    google::longrunning::Operation op;
    grpc::ClientContext submit_context;
    if (!jobs->SubmitOptimumMap(&submit_context, submit, &op).ok()) {
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
    if (!op.has_response()) state.SkipWithError("the map failed");
  }
  state.counters["cells_per_s"] =
      benchmark::Counter(kCells * state.iterations(), benchmark::Counter::kIsRate);
  server->reset();
  std::filesystem::remove_all(dir);
}
BENCHMARK(BM_MapOnWorkers)->Arg(1)->Arg(2)->Unit(benchmark::kSecond)->UseRealTime()->Iterations(1);

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
