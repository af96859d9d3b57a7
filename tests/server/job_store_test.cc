// JobStore semantics, the contract every store keeps, exercised on each implementation (an SQLite
// file in a temporary directory, a database of a throwaway PostgreSQL cluster): the job life
// cycle, request_id idempotency, the content-addressed cache and shared runs, cancellation,
// deletion, pagination, counters and bad input. The SQLite store's durability (restart, kill -9),
// concurrency and schema migration are in sqlite_job_store_test.cc.
#include "server/store/job_store.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <stdlib.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <set>
#include <string>
#include <vector>

#include "server/store/postgres_job_store.h"
#include "server/store/sqlite_job_store.h"
#include "support/store_under_test.h"

namespace drillbif::server {
namespace {

using ::testing::HasSubstr;
using ::testing::MatchesRegex;
using ::testing::Not;

// The value of a StatusOr the test expects to be OK. On an error: a test failure and T{} instead
// of undefined behaviour, so that one wrong result does not crash the checks that follow (and
// skip the temp dir's cleanup).
template <typename T>
T Must(StatusOr<T> result) {
  EXPECT_TRUE(result.ok()) << result.status().ToString();
  return result.ok() ? std::move(result).value() : T{};
}

using drillbif::testing::StoreKind;
using drillbif::testing::StoreUnderTest;

// Unix time in ms, as the stores read it.
int64_t NowForTest() {
  return std::chrono::duration_cast<std::chrono::milliseconds>(
             std::chrono::system_clock::now().time_since_epoch())
      .count();
}

class JobStoreTest : public ::testing::TestWithParam<StoreKind> {
 protected:
  void SetUp() override {
    ASSERT_TRUE(under_test_.Create());
    store_ = under_test_.Open();
    ASSERT_NE(store_, nullptr);
  }

  // Submits and returns the id (failing the test on error).
  std::string SubmitOk(const std::string& kind, const std::string& request,
                       const std::string& cache_key = "", const std::string& request_id = "") {
    StatusOr<SubmitResult> r = store_->Submit({kind, request, cache_key, request_id});
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    return r.ok() ? r->id : std::string();
  }

  // Claims the next job and returns its id ("" when none or on error).
  std::string ClaimOk(const std::string& worker = "w") {
    StatusOr<std::optional<JobRecord>> job = store_->ClaimNext(worker);
    EXPECT_TRUE(job.ok()) << job.status().ToString();
    return job.ok() && job->has_value() ? (*job)->id : std::string();
  }

  JobRecord GetOk(const std::string& id) {
    StatusOr<JobRecord> job = store_->Get(id);
    EXPECT_TRUE(job.ok()) << job.status().ToString();
    return job.ok() ? *job : JobRecord();
  }

  bool NothingToClaim() {
    StatusOr<std::optional<JobRecord>> job = store_->ClaimNext("w");
    return job.ok() && !job->has_value();
  }

  StoreUnderTest under_test_{GetParam()};
  std::unique_ptr<JobStore> store_;
};

INSTANTIATE_TEST_SUITE_P(Stores, JobStoreTest, ::testing::ValuesIn(testing::kStoreKinds),
                         testing::StoreKindName);

TEST_P(JobStoreTest, SubmitClaimProgressCompleteAndReadTheResult) {
  const std::string id = SubmitOk("simulate", std::string("req\0bytes", 9), "key-1");
  JobRecord queued = GetOk(id);
  EXPECT_EQ(queued.state, JobState::kQueued);
  EXPECT_EQ(queued.kind, "simulate");
  EXPECT_EQ(queued.request, std::string("req\0bytes", 9));  // Bytes, not C strings.
  EXPECT_EQ(queued.cache_key, "key-1");
  EXPECT_GT(queued.created_ms, 1600000000000);  // Unix ms, after 2020.
  EXPECT_EQ(queued.started_ms, 0);
  EXPECT_EQ(queued.attempts, 0);

  StatusOr<std::optional<JobRecord>> claimed = store_->ClaimNext("worker-7");
  ASSERT_TRUE(claimed.ok()) << claimed.status().ToString();
  ASSERT_TRUE(claimed->has_value());
  EXPECT_EQ((*claimed)->id, id);
  EXPECT_EQ((*claimed)->state, JobState::kRunning);
  EXPECT_EQ((*claimed)->request, std::string("req\0bytes", 9));
  EXPECT_EQ((*claimed)->attempts, 1);
  EXPECT_EQ((*claimed)->worker_id, "worker-7");
  EXPECT_GE((*claimed)->started_ms, queued.created_ms);
  EXPECT_TRUE(NothingToClaim());

  ASSERT_TRUE(store_->UpdateProgress(id, 0.25, 0.125, 7).ok());
  JobRecord running = GetOk(id);
  EXPECT_EQ(running.progress, 0.25);
  ASSERT_TRUE(running.current_value.has_value());
  EXPECT_EQ(*running.current_value, 0.125);
  EXPECT_EQ(running.points, 7);

  EXPECT_EQ(store_->GetResult(id).status().code(), StatusCode::kFailedPrecondition);
  const std::string result("result\0proto", 12);
  ASSERT_TRUE(store_->Complete(id, result, 42).ok());
  JobRecord done = GetOk(id);
  EXPECT_EQ(done.state, JobState::kSucceeded);
  EXPECT_EQ(done.progress, 1.0);
  EXPECT_EQ(done.points, 42);
  EXPECT_GE(done.finished_ms, done.started_ms);
  EXPECT_FALSE(done.cache_hit);
  StatusOr<std::string> bytes = store_->GetResult(id);
  ASSERT_TRUE(bytes.ok()) << bytes.status().ToString();
  EXPECT_EQ(*bytes, result);
}

TEST_P(JobStoreTest, CompletingTwiceIsRefusedAndKeepsTheFirstResult) {
  const std::string id = SubmitOk("simulate", "r");
  ASSERT_EQ(ClaimOk(), id);
  ASSERT_TRUE(store_->Complete(id, "first", 1).ok());
  Status again = store_->Complete(id, "second", 2);
  EXPECT_EQ(again.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(again.message(), HasSubstr("SUCCEEDED, not RUNNING"));
  EXPECT_EQ(store_->Fail(id, StatusCode::kInternal, "late").code(),
            StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->MarkCancelled(id).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->UpdateProgress(id, 0.5, std::nullopt, 1).code(),
            StatusCode::kFailedPrecondition);
  EXPECT_EQ(Must(store_->GetResult(id)), "first");
  EXPECT_EQ(GetOk(id).points, 1);
}

TEST_P(JobStoreTest, CompleteNeedsAClaim) {
  const std::string id = SubmitOk("simulate", "r");
  EXPECT_EQ(store_->Complete(id, "x", 0).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(GetOk(id).state, JobState::kQueued);
}

TEST_P(JobStoreTest, FailRecordsTheErrorAndHasNoResult) {
  const std::string id = SubmitOk("continue", "r");
  ASSERT_EQ(ClaimOk(), id);
  ASSERT_TRUE(store_->Fail(id, StatusCode::kInvalidArgument, "xi: must be > 0").ok());
  JobRecord job = GetOk(id);
  EXPECT_EQ(job.state, JobState::kFailed);
  EXPECT_EQ(job.error_code, StatusCode::kInvalidArgument);
  EXPECT_EQ(job.error_message, "xi: must be > 0");
  EXPECT_GT(job.finished_ms, 0);
  EXPECT_EQ(store_->GetResult(id).status().code(), StatusCode::kFailedPrecondition);
}

TEST_P(JobStoreTest, SameRequestIdReturnsTheSameJob) {
  StatusOr<SubmitResult> first = store_->Submit({"simulate", "body", "k", "client-req-1"});
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  EXPECT_FALSE(first->deduplicated);
  StatusOr<SubmitResult> retry = store_->Submit({"simulate", "body", "k", "client-req-1"});
  ASSERT_TRUE(retry.ok()) << retry.status().ToString();
  EXPECT_TRUE(retry->deduplicated);
  EXPECT_EQ(retry->id, first->id);
  EXPECT_EQ(GetOk(first->id).request_id, "client-req-1");

  // The same key for another request is the client's bug: refused, nothing created.
  StatusOr<SubmitResult> other_body = store_->Submit({"simulate", "other", "k2", "client-req-1"});
  EXPECT_EQ(other_body.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(other_body.status().message(), HasSubstr("client-req-1"));
  EXPECT_EQ(store_->Submit({"sweep", "body", "k", "client-req-1"}).status().code(),
            StatusCode::kFailedPrecondition);

  // Without a request_id, identical submits are separate jobs (sharing one run by cache_key).
  StatusOr<SubmitResult> no_key = store_->Submit({"simulate", "body", "", ""});
  ASSERT_TRUE(no_key.ok());
  EXPECT_NE(no_key->id, first->id);
  StatusOr<ListResult> all = store_->List({});
  ASSERT_TRUE(all.ok());
  EXPECT_EQ(all->jobs.size(), 2u);
}

TEST_P(JobStoreTest, IdenticalRequestAfterSuccessIsACacheHitThatNeverRuns) {
  const std::string first = SubmitOk("simulate", "body", "cache-K");
  ASSERT_EQ(ClaimOk(), first);
  ASSERT_TRUE(store_->Complete(first, "the result", 3).ok());

  StatusOr<SubmitResult> second = store_->Submit({"simulate", "body", "cache-K", ""});
  ASSERT_TRUE(second.ok()) << second.status().ToString();
  EXPECT_TRUE(second->cache_hit);
  EXPECT_NE(second->id, first);
  JobRecord hit = GetOk(second->id);
  EXPECT_EQ(hit.state, JobState::kSucceeded);
  EXPECT_TRUE(hit.cache_hit);
  EXPECT_EQ(hit.points, 3);
  EXPECT_EQ(hit.attempts, 0);
  EXPECT_EQ(Must(store_->GetResult(second->id)), "the result");
  EXPECT_TRUE(NothingToClaim());  // No engine run.

  StatusOr<StoreStats> stats = store_->Stats();
  ASSERT_TRUE(stats.ok());
  EXPECT_EQ(stats->cache_hits_total, 1);

  // Another key is not a hit; an empty key never is.
  EXPECT_FALSE(Must(store_->Submit({"simulate", "body", "cache-L", ""})).cache_hit);
  EXPECT_FALSE(Must(store_->Submit({"simulate", "body", "", ""})).cache_hit);
}

TEST_P(JobStoreTest, IdenticalRequestWhileRunningSharesTheRun) {
  const std::string a = SubmitOk("sweep", "body", "K");
  StatusOr<SubmitResult> b = store_->Submit({"sweep", "body", "K", ""});
  ASSERT_TRUE(b.ok());
  EXPECT_EQ(b->shared_with, a);
  EXPECT_FALSE(b->cache_hit);
  EXPECT_EQ(GetOk(b->id).shared_with, a);
  EXPECT_EQ(Must(store_->Stats()).queue_depth, 1);  // Only a can be claimed.

  ASSERT_EQ(ClaimOk(), a);
  EXPECT_TRUE(NothingToClaim());
  EXPECT_EQ(GetOk(b->id).state, JobState::kRunning);  // b mirrors a.
  ASSERT_TRUE(store_->UpdateProgress(a, 0.5, 0.3, 11).ok());
  JobRecord b_running = GetOk(b->id);
  EXPECT_EQ(b_running.progress, 0.5);
  EXPECT_EQ(b_running.current_value, 0.3);
  EXPECT_EQ(b_running.points, 11);
  // Only the worker of the job that runs can act on it.
  EXPECT_EQ(store_->Complete(b->id, "x", 0).code(), StatusCode::kFailedPrecondition);

  // A third identical submit while running shares it too.
  StatusOr<SubmitResult> c = store_->Submit({"sweep", "body", "K", ""});
  ASSERT_TRUE(c.ok());
  EXPECT_EQ(c->shared_with, a);
  EXPECT_EQ(GetOk(c->id).state, JobState::kRunning);

  ASSERT_TRUE(store_->Complete(a, "shared result", 20).ok());
  for (const std::string& id : {b->id, c->id}) {
    JobRecord job = GetOk(id);
    EXPECT_EQ(job.state, JobState::kSucceeded) << id;
    EXPECT_TRUE(job.cache_hit);
    EXPECT_EQ(job.points, 20);
    EXPECT_EQ(Must(store_->GetResult(id)), "shared result");
  }
  EXPECT_FALSE(GetOk(a).cache_hit);
  EXPECT_EQ(Must(store_->Stats()).cache_hits_total, 2);
}

TEST_P(JobStoreTest, FailureOfASharedRunFailsItsFollowersAndIsNotCached) {
  const std::string a = SubmitOk("trace", "body", "K");
  const std::string b = SubmitOk("trace", "body", "K");
  ASSERT_EQ(ClaimOk(), a);
  ASSERT_TRUE(store_->Fail(a, StatusCode::kFailedPrecondition, "chaotic start").ok());
  JobRecord follower = GetOk(b);
  EXPECT_EQ(follower.state, JobState::kFailed);
  EXPECT_EQ(follower.error_code, StatusCode::kFailedPrecondition);
  EXPECT_EQ(follower.error_message, "chaotic start");
  // Failures are not cached: the next identical request runs.
  StatusOr<SubmitResult> c = store_->Submit({"trace", "body", "K", ""});
  ASSERT_TRUE(c.ok());
  EXPECT_FALSE(c->cache_hit);
  EXPECT_TRUE(c->shared_with.empty());
  EXPECT_EQ(ClaimOk(), c->id);
}

TEST_P(JobStoreTest, CancelQueuedJobAtOnce) {
  const std::string id = SubmitOk("simulate", "r");
  StatusOr<JobState> state = store_->Cancel(id);
  ASSERT_TRUE(state.ok()) << state.status().ToString();
  EXPECT_EQ(*state, JobState::kCancelled);
  JobRecord job = GetOk(id);
  EXPECT_EQ(job.state, JobState::kCancelled);
  EXPECT_GT(job.finished_ms, 0);
  EXPECT_TRUE(NothingToClaim());
  // Idempotent.
  EXPECT_EQ(Must(store_->Cancel(id)), JobState::kCancelled);
}

TEST_P(JobStoreTest, CancelRunningJobAsksItsWorker) {
  const std::string id = SubmitOk("sweep", "r");
  ASSERT_EQ(ClaimOk(), id);
  EXPECT_FALSE(Must(store_->IsCancelRequested(id)));
  StatusOr<JobState> state = store_->Cancel(id);
  ASSERT_TRUE(state.ok());
  EXPECT_EQ(*state, JobState::kRunning);
  EXPECT_TRUE(Must(store_->IsCancelRequested(id)));
  EXPECT_TRUE(GetOk(id).cancel_requested);
  EXPECT_EQ(GetOk(id).state, JobState::kRunning);
  ASSERT_TRUE(store_->MarkCancelled(id).ok());
  EXPECT_EQ(GetOk(id).state, JobState::kCancelled);
  EXPECT_EQ(store_->GetResult(id).status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->MarkCancelled(id).code(), StatusCode::kFailedPrecondition);
}

TEST_P(JobStoreTest, CancelFinishedJobIsRefused) {
  const std::string id = SubmitOk("simulate", "r");
  ASSERT_EQ(ClaimOk(), id);
  ASSERT_TRUE(store_->Complete(id, "x", 0).ok());
  EXPECT_EQ(store_->Cancel(id).status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(GetOk(id).state, JobState::kSucceeded);
}

TEST_P(JobStoreTest, CancellingTheSharedRunHandsItToTheOldestFollower) {
  const std::string a = SubmitOk("sweep", "body", "K");
  const std::string b = SubmitOk("sweep", "body", "K");
  const std::string c = SubmitOk("sweep", "body", "K");
  ASSERT_EQ(ClaimOk(), a);
  ASSERT_EQ(Must(store_->Cancel(a)), JobState::kRunning);
  // A job being cancelled takes no new followers: d waits on its own.
  StatusOr<SubmitResult> d = store_->Submit({"sweep", "body", "K", ""});
  ASSERT_TRUE(d.ok());
  EXPECT_TRUE(d->shared_with.empty());
  ASSERT_TRUE(store_->MarkCancelled(a).ok());

  JobRecord promoted = GetOk(b);
  EXPECT_EQ(promoted.state, JobState::kQueued);
  EXPECT_TRUE(promoted.shared_with.empty());
  EXPECT_EQ(GetOk(c).shared_with, b);
  EXPECT_EQ(GetOk(c).state, JobState::kQueued);
  EXPECT_EQ(ClaimOk(), b);  // b is older than d.
  ASSERT_TRUE(store_->Complete(b, "R", 1).ok());
  EXPECT_EQ(GetOk(c).state, JobState::kSucceeded);
  EXPECT_EQ(Must(store_->GetResult(c)), "R");
  EXPECT_EQ(GetOk(a).state, JobState::kCancelled);
  // d is still queued (it runs on its own) and its result row is the same content address.
  EXPECT_EQ(ClaimOk(), d->id);
  ASSERT_TRUE(store_->Complete(d->id, "R", 1).ok());
  EXPECT_EQ(Must(store_->GetResult(d->id)), "R");
}

TEST_P(JobStoreTest, CancellingAFollowerLeavesTheSharedRunAlone) {
  const std::string a = SubmitOk("sweep", "body", "K");
  const std::string b = SubmitOk("sweep", "body", "K");
  ASSERT_EQ(ClaimOk(), a);
  EXPECT_EQ(Must(store_->Cancel(b)), JobState::kCancelled);  // Nothing runs for b: at once.
  EXPECT_FALSE(Must(store_->IsCancelRequested(a)));
  ASSERT_TRUE(store_->Complete(a, "R", 1).ok());
  EXPECT_EQ(GetOk(b).state, JobState::kCancelled);
  EXPECT_EQ(GetOk(a).state, JobState::kSucceeded);
}

TEST_P(JobStoreTest, CancellingAQueuedSharedRunPromotesTheFollower) {
  const std::string a = SubmitOk("sweep", "body", "K");
  const std::string b = SubmitOk("sweep", "body", "K");
  EXPECT_EQ(Must(store_->Cancel(a)), JobState::kCancelled);
  EXPECT_TRUE(GetOk(b).shared_with.empty());
  EXPECT_EQ(ClaimOk(), b);
}

TEST_P(JobStoreTest, RequeueGivesTheJobBackWithoutCountingTheAttempt) {
  const std::string id = SubmitOk("sweep", "r");
  ASSERT_EQ(ClaimOk(), id);
  ASSERT_TRUE(store_->UpdateProgress(id, 0.5, std::nullopt, 3).ok());
  ASSERT_TRUE(store_->Requeue(id).ok());
  JobRecord job = GetOk(id);
  EXPECT_EQ(job.state, JobState::kQueued);
  EXPECT_EQ(job.attempts, 0);
  EXPECT_EQ(job.progress, 0.0);
  EXPECT_EQ(job.points, 0);
  EXPECT_EQ(ClaimOk(), id);
  EXPECT_EQ(GetOk(id).attempts, 1);
  // A cancel asked before the requeue wins.
  ASSERT_EQ(Must(store_->Cancel(id)), JobState::kRunning);
  ASSERT_TRUE(store_->Requeue(id).ok());
  EXPECT_EQ(GetOk(id).state, JobState::kCancelled);
}

// Claims `id` with a lease of `lease_ms` and returns the record (failing the test if another job
// or none came).
JobRecord ClaimLeased(JobStore& store, const std::string& id, int64_t lease_ms,
                      const std::string& worker = "w") {
  ClaimOptions options;
  options.lease_ms = lease_ms;
  std::optional<JobRecord> job = Must(store.ClaimNext(worker, options));
  EXPECT_TRUE(job.has_value() && job->id == id);
  return job.value_or(JobRecord());
}

TEST_P(JobStoreTest, AnExpiredLeaseIsTakenBackAndItsWorkerCanNoLongerFinish) {
  const std::string id = SubmitOk("trace", "r");
  const int64_t before = NowForTest();
  const JobRecord first = ClaimLeased(*store_, id, 1000, "w1");
  const int64_t after = NowForTest();
  EXPECT_GE(first.lease_expires_ms, before + 1000);
  EXPECT_LE(first.lease_expires_ms, after + 1000);
  EXPECT_EQ(GetOk(id).lease_expires_ms, first.lease_expires_ms);
  // Not expired yet (the bound is strict: a lease is good until its last millisecond).
  RecoveryReport report = Must(store_->ReclaimExpiredLeases(first.lease_expires_ms));
  EXPECT_EQ(report.requeued + report.cancelled + report.failed, 0);
  EXPECT_EQ(GetOk(id).state, JobState::kRunning);

  report = Must(store_->ReclaimExpiredLeases(first.lease_expires_ms + 1));
  EXPECT_EQ(report.requeued, 1);
  JobRecord job = GetOk(id);
  EXPECT_EQ(job.state, JobState::kQueued);
  EXPECT_EQ(job.attempts, 1);  // The lost attempt counts (a crash loop must end).
  // The worker that lost its lease cannot renew it nor finish the job, before and after
  // another worker claims it.
  EXPECT_EQ(store_->RenewLease(id, first.run, 1000).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->Complete(id, first.run, "late", 1).code(), StatusCode::kFailedPrecondition);
  const JobRecord second = ClaimLeased(*store_, id, 1000, "w2");
  EXPECT_EQ(second.run, first.run + 1);
  EXPECT_EQ(second.attempts, 2);
  EXPECT_EQ(store_->RenewLease(id, first.run, 1000).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->Complete(id, first.run, "late", 1).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->AppendResultChunk(id, first.run, 0, 0, 1, "x").code(),
            StatusCode::kFailedPrecondition);
  EXPECT_TRUE(store_->Complete(id, second.run, "result", 1).ok());
  EXPECT_EQ(Must(store_->GetResult(id)), "result");
}

TEST_P(JobStoreTest, ARenewedLeaseIsKeptAndAClaimWithoutLeaseIsNeverTakenBack) {
  const std::string leased = SubmitOk("trace", "a");
  const std::string unleased = SubmitOk("trace", "b");
  const JobRecord job = ClaimLeased(*store_, leased, 1000);
  ASSERT_EQ(ClaimOk(), unleased);
  EXPECT_EQ(GetOk(unleased).lease_expires_ms, 0);
  const int64_t before = NowForTest();
  ASSERT_TRUE(store_->RenewLease(leased, job.run, 600000).ok());
  const int64_t renewed = GetOk(leased).lease_expires_ms;
  EXPECT_GE(renewed, before + 600000);
  const RecoveryReport report = Must(store_->ReclaimExpiredLeases(job.lease_expires_ms + 1));
  EXPECT_EQ(report.requeued + report.cancelled + report.failed, 0);
  EXPECT_EQ(GetOk(leased).state, JobState::kRunning);
  EXPECT_EQ(GetOk(unleased).state, JobState::kRunning);
  // RecoverAfterRestart (one process per store) takes back both.
  EXPECT_EQ(Must(store_->RecoverAfterRestart()).requeued, 2);
}

TEST_P(JobStoreTest, AnExpiredLeaseEndsACancelledJobAndFailsAJobThatKeepsLosingIt) {
  const std::string cancelled = SubmitOk("trace", "a");
  JobRecord job = ClaimLeased(*store_, cancelled, 1000);
  ASSERT_EQ(Must(store_->Cancel(cancelled)), JobState::kRunning);
  RecoveryReport report = Must(store_->ReclaimExpiredLeases(job.lease_expires_ms + 1));
  EXPECT_EQ(report.cancelled, 1);
  EXPECT_EQ(GetOk(cancelled).state, JobState::kCancelled);

  // Default max_attempts 3: taken back twice, failed the third time.
  const std::string crashing = SubmitOk("trace", "b");
  for (int attempt = 1; attempt <= 3; ++attempt) {
    job = ClaimLeased(*store_, crashing, 1000);
    report = Must(store_->ReclaimExpiredLeases(job.lease_expires_ms + 1));
    EXPECT_EQ(report.requeued, attempt < 3 ? 1 : 0) << attempt;
    EXPECT_EQ(report.failed, attempt < 3 ? 0 : 1) << attempt;
  }
  const JobRecord failed = GetOk(crashing);
  EXPECT_EQ(failed.state, JobState::kFailed);
  EXPECT_EQ(failed.error_code, StatusCode::kInternal);
  EXPECT_THAT(failed.error_message, HasSubstr("stopped renewing its lease, 3 times"));
}

TEST_P(JobStoreTest, BadLeasesAreRejected) {
  const std::string id = SubmitOk("trace", "a");
  ClaimOptions negative;
  negative.lease_ms = -1;
  EXPECT_EQ(store_->ClaimNext("w", negative).status().code(), StatusCode::kInvalidArgument);
  const JobRecord job = ClaimLeased(*store_, id, 1000);
  EXPECT_EQ(store_->RenewLease(id, job.run, 0).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->RenewLease("nope", 1, 1000).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->RenewLease(id, job.run, INT64_MAX).code(), StatusCode::kInvalidArgument);
  // A lease beyond the clock's range is accepted at claim and never expires.
  const std::string forever = SubmitOk("trace", "b");
  const JobRecord endless = ClaimLeased(*store_, forever, INT64_MAX);
  EXPECT_EQ(endless.lease_expires_ms, INT64_MAX);
  EXPECT_EQ(Must(store_->ReclaimExpiredLeases(INT64_MAX)).requeued, 1);  // `id` only
  EXPECT_EQ(GetOk(forever).state, JobState::kRunning);
}

TEST_P(JobStoreTest, FindSucceededNamesTheJobHoldingAKeysResult) {
  EXPECT_EQ(Must(store_->FindSucceeded("K")), std::nullopt);
  const std::string first = SubmitOk("optimum", "r", "K");
  EXPECT_EQ(Must(store_->FindSucceeded("K")), std::nullopt);  // queued: no result yet
  ASSERT_EQ(ClaimOk(), first);
  EXPECT_EQ(Must(store_->FindSucceeded("K")), std::nullopt);  // running
  ASSERT_TRUE(store_->Complete(first, "result", 1).ok());
  EXPECT_EQ(Must(store_->FindSucceeded("K")), first);
  // A later cache hit holds the same result; the oldest job is named.
  const std::string hit = SubmitOk("optimum", "r", "K");
  ASSERT_TRUE(GetOk(hit).cache_hit);
  EXPECT_EQ(Must(store_->FindSucceeded("K")), first);
  ASSERT_TRUE(store_->Delete(first).ok());
  EXPECT_EQ(Must(store_->FindSucceeded("K")), hit);
  EXPECT_EQ(Must(store_->FindSucceeded("other")), std::nullopt);
  EXPECT_EQ(store_->FindSucceeded("").status().code(), StatusCode::kInvalidArgument);
}

// Text kept as text is valid UTF-8 without NUL bytes in every store: identifiers that are not are
// refused (a store cutting a C string at the NUL would merge two request_ids), and messages and
// worker ids are kept with U+FFFD in place of what is not.
TEST_P(JobStoreTest, TextIsRefusedOrKeptAsValidUtf8WithoutNul) {
  const std::string nul("a\0b", 3);
  const std::string invalid = "a\xff\xfe";
  for (const auto& [field, text] : {std::pair{"request_id", nul}, {"request_id", invalid}}) {
    const Status s = store_->Submit({"sweep", "r", "", text}).status();
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(s.message(), HasSubstr(field));
  }
  EXPECT_EQ(store_->Submit({"sweep", "r", nul, ""}).status().code(), StatusCode::kInvalidArgument);
  SubmitRequest bad_client{"sweep", "r", "", ""};
  bad_client.client = invalid;
  EXPECT_EQ(store_->Submit(bad_client).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->Submit({std::string("sw\0eep", 6), "r", "", ""}).status().code(),
            StatusCode::kInvalidArgument);

  const std::string id = SubmitOk("sweep", "r");
  StatusOr<std::optional<JobRecord>> claimed = store_->ClaimNext(std::string("w\0x", 3));
  ASSERT_TRUE(claimed.ok() && claimed->has_value()) << claimed.status().ToString();
  EXPECT_EQ(GetOk(id).worker_id, "w\xEF\xBF\xBDx");
  ASSERT_TRUE(store_->Fail(id, StatusCode::kInternal, std::string("bad \0 and \xff", 11)).ok());
  EXPECT_EQ(GetOk(id).error_message, "bad \xEF\xBF\xBD and \xEF\xBF\xBD");
}

TEST_P(JobStoreTest, GetLeavesOutTheRequestBytesWhenAsked) {
  const std::string request(100000, 'q');
  const std::string id = SubmitOk("sweep", request);
  ASSERT_EQ(ClaimOk(), id);
  ASSERT_TRUE(store_->UpdateProgress(id, 0.25, 1.5, 7).ok());
  const JobRecord whole = GetOk(id);
  EXPECT_EQ(whole.request, request);
  StatusOr<JobRecord> slim = store_->Get(id, /*include_request=*/false);
  ASSERT_TRUE(slim.ok()) << slim.status().ToString();
  EXPECT_EQ(slim->request, "");
  // Everything else as the whole record says.
  EXPECT_EQ(slim->id, whole.id);
  EXPECT_EQ(slim->state, whole.state);
  EXPECT_EQ(slim->progress, whole.progress);
  EXPECT_EQ(slim->current_value, whole.current_value);
  EXPECT_EQ(slim->points, whole.points);
  EXPECT_EQ(slim->run, whole.run);
  EXPECT_EQ(slim->worker_id, whole.worker_id);
  EXPECT_EQ(store_->Get("nope", false).status().code(), StatusCode::kNotFound);
}

TEST_P(JobStoreTest, DeleteOnlyFinishedJobs) {
  const std::string queued = SubmitOk("simulate", "q");
  EXPECT_EQ(store_->Delete(queued).code(), StatusCode::kFailedPrecondition);
  const std::string running = ClaimOk();
  ASSERT_EQ(running, queued);
  Status refused = store_->Delete(running);
  EXPECT_EQ(refused.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(refused.message(), HasSubstr("RUNNING"));
  ASSERT_TRUE(store_->Complete(running, "x", 0).ok());
  ASSERT_TRUE(store_->Delete(running).ok());
  EXPECT_EQ(store_->Get(running).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->GetResult(running).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->Delete(running).code(), StatusCode::kNotFound);

  const std::string cancelled = SubmitOk("simulate", "c");
  ASSERT_TRUE(store_->Cancel(cancelled).ok());
  EXPECT_TRUE(store_->Delete(cancelled).ok());
}

TEST_P(JobStoreTest, ACachedResultLivesAsLongAsAJobHoldsIt) {
  const std::string a = SubmitOk("simulate", "body", "K");
  ASSERT_EQ(ClaimOk(), a);
  ASSERT_TRUE(store_->Complete(a, "R", 1).ok());
  const std::string b = SubmitOk("simulate", "body", "K");  // Cache hit.
  ASSERT_TRUE(store_->Delete(a).ok());
  EXPECT_EQ(Must(store_->GetResult(b)), "R");
  EXPECT_TRUE(Must(store_->Submit({"simulate", "body", "K", ""})).cache_hit);  // Still cached.
  // Delete every job holding it: the result goes, the next request runs.
  StatusOr<ListResult> all = store_->List({});
  ASSERT_TRUE(all.ok());
  for (const JobRecord& job : all->jobs) ASSERT_TRUE(store_->Delete(job.id).ok());
  StatusOr<SubmitResult> fresh = store_->Submit({"simulate", "body", "K", ""});
  ASSERT_TRUE(fresh.ok());
  EXPECT_FALSE(fresh->cache_hit);
  // The counter is monotonic: deleting hits does not lower it.
  EXPECT_EQ(Must(store_->Stats()).cache_hits_total, 2);
}

TEST_P(JobStoreTest, DeletingARequestIdFreesIt) {
  const std::string a = SubmitOk("simulate", "one", "", "rid");
  ASSERT_TRUE(store_->Cancel(a).ok());
  ASSERT_TRUE(store_->Delete(a).ok());
  StatusOr<SubmitResult> again = store_->Submit({"simulate", "two", "", "rid"});
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_FALSE(again->deduplicated);
}

// Walks all pages and returns the ids in order.
std::vector<std::string> AllPages(JobStore& store, ListRequest request, int* pages) {
  std::vector<std::string> ids;
  *pages = 0;
  for (;;) {
    StatusOr<ListResult> page = store.List(request);
    EXPECT_TRUE(page.ok()) << page.status().ToString();
    if (!page.ok()) break;
    ++*pages;
    EXPECT_LE(static_cast<int>(page->jobs.size()), request.page_size);
    for (const JobRecord& job : page->jobs) ids.push_back(job.id);
    if (page->next_page_token.empty()) break;
    request.page_token = page->next_page_token;
    if (*pages > 100) {
      ADD_FAILURE() << "pagination does not end";
      break;
    }
  }
  return ids;
}

TEST_P(JobStoreTest, PaginationReturnsEveryJobOnceInSubmissionOrder) {
  std::vector<std::string> submitted;
  for (int i = 0; i < 20; ++i) {
    submitted.push_back(
        SubmitOk(i % 3 == 0 ? "sweep" : "simulate", std::string("r") + std::to_string(i)));
  }
  // Finish a few so that the states differ.
  for (int i = 0; i < 5; ++i) {
    const std::string id = ClaimOk();
    ASSERT_TRUE(store_->Complete(id, "x", 0).ok());
  }
  for (int page_size : {1, 2, 7, 20, 50}) {
    int pages = 0;
    ListRequest request;
    request.page_size = page_size;
    EXPECT_EQ(AllPages(*store_, request, &pages), submitted) << "page_size " << page_size;
    EXPECT_EQ(pages, (20 + page_size - 1) / page_size) << "page_size " << page_size;
  }

  // Filters.
  ListRequest succeeded;
  succeeded.page_size = 2;
  succeeded.state = JobState::kSucceeded;
  int pages = 0;
  EXPECT_EQ(AllPages(*store_, succeeded, &pages),
            std::vector<std::string>(submitted.begin(), submitted.begin() + 5));
  ListRequest sweeps;
  sweeps.page_size = 3;
  sweeps.kind = "sweep";
  std::vector<std::string> expected_sweeps;
  for (int i = 0; i < 20; i += 3) expected_sweeps.push_back(submitted[i]);
  EXPECT_EQ(AllPages(*store_, sweeps, &pages), expected_sweeps);
}

TEST_P(JobStoreTest, PaginationIsStableWhileJobsAreSubmittedAndDeleted) {
  std::vector<std::string> submitted;
  for (int i = 0; i < 10; ++i) submitted.push_back(SubmitOk("simulate", std::to_string(i)));
  ListRequest request;
  request.page_size = 3;
  StatusOr<ListResult> first = store_->List(request);
  ASSERT_TRUE(first.ok());
  ASSERT_EQ(first->jobs.size(), 3u);
  // Delete an already listed job and submit new ones: the rest still comes exactly once.
  ASSERT_TRUE(store_->Cancel(submitted[0]).ok());
  ASSERT_TRUE(store_->Delete(submitted[0]).ok());
  for (int i = 10; i < 12; ++i) submitted.push_back(SubmitOk("simulate", std::to_string(i)));
  request.page_token = first->next_page_token;
  int pages = 0;
  std::vector<std::string> rest = AllPages(*store_, request, &pages);
  EXPECT_EQ(rest, std::vector<std::string>(submitted.begin() + 3, submitted.end()));
}

TEST_P(JobStoreTest, ListLeavesOutRequestBytesUnlessAsked) {
  SubmitOk("simulate", "big request");
  StatusOr<ListResult> plain = store_->List({});
  ASSERT_TRUE(plain.ok());
  ASSERT_EQ(plain->jobs.size(), 1u);
  EXPECT_TRUE(plain->jobs[0].request.empty());
  EXPECT_EQ(plain->jobs[0].kind, "simulate");
  ListRequest with_request;
  with_request.include_request = true;
  EXPECT_EQ(Must(store_->List(with_request)).jobs.at(0).request, "big request");
}

TEST_P(JobStoreTest, ListRejectsBadPageArguments) {
  ListRequest negative;
  negative.page_size = -1;
  EXPECT_EQ(store_->List(negative).status().code(), StatusCode::kInvalidArgument);
  // The last two are 2^63 and 2^64 - 1: beyond INT64, they must not wrap to a small or negative
  // seq (which would restart the listing or skip it).
  for (const char* token : {"garbage", "p", "pXYZ", "p12345678901234567", "pFF", "p-1",
                            "p8000000000000000", "pffffffffffffffff"}) {
    ListRequest bad;
    bad.page_token = token;
    EXPECT_EQ(store_->List(bad).status().code(), StatusCode::kInvalidArgument) << token;
  }
  // A hostile token is echoed only in part.
  ListRequest huge;
  huge.page_token = "p" + std::string(100000, 'z');
  StatusOr<ListResult> refused = store_->List(huge);
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_LT(refused.status().message().size(), 100u);
  // The largest seq is a valid token: the page after it is empty.
  SubmitOk("simulate", "r");
  ListRequest last;
  last.page_token = "p7fffffffffffffff";
  StatusOr<ListResult> page = store_->List(last);
  ASSERT_TRUE(page.ok()) << page.status().ToString();
  EXPECT_TRUE(page->jobs.empty());
  EXPECT_TRUE(page->next_page_token.empty());
}

TEST_P(JobStoreTest, StatsCountJobsByState) {
  const std::string a = SubmitOk("simulate", "a", "Ka");
  SubmitOk("simulate", "a", "Ka");  // Shares a: queued, but not claimable.
  const std::string c = SubmitOk("simulate", "c");
  SubmitOk("simulate", "d");
  ASSERT_EQ(ClaimOk(), a);
  ASSERT_EQ(ClaimOk(), c);
  ASSERT_TRUE(store_->Fail(c, StatusCode::kInternal, "boom").ok());
  StatusOr<StoreStats> stats = store_->Stats();
  ASSERT_TRUE(stats.ok()) << stats.status().ToString();
  EXPECT_EQ(stats->jobs_by_state[static_cast<int>(JobState::kQueued)], 1);
  EXPECT_EQ(stats->jobs_by_state[static_cast<int>(JobState::kRunning)], 2);  // a and its follower
  EXPECT_EQ(stats->jobs_by_state[static_cast<int>(JobState::kFailed)], 1);
  EXPECT_EQ(stats->jobs_by_state[static_cast<int>(JobState::kSucceeded)], 0);
  EXPECT_EQ(stats->queue_depth, 1);
  EXPECT_EQ(stats->cache_hits_total, 0);
}

TEST_P(JobStoreTest, ClaimsInSubmissionOrder) {
  std::vector<std::string> ids;
  for (int i = 0; i < 5; ++i) ids.push_back(SubmitOk("simulate", std::to_string(i)));
  for (const std::string& id : ids) EXPECT_EQ(ClaimOk(), id);
  EXPECT_TRUE(NothingToClaim());
}

TEST_P(JobStoreTest, IdsAreRandom128BitHex) {
  std::set<std::string> ids;
  for (int i = 0; i < 50; ++i) {
    const std::string id = SubmitOk("simulate", "same");
    EXPECT_THAT(id, MatchesRegex("[0-9a-f]{32}"));
    ids.insert(id);
  }
  EXPECT_EQ(ids.size(), 50u);
}

TEST_P(JobStoreTest, BadInputIsRejectedWithClearCodes) {
  StatusOr<SubmitResult> no_kind = store_->Submit({"", "r", "", ""});
  EXPECT_EQ(no_kind.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(no_kind.status().message(), HasSubstr("kind"));

  const std::string unknown = "0123456789abcdef0123456789abcdef";
  EXPECT_EQ(store_->Get(unknown).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->GetResult(unknown).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->Cancel(unknown).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->IsCancelRequested(unknown).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->Delete(unknown).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->Complete(unknown, "x", 0).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->Fail(unknown, StatusCode::kInternal, "x").code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->MarkCancelled(unknown).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->Requeue(unknown).code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->UpdateProgress(unknown, 0.5, std::nullopt, 0).code(), StatusCode::kNotFound);
  // SQL text in an id is just an unknown id.
  EXPECT_EQ(store_->Get("' OR 1=1 --").status().code(), StatusCode::kNotFound);

  const std::string id = SubmitOk("simulate", "r");
  ASSERT_EQ(ClaimOk(), id);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  EXPECT_EQ(store_->UpdateProgress(id, 1.5, std::nullopt, 0).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->UpdateProgress(id, nan, std::nullopt, 0).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->UpdateProgress(id, 0.5, nan, 0).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->UpdateProgress(id, 0.5, std::nullopt, -1).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->Complete(id, "x", -1).code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->Fail(id, StatusCode::kOk, "not an error").code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(GetOk(id).state, JobState::kRunning);  // None of them changed it.
}

TEST(SqliteJobStoreOpenTest, RejectsBadOptionsAndPaths) {
  EXPECT_EQ(SqliteJobStore::Open("").status().code(), StatusCode::kInvalidArgument);
  SqliteJobStoreOptions options;
  options.max_attempts = 0;
  EXPECT_EQ(SqliteJobStore::Open(::testing::TempDir() + "unused.db", options).status().code(),
            StatusCode::kInvalidArgument);
  StatusOr<std::unique_ptr<JobStore>> no_dir =
      SqliteJobStore::Open("/nonexistent-dir-for-drillbif/jobs.db");
  EXPECT_EQ(no_dir.status().code(), StatusCode::kUnavailable);
  EXPECT_THAT(no_dir.status().message(), HasSubstr("cannot read or write its file"));
  EXPECT_THAT(no_dir.status().message(), HasSubstr("/nonexistent-dir-for-drillbif/jobs.db"));
  options = SqliteJobStoreOptions();
  options.wal_size_limit_bytes = -1;
  EXPECT_EQ(SqliteJobStore::Open(::testing::TempDir() + "unused.db", options).status().code(),
            StatusCode::kInvalidArgument);
}

TEST(PostgresJobStoreOpenTest, RejectsBadOptionsUnreachableServersAndNewerSchemas) {
  EXPECT_EQ(PostgresJobStore::Open("").status().code(), StatusCode::kInvalidArgument);
  PostgresJobStoreOptions options;
  options.max_attempts = 0;
  EXPECT_EQ(PostgresJobStore::Open("postgresql:///jobs", options).status().code(),
            StatusCode::kInvalidArgument);
  // No server there: UNAVAILABLE, the password in neither the message nor the log.
  options = PostgresJobStoreOptions();
  options.password = "s3cret-pw";
  std::string log;
  options.log = [&](std::string_view line) { log += std::string(line) + "\n"; };
  const Status unreachable =
      PostgresJobStore::Open("postgresql://drillbif@/jobs?host=/nonexistent-dir-for-drillbif",
                             options)
          .status();
  EXPECT_EQ(unreachable.code(), StatusCode::kUnavailable) << unreachable.ToString();
  EXPECT_THAT(unreachable.message(), HasSubstr("unreachable"));
  EXPECT_THAT(unreachable.message(), Not(HasSubstr("s3cret")));
  EXPECT_THAT(log, HasSubstr("nonexistent-dir-for-drillbif"));
  EXPECT_THAT(log, Not(HasSubstr("s3cret")));

  // A database whose schema a newer build wrote is refused, and left as it was.
  drillbif::testing::PostgresCluster cluster;
  ASSERT_TRUE(cluster.ok() && cluster.CreateDatabase("jobs")) << cluster.error();
  ASSERT_TRUE(PostgresJobStore::Open(cluster.Uri("jobs")).ok());
  ASSERT_EQ(cluster.Query("jobs", "UPDATE drillbif_schema SET version = 99 RETURNING version"),
            "99");
  const Status newer = PostgresJobStore::Open(cluster.Uri("jobs")).status();
  EXPECT_EQ(newer.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(newer.message(), HasSubstr("schema version 99 is newer"));
  EXPECT_EQ(cluster.Query("jobs", "SELECT version FROM drillbif_schema"), "99");
}

TEST(PostgresJobStoreFaultTest, ALostServerIsUnavailableUntilAProbeFindsItBack) {
  drillbif::testing::PostgresCluster cluster;
  ASSERT_TRUE(cluster.ok() && cluster.CreateDatabase("jobs")) << cluster.error();
  std::unique_ptr<JobStore> store = Must(PostgresJobStore::Open(cluster.Uri("jobs")));
  ASSERT_NE(store, nullptr);
  const std::string id = Must(store->Submit({"sweep", "r", "", ""})).id;
  EXPECT_TRUE(store->Health().ok());

  ASSERT_TRUE(cluster.Stop());
  const StatusOr<JobRecord> lost = store->Get(id);
  EXPECT_EQ(lost.status().code(), StatusCode::kUnavailable) << lost.status().ToString();
  EXPECT_EQ(store->Health().code(), StatusCode::kUnavailable);
  EXPECT_EQ(store->Probe().code(), StatusCode::kUnavailable);
  EXPECT_EQ(store->Health().code(), StatusCode::kUnavailable);  // The fault stays.

  ASSERT_TRUE(cluster.Restart());
  EXPECT_TRUE(store->Probe().ok());
  EXPECT_TRUE(store->Health().ok());
  // The connection was opened again and the job is there.
  EXPECT_EQ(Must(store->Get(id)).state, JobState::kQueued);
}

TEST(JobStateNameTest, NamesEveryState) {
  EXPECT_STREQ(JobStateName(JobState::kQueued), "QUEUED");
  EXPECT_STREQ(JobStateName(JobState::kCancelled), "CANCELLED");
  EXPECT_TRUE(IsFinished(JobState::kFailed));
  EXPECT_FALSE(IsFinished(JobState::kRunning));
}

}  // namespace
}  // namespace drillbif::server
