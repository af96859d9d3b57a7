// The trace job's memory on the period-2 reference box (docs/performance.md): jobs::RunTrace of
// omega in [0.05, 2], a in [0.01, 8] with period 2, its curves streamed to a sink that counts and
// drops them, as a server's worker streams them to the store: the engine's curves and what the
// job holds to stream them in order. One run (minutes):
//   build/bench/trace_job_bench --benchmark_filter=BM_TraceJobPeriodTwoBox
// Counters: curves (streamed), result_mb (bytes streamed), peak_rss_mb (the process' VmHWM).
#include <benchmark/benchmark.h>

#include <fstream>
#include <string>

#include "drillbif/v1/trace.pb.h"
#include "jobs/trace_job.h"

namespace drillbif {
namespace {

// The process' peak resident set (VmHWM) in MB, 0 if unknown.
double PeakRssMb() {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);) {
    if (line.rfind("VmHWM:", 0) == 0) return std::stod(line.substr(6)) / 1024.0;
  }
  return 0.0;
}

// Counts what is streamed and keeps none of it.
class CountingSink : public jobs::ResultSink {
 public:
  Status Append(const google::protobuf::Message& items, int64_t count) override {
    items_ += count;
    bytes_ += static_cast<double>(items.ByteSizeLong());
    return Status::Ok();
  }
  int64_t items() const { return items_; }
  double bytes() const { return bytes_; }

 private:
  int64_t items_ = 0;
  double bytes_ = 0.0;
};

// Arg: threads.
void BM_TraceJobPeriodTwoBox(benchmark::State& state) {
  v1::TraceRequest request;
  request.add_trace_params("omega");
  request.add_trace_params("a");
  request.add_min(0.05), request.add_min(0.01);
  request.add_max(2.0), request.add_max(8.0);
  request.set_period2(true);
  request.set_threads(static_cast<int>(state.range(0)));
  CountingSink sink;
  bool ok = true;
  for (auto _ : state) {
    jobs::RunContext context;
    context.sink = &sink;
    const StatusOr<v1::TraceResult> r = jobs::RunTrace(request, context);
    ok = r.ok() && r->status() == "COMPLETED";
  }
  state.counters["curves"] = static_cast<double>(sink.items());
  state.counters["result_mb"] = sink.bytes() / (1024.0 * 1024.0);
  state.counters["peak_rss_mb"] = PeakRssMb();
  if (!ok) state.SkipWithError("trace job failed");
}
BENCHMARK(BM_TraceJobPeriodTwoBox)
    ->Arg(2)
    ->Unit(benchmark::kMillisecond)
    ->Iterations(1)
    ->UseRealTime();

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
