// What the job store sustains: job cycles (submit, claim with a lease, complete), lease renewals
// (the workers' heartbeats), reclaim passes and job reads (the watch hub's polls), on the SQLite
// file and on PostgreSQL (a throwaway cluster in /dev/shm or the temp dir, started as
// tests/support/postgres_cluster.h does: fsync off, so these are the store's own costs, not a
// disk's), from 1 and from 4 connections at once (processes sharing the store).
//
//   build/bench/store_bench --benchmark_repetitions=3 --benchmark_report_aggregates_only=true
//
// Arguments: /0 SQLite, /1 PostgreSQL; threads: connections, one store object each.
#include <benchmark/benchmark.h>
#include <stdlib.h>

#include <atomic>
#include <filesystem>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "server/store/job_store.h"
#include "server/store/postgres_job_store.h"
#include "server/store/sqlite_job_store.h"
#include "support/postgres_cluster.h"

namespace drillbif::server {
namespace {

// One store of each kind for the whole run, and a connection per benchmark thread.
class Stores {
 public:
  static Stores& Get() {
    static Stores stores;
    return stores;
  }

  // A new connection to store `kind` (0 SQLite, 1 PostgreSQL); nullptr when it cannot open.
  std::unique_ptr<JobStore> Open(int kind) {
    std::lock_guard<std::mutex> lock(mutex_);
    StatusOr<std::unique_ptr<JobStore>> store = kind == 0
                                                    ? SqliteJobStore::Open(dir_ + "/jobs.db")
                                                    : PostgresJobStore::Open(cluster_.Uri("jobs"));
    return store.ok() ? std::move(store).value() : nullptr;
  }

 private:
  Stores() {
    if (cluster_.ok()) cluster_.CreateDatabase("jobs");
    std::string pattern =
        std::filesystem::temp_directory_path().string() + "/drillbif_bench_XXXXXX";
    if (mkdtemp(pattern.data()) != nullptr) dir_ = pattern;
  }
  ~Stores() {
    std::error_code ignored;
    if (!dir_.empty()) std::filesystem::remove_all(dir_, ignored);
  }
  std::mutex mutex_;
  std::string dir_;
  testing::PostgresCluster cluster_;
};

std::atomic<int64_t> counter{0};

// A connection to the store the benchmark's argument names; nullptr (the benchmark skipped with
// an error) when it cannot be opened.
std::unique_ptr<JobStore> OpenOrSkip(benchmark::State& state) {
  std::unique_ptr<JobStore> store = Stores::Get().Open(static_cast<int>(state.range(0)));
  if (!store) state.SkipWithError("cannot open the store");
  return store;
}

// Each iteration: a job submitted, claimed with a lease and completed with a 1 KB result.
void BM_JobCycle(benchmark::State& state) {
  std::unique_ptr<JobStore> store = OpenOrSkip(state);
  if (!store) return;
  ClaimOptions claim;
  claim.lease_ms = 15000;
  const std::string result(1000, 'r');
  const std::string worker = "bench-" + std::to_string(state.thread_index());
  for (auto _ : state) {
    const std::string body = "job " + std::to_string(counter.fetch_add(1));
    StatusOr<SubmitResult> submitted = store->Submit({"sweep", body, "", ""});
    StatusOr<std::optional<JobRecord>> job = store->ClaimNext(worker, claim);
    if (!submitted.ok() || !job.ok() || !job->has_value()) {
      state.SkipWithError("submit or claim failed");
      break;
    }
    if (!store->Complete((*job)->id, (*job)->run, result, 1).ok()) {
      state.SkipWithError("complete failed");
      break;
    }
  }
  state.SetItemsProcessed(state.iterations());
}

// Each iteration: one lease renewal of a running job of this connection's.
void BM_RenewLease(benchmark::State& state) {
  std::unique_ptr<JobStore> store = OpenOrSkip(state);
  if (!store) return;
  ClaimOptions claim;
  claim.lease_ms = 15000;
  const std::string body = "leased " + std::to_string(counter.fetch_add(1));
  StatusOr<SubmitResult> submitted = store->Submit({"trace", body, "", ""});
  // Another thread may claim this job first; renew whichever this thread got.
  StatusOr<std::optional<JobRecord>> job = store->ClaimNext("renewer", claim);
  if (!submitted.ok() || !job.ok() || !job->has_value()) {
    state.SkipWithError("submit or claim failed");
    return;
  }
  for (auto _ : state) {
    if (!store->RenewLease((*job)->id, (*job)->run, 15000).ok()) {
      state.SkipWithError("renewal failed");
      break;
    }
  }
  state.SetItemsProcessed(state.iterations());
  (void)store->Complete((*job)->id, (*job)->run, "", 0);
}

// Each iteration: one read of a job (what the watch hub does per watched job and poll).
void BM_GetJob(benchmark::State& state) {
  std::unique_ptr<JobStore> store = OpenOrSkip(state);
  if (!store) return;
  StatusOr<SubmitResult> submitted =
      store->Submit({"sweep", "watched " + std::to_string(counter.fetch_add(1)), "", ""});
  if (!submitted.ok()) {
    state.SkipWithError("submit failed");
    return;
  }
  for (auto _ : state) {
    if (!store->Get(submitted->id).ok()) {
      state.SkipWithError("get failed");
      break;
    }
  }
  state.SetItemsProcessed(state.iterations());
}

// Each iteration: one pass of the reclaimer over the running jobs (none expired).
void BM_ReclaimPass(benchmark::State& state) {
  std::unique_ptr<JobStore> store = OpenOrSkip(state);
  if (!store) return;
  for (auto _ : state) {
    if (!store->ReclaimExpiredLeases(0).ok()) {
      state.SkipWithError("reclaim failed");
      break;
    }
  }
  state.SetItemsProcessed(state.iterations());
}

BENCHMARK(BM_JobCycle)->Arg(0)->Arg(1)->Threads(1)->Threads(4)->UseRealTime();
BENCHMARK(BM_RenewLease)->Arg(0)->Arg(1)->Threads(1)->Threads(4)->UseRealTime();
BENCHMARK(BM_ReclaimPass)->Arg(0)->Arg(1)->UseRealTime();
BENCHMARK(BM_GetJob)->Arg(0)->Arg(1)->UseRealTime();

}  // namespace
}  // namespace drillbif::server

BENCHMARK_MAIN();
