// The optimum job end to end (jobs::RunOptimum, what the server's workers run) over the
// reference (omega, a) box, omega in [0.05, 2], a in [0.01, 8] at b = 0.15, grid 196 x 800
// (drillctl optimum's default for --margin 0.02), once the curves are known: each timed request
// asks another margin (0.02, 0.03, 0.04 in turn) over the curves and region an earlier request left
// in the cache (jobs/optimum_cache.h), so it runs the query and the coexistence check at the answer
// (8 simulations of 500 forcing periods). The first request, untimed, traces the curves (tens of
// seconds) and fills the region (seconds). Run:
//   build/bench/optimum_bench --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
// Counters: reused (1 when both the curves and the region were reused), query_ms, check_ms.
#include <benchmark/benchmark.h>

#include "jobs/optimum_cache.h"
#include "jobs/optimum_job.h"

namespace drillbif {
namespace {

v1::OptimumRequest ReferenceBoxRequest(double margin) {
  v1::OptimumRequest r;
  v1::TraceRequest* t = r.mutable_trace();
  t->add_trace_params(std::string("omega"));  // not ("omega"): GCC 12 -Wrestrict false positive
  t->add_trace_params(std::string("a"));
  t->add_min(0.05);
  t->add_min(0.01);
  t->add_max(2.0);
  t->add_max(8.0);
  r.add_margin(margin);
  r.add_grid(196);
  r.add_grid(800);
  return r;
}

jobs::OptimumCache& WarmCache() {
  static jobs::OptimumCache* cache = [] {
    auto* c = new jobs::OptimumCache;
    (void)jobs::RunOptimum(ReferenceBoxRequest(0.02), {.optimum_cache = c});
    return c;
  }();
  return *cache;
}

void BM_OptimumOverKnownCurves(benchmark::State& state) {
  jobs::OptimumCache& cache = WarmCache();
  const double margins[] = {0.02, 0.03, 0.04};
  int i = 0;
  v1::OptimumResult last;
  for (auto _ : state) {
    StatusOr<v1::OptimumResult> r =
        jobs::RunOptimum(ReferenceBoxRequest(margins[i++ % 3]), {.optimum_cache = &cache});
    if (!r.ok()) {
      state.SkipWithError(r.status().ToString().c_str());
      return;
    }
    last = *r;
  }
  state.counters["reused"] = last.curves_reused() && last.region_reused();
  state.counters["query_ms"] = 1e3 * last.query_seconds();
  state.counters["check_ms"] = 1e3 * last.check_seconds();
}
BENCHMARK(BM_OptimumOverKnownCurves)->Unit(benchmark::kMillisecond);

}  // namespace
}  // namespace drillbif

BENCHMARK_MAIN();
