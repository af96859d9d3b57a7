// The largest job of each kind that a server's limits admit runs within the memory its kind is
// allowed, measured on a drillbif-server child process (VmHWM of /proc/PID/status, the peak RSS,
// against the idle server's); the request one step larger is refused at submit naming the limit
// and the request field; a 10^7-value sweep is refused at submit by the default limits.
//
// The limits are lowered (--job-limit) so that each largest job runs in seconds; the largest
// admitted request is found with the same estimate the server uses (jobs::CheckRequest and
// jobs::CheckCost), so the test follows the cost constants. The defaults' largest jobs are run by
// bench/largest_jobs.sh (docs/service.md, "Memory of the largest accepted jobs").
#include <gmock/gmock.h>
#include <google/protobuf/message.h>
#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "jobs/job_cost.h"
#include "jobs/registry.h"
#include "support/operations.h"
#include "support/server_process.h"
#include "support/small_requests.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

using drillbif::testing::PeakRssBytes;
using drillbif::testing::ServerProcess;
using drillbif::testing::Submit;
using drillbif::testing::WaitDone;
using google::longrunning::Operation;
using google::protobuf::Message;
using ::testing::HasSubstr;

// What the server holds beyond a job's own estimate while the job runs and its result is read
// back, each bounded by the server's defaults: SQLite's page cache (2 MiB a connection, cache_size
// -2000, for the store's connection and the workers'), the operation with its result inline when
// WaitOperation answers (up to --max-inline-result-bytes = 4 MiB, held as the stored blob, the
// parsed result, the packed Any and the serialized answer: 16 MiB), glibc's per-thread malloc
// arenas keeping freed pages of the worker and executor threads, and gRPC's call buffers: 32 MiB.
constexpr int64_t kAllowanceBytes = 32 << 20;

// One kind's largest admitted job: `request(x)` grows with x; the limits lowered for the test.
struct LargestJob {
  const char* kind;
  jobs::KindLimits limits;
  std::function<std::unique_ptr<Message>(int64_t x)> request;
  int64_t admitted, refused;  // a size admitted and one refused, bracketing the largest
  const char* limit_name;     // the limit the refusal of the next size names
  const char* field;          // the request field it names
};

// One worker, and `limits` as `kind`'s --job-limit flags.
std::vector<std::string> FlagsOf(const char* kind, const jobs::KindLimits& limits) {
  const std::string k = kind;
  std::ostringstream seconds;
  seconds << limits.max_seconds;
  return {"--workers",   "1",
          "--job-limit", k + ".seconds=" + seconds.str(),
          "--job-limit", k + ".result-bytes=" + std::to_string(limits.max_result_bytes),
          "--job-limit", k + ".memory-bytes=" + std::to_string(limits.max_memory_bytes)};
}

// The estimate of request(x), or nullopt when the limits refuse it (or it is invalid).
std::optional<jobs::JobCost> Admitted(const LargestJob& job, int64_t x) {
  const jobs::JobKindSpec* spec = jobs::FindKind(job.kind);
  const std::unique_ptr<Message> request = job.request(x);
  const StatusOr<jobs::JobCost> cost = jobs::CheckRequest(*spec, *request);
  if (!cost.ok() || !jobs::CheckCost(*cost, job.limits, job.kind).ok()) return std::nullopt;
  return *cost;
}

// Runs the largest admitted request of `job` on a fresh server with its limits and checks the
// server's peak RSS growth against the memory limit plus kAllowanceBytes, then that the next
// size is refused at submit naming the limit and the field.
void RunLargest(const LargestJob& job) {
  ASSERT_TRUE(Admitted(job, job.admitted)) << job.kind << " " << job.admitted;
  ASSERT_FALSE(Admitted(job, job.refused)) << job.kind << " " << job.refused;
  int64_t lo = job.admitted, hi = job.refused;  // lo admitted, hi refused
  while (hi - lo > 1) {
    const int64_t mid = lo + (hi - lo) / 2;
    (Admitted(job, mid) ? lo : hi) = mid;
  }
  const jobs::JobCost cost = *Admitted(job, lo);

  drillbif::testing::TempDir dir(std::string("drillbif_largest_") + job.kind);
  ServerProcess server(dir.path(), dir.path() + "/jobs.db", FlagsOf(job.kind, job.limits));
  ASSERT_TRUE(server.serving()) << "see " << server.log_path();
  const jobs::JobKindSpec& spec = *jobs::FindKind(job.kind);
  // The idle peak: after a call has been served, so that gRPC's and the store's first-use
  // allocations are not counted as the job's.
  Operation none;
  ASSERT_FALSE(Submit(server, spec, *job.request(hi), &none).ok());
  const int64_t idle = PeakRssBytes(server.pid());
  ASSERT_GT(idle, 0);

  Operation op;
  const auto start = std::chrono::steady_clock::now();
  const grpc::Status s = Submit(server, spec, *job.request(lo), &op);
  ASSERT_TRUE(s.ok()) << s.error_message();
  auto operations = google::longrunning::Operations::NewStub(server.channel());
  op = WaitDone(*operations, op.name(), 120);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  EXPECT_EQ(drillbif::testing::MetadataOf(op).state(), v1::SUCCEEDED)
      << op.error().message() << "; see " << server.log_path();
  const int64_t growth = PeakRssBytes(server.pid()) - idle;
  std::printf(
      "%s: largest admitted size %lld (estimate %.1f MB of memory, %.1f s); ran %.1f s; "
      "peak RSS growth %.1f MB (idle %.1f MB), limit %.1f MB + allowance %.1f MB\n",
      job.kind, static_cast<long long>(lo), cost.memory_bytes.amount / 1e6, cost.seconds.amount,
      seconds, growth / 1e6, idle / 1e6, job.limits.max_memory_bytes / 1e6, kAllowanceBytes / 1e6);
  EXPECT_LE(growth, job.limits.max_memory_bytes + kAllowanceBytes) << job.kind;

  // One step over: refused at submit, naming the limit and the field; no job is created.
  Operation refused;
  const grpc::Status over = Submit(server, spec, *job.request(lo + 1), &refused);
  EXPECT_EQ(over.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << over.error_message();
  EXPECT_THAT(over.error_message(), HasSubstr(job.limit_name));
  EXPECT_THAT(over.error_message(), HasSubstr(job.field));
}

// The kind's default limits with a lowered memory limit (and result limit when given).
jobs::KindLimits Lowered(const char* kind, int64_t memory_bytes, int64_t result_bytes = 0) {
  jobs::KindLimits limits = jobs::FindKind(kind)->default_limits;
  limits.max_memory_bytes = memory_bytes;
  if (result_bytes > 0) limits.max_result_bytes = result_bytes;
  return limits;
}

template <typename T>
std::unique_ptr<Message> Own(T request) {
  return std::make_unique<T>(std::move(request));
}

TEST(LargestJobMemory, TheLargestAdmittedSimulationStreamsWithinItsMemoryLimit) {
  // The simulation's result is streamed to the store: its memory estimate is a constant, so the
  // result limit binds. 24 MB of Poincare samples (~600000 periods, ~3 s) with the memory limit
  // at the estimate: a run that held its result would exceed it by more than the allowance.
  const jobs::KindLimits limits = Lowered("simulate", 4'000'000, 24'000'000);
  RunLargest({"simulate", limits,
              [](int64_t x) {
                v1::SimulateRequest r;
                r.set_transient_periods(0);
                r.set_sample_periods(static_cast<int32_t>(x));
                r.mutable_outputs()->set_poincare(true);
                return Own(r);
              },
              1000, 10'000'000, "max_result_bytes", "request.sample_periods"});
}

TEST(LargestJobMemory, TheLargestAdmittedSweepStaysWithinItsMemoryLimit) {
  // 100 values of b, as many samples each as 96 MB admits (~6000, ~3 s on the 2 cores).
  const jobs::KindLimits limits = Lowered("sweep", 96'000'000);
  RunLargest({"sweep", limits,
              [](int64_t x) {
                v1::SweepRequest r = drillbif::testing::SmallSweep(0.0, 100);
                r.set_threads(0);
                r.set_sample_periods(static_cast<int32_t>(x));
                return Own(r);
              },
              1, 100'000, "max_memory_bytes", "request.sample_periods"});
}

TEST(LargestJobMemory, TheLargestAdmittedContinuationStaysWithinItsMemoryLimit) {
  // Short steps, so that the branch takes every step of the budget 100 MB admits (~5000).
  const jobs::KindLimits limits = Lowered("continue", 100'000'000);
  RunLargest({"continue", limits,
              [](int64_t x) {
                v1::ContinueRequest r;
                r.set_param("b");
                r.set_min(0.0);
                r.set_max(0.2);
                r.set_direction(v1::ContinueRequest::INCREASING);
                r.set_initial_step(1e-6);
                r.set_max_step(1e-6);
                r.set_max_steps(static_cast<int32_t>(x));
                return Own(r);
              },
              10, 1'000'000, "max_memory_bytes", "request.max_steps"});
}

TEST(LargestJobMemory, TheLargestAdmittedTraceRegionStaysWithinItsMemoryLimit) {
  // The small (omega, a) box's curves and the largest square region grid 64 MB admits (~270^2).
  const jobs::KindLimits limits = Lowered("trace", 64'000'000);
  RunLargest({"trace", limits,
              [](int64_t x) {
                v1::TraceRequest r = drillbif::testing::SmallBoxTrace();
                r.mutable_region()->add_grid(static_cast<int32_t>(x));
                r.mutable_region()->add_grid(static_cast<int32_t>(x));
                return Own(r);
              },
              3, 10001, "max_memory_bytes", "request.region.grid"});
}

TEST(LargestJobMemory, TheLargestAdmittedOptimumStaysWithinItsMemoryLimit) {
  const jobs::KindLimits limits = Lowered("optimum", 64'000'000);
  RunLargest({"optimum", limits,
              [](int64_t x) {
                v1::OptimumRequest r;
                *r.mutable_trace() = drillbif::testing::SmallBoxTrace();
                r.add_grid(static_cast<int32_t>(x));
                r.add_grid(static_cast<int32_t>(x));
                return Own(r);
              },
              3, 10001, "max_memory_bytes", "request.grid"});
}

TEST(LargestJobMemory, ATenMillionValueSweepIsRefusedAtSubmitByTheDefaultLimits) {
  drillbif::testing::TempDir dir("drillbif_huge_sweep");
  ServerProcess server(dir.path(), dir.path() + "/jobs.db", {"--workers", "1"});
  ASSERT_TRUE(server.serving()) << "see " << server.log_path();
  const jobs::JobKindSpec& sweep = *jobs::FindKind("sweep");
  v1::SweepRequest request = drillbif::testing::SmallSweep(0.0, 10'000'000);
  // With the default 100 samples a value: 10^9 samples, over what one sweep may record.
  Operation op;
  grpc::Status s = Submit(server, sweep, request, &op);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::INVALID_ARGUMENT) << s.error_message();
  EXPECT_THAT(s.error_message(), HasSubstr("steps"));
  // One sample and no transient a value (10^7 samples, within that count): 700 MB of results,
  // over the 256 MB result limit (and, held 4-fold, the 1 GB memory limit).
  request.set_transient_periods(0);
  request.set_sample_periods(1);
  s = Submit(server, sweep, request, &op);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_THAT(s.error_message(), HasSubstr("request.steps"));
  EXPECT_THAT(s.error_message(), HasSubstr("max_result_bytes"));
  // Refused, not queued: the store has no job.
  auto operations = google::longrunning::Operations::NewStub(server.channel());
  google::longrunning::ListOperationsRequest list;
  google::longrunning::ListOperationsResponse page;
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  ASSERT_TRUE(operations->ListOperations(&context, list, &page).ok());
  EXPECT_EQ(page.operations_size(), 0);
}

}  // namespace
}  // namespace drillbif::server
