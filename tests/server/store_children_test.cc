// Child jobs in the job store: a running parent's current run submits its tasks as children,
// which any worker (or the parent itself) claims and runs like any job; claims prefer children
// of running parents over new top-level jobs; a parent that leaves RUNNING, or is cancelled,
// cancels its unfinished children in the same transaction; List, Stats, Delete and Evict know
// about them; and older stores migrate. Run on every store implementation
// (support/store_under_test.h).
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <sqlite3.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <thread>
#include <vector>

#include "server/store/job_store.h"
#include "server/store/postgres_job_store.h"
#include "server/store/sqlite_job_store.h"
#include "support/store_under_test.h"

namespace drillbif::server {
namespace {

using ::testing::HasSubstr;

template <typename T>
T Must(StatusOr<T> result) {
  EXPECT_TRUE(result.ok()) << result.status().ToString();
  return result.ok() ? std::move(result).value() : T{};
}

// Later than any lease a test takes: every leased run has expired by then.
constexpr int64_t kEndOfTime = std::numeric_limits<int64_t>::max();

// A parent running with three children: one that succeeded, one running (claimed by a worker)
// and one queued.
struct Family {
  std::string parent;
  int64_t run = 0;  // The parent's run.
  std::string done;
  std::string running;
  int64_t running_run = 0;
  std::string queued;
};

class StoreChildrenTest : public ::testing::TestWithParam<drillbif::testing::StoreKind> {
 protected:
  void SetUp() override {
    ASSERT_TRUE(under_test_.Create());
    store_ = under_test_.Open();
    ASSERT_NE(store_, nullptr);
  }

  std::string SubmitTop(const std::string& body, const std::string& client = "",
                        int lane = kLaneShort) {
    SubmitRequest submit;
    submit.kind = "trace";
    submit.request = body;
    submit.client = client;
    submit.lane = lane;
    return Must(store_->Submit(submit)).id;
  }

  StatusOr<SubmitResult> SubmitChild(const std::string& parent, int64_t parent_run,
                                     const std::string& body, int lane = kLaneShort) {
    SubmitRequest submit;
    submit.kind = "trace_task";
    submit.request = body;
    submit.client = "alice";
    submit.lane = lane;
    submit.parent = parent;
    submit.parent_run = parent_run;
    return store_->Submit(submit);
  }

  std::string SubmitChildOk(const std::string& parent, int64_t parent_run, const std::string& body,
                            int lane = kLaneShort) {
    return Must(SubmitChild(parent, parent_run, body, lane)).id;
  }

  // The job a claim with these options takes (an empty record when none).
  JobRecord Claim(ClaimOptions options = {}) {
    std::optional<JobRecord> job = Must(store_->ClaimNext("w", options));
    return job ? *job : JobRecord{};
  }

  JobRecord ClaimChildOf(const std::string& parent, int64_t lease_ms = 0) {
    ClaimOptions options;
    options.parent = parent;
    options.lease_ms = lease_ms;
    return Claim(options);
  }

  // Submits a top-level job and claims it (it must be the only claimable one); returns its run.
  int64_t StartParent(std::string* id, int64_t lease_ms = 0) {
    *id = SubmitTop("parent " + std::to_string(++parents_));
    ClaimOptions options;
    options.lease_ms = lease_ms;
    const JobRecord job = Claim(options);
    EXPECT_EQ(job.id, *id);
    return job.run;
  }

  Family StartFamily(int64_t parent_lease_ms = 0) {
    Family f;
    f.run = StartParent(&f.parent, parent_lease_ms);
    f.done = SubmitChildOk(f.parent, f.run, "task 0");
    const JobRecord done = ClaimChildOf(f.parent);
    EXPECT_EQ(done.id, f.done);
    EXPECT_TRUE(store_->Complete(f.done, done.run, "result 0", 1).ok());
    f.running = SubmitChildOk(f.parent, f.run, "task 1");
    f.queued = SubmitChildOk(f.parent, f.run, "task 2");
    const JobRecord running = ClaimChildOf(f.parent);
    EXPECT_EQ(running.id, f.running);
    f.running_run = running.run;
    return f;
  }

  // What a parent leaving RUNNING must leave behind: its queued child CANCELLED, its running
  // child asked to stop (and able to record that it stopped), its finished child untouched.
  void ExpectChildrenStopped(const Family& f) {
    const JobRecord queued = Must(store_->Get(f.queued));
    EXPECT_EQ(queued.state, JobState::kCancelled);
    EXPECT_GT(queued.finished_ms, 0);
    EXPECT_EQ(queued.attempts, 0);
    const JobRecord running = Must(store_->Get(f.running));
    EXPECT_EQ(running.state, JobState::kRunning);
    EXPECT_TRUE(running.cancel_requested);
    EXPECT_TRUE(Must(store_->IsCancelRequested(f.running)));
    EXPECT_TRUE(store_->MarkCancelled(f.running, f.running_run).ok());
    EXPECT_EQ(Must(store_->Get(f.running)).state, JobState::kCancelled);
    EXPECT_EQ(Must(store_->Get(f.done)).state, JobState::kSucceeded);
    EXPECT_EQ(Must(store_->GetResult(f.done)), "result 0");
    // Nothing of the family is left to claim.
    EXPECT_EQ(ClaimChildOf(f.parent).id, "");
  }

  std::vector<std::string> Ids(const ListResult& list) {
    std::vector<std::string> ids;
    for (const JobRecord& job : list.jobs) ids.push_back(job.id);
    return ids;
  }

  int64_t SqlInt(const std::string& sql) { return under_test_.SqlInt(sql); }

  drillbif::testing::StoreUnderTest under_test_{GetParam()};
  std::unique_ptr<JobStore> store_;
  int parents_ = 0;
};

INSTANTIATE_TEST_SUITE_P(Stores, StoreChildrenTest,
                         ::testing::ValuesIn(drillbif::testing::kStoreKinds),
                         drillbif::testing::StoreKindName);

TEST_P(StoreChildrenTest, ARunningParentSubmitsChildrenThatRunLikeAnyJob) {
  std::string parent;
  const int64_t run = StartParent(&parent);
  const std::string child = SubmitChildOk(parent, run, "task", kLaneLong);
  JobRecord record = Must(store_->Get(child));
  EXPECT_EQ(record.parent, parent);
  EXPECT_EQ(record.state, JobState::kQueued);
  EXPECT_EQ(record.kind, "trace_task");
  EXPECT_EQ(record.client, "alice");  // The caller's, not the parent's.
  EXPECT_EQ(record.lane, kLaneLong);
  EXPECT_EQ(Must(store_->Get(parent)).parent, "");

  // Any worker takes it; the parent reads its result.
  const JobRecord claimed = Claim();
  EXPECT_EQ(claimed.id, child);
  EXPECT_EQ(claimed.parent, parent);
  EXPECT_EQ(claimed.request, "task");
  EXPECT_EQ(claimed.run, 1);
  ASSERT_TRUE(store_->AppendResultChunk(child, claimed.run, 0, 0, 1, "-item").ok());
  ASSERT_TRUE(store_->Complete(child, claimed.run, "sum", 1).ok());
  EXPECT_EQ(Must(store_->GetResult(child)), "sum-item");
  EXPECT_EQ(Must(store_->Get(child)).state, JobState::kSucceeded);
  EXPECT_EQ(Must(store_->Get(parent)).state, JobState::kRunning);  // Children finish alone.
}

TEST_P(StoreChildrenTest, AChildOfAnUnknownParentIsNotFound) {
  const StatusOr<SubmitResult> child = SubmitChild("0123456789abcdef0123456789abcdef", 1, "t");
  ASSERT_FALSE(child.ok());
  EXPECT_EQ(child.status().code(), StatusCode::kNotFound);
  EXPECT_THAT(child.status().message(), HasSubstr("parent"));
  EXPECT_EQ(Must(store_->Stats()).jobs_by_state[static_cast<int>(JobState::kQueued)], 0);
}

TEST_P(StoreChildrenTest, OnlyTheCurrentRunOfARunningParentMaySubmitChildren) {
  const auto expect_refused = [&](const std::string& parent, int64_t run, const char* why) {
    const StatusOr<SubmitResult> child = SubmitChild(parent, run, "t");
    ASSERT_FALSE(child.ok()) << why;
    EXPECT_EQ(child.status().code(), StatusCode::kFailedPrecondition) << why;
    EXPECT_THAT(child.status().message(), HasSubstr(why));
  };
  // A queued parent has no run yet.
  const std::string queued = SubmitTop("queued");
  expect_refused(queued, 1, "QUEUED");
  // A stale run: the parent was requeued and claimed again by another worker.
  ASSERT_EQ(Claim().id, queued);
  ASSERT_TRUE(store_->Requeue(queued, 1).ok());
  ASSERT_EQ(Claim().run, 2);
  expect_refused(queued, 1, "stale");
  EXPECT_TRUE(SubmitChild(queued, 2, "t").ok());
  // A parent being cancelled spawns no more work.
  ASSERT_EQ(Must(store_->Cancel(queued)), JobState::kRunning);
  expect_refused(queued, 2, "cancel");
  // A finished parent.
  ASSERT_TRUE(store_->MarkCancelled(queued, 2).ok());
  expect_refused(queued, 2, "CANCELLED");
  // Only the one child submitted by the current run exists (cancelled with its parent).
  ListRequest children;
  children.parent = queued;
  EXPECT_EQ(Must(store_->List(children)).jobs.size(), 1u);
}

TEST_P(StoreChildrenTest, BadChildRequestsAreInvalidArguments) {
  std::string parent;
  const int64_t run = StartParent(&parent);
  SubmitRequest cached;
  cached.kind = "trace_task";
  cached.parent = parent;
  cached.parent_run = run;
  cached.cache_key = "k";
  StatusOr<SubmitResult> refused = store_->Submit(cached);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(refused.status().message(), HasSubstr("cache_key"));

  SubmitRequest no_run = cached;
  no_run.cache_key = "";
  no_run.parent_run = 0;
  refused = store_->Submit(no_run);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(refused.status().message(), HasSubstr("parent_run"));

  SubmitRequest run_without_parent;
  run_without_parent.kind = "trace";
  run_without_parent.parent_run = run;
  refused = store_->Submit(run_without_parent);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(refused.status().message(), HasSubstr("parent_run"));
}

TEST_P(StoreChildrenTest, ChildrenAreNeitherRefusedNorCountedByQueueLimits) {
  std::string parent;
  const int64_t run = StartParent(&parent);
  SubmitRequest top;
  top.kind = "trace";
  top.client = "alice";
  top.request = "waiting";
  ASSERT_TRUE(store_->Submit(top).ok());  // One top-level job waiting.
  for (int i = 0; i < 3; ++i) {
    SubmitRequest child;
    child.kind = "trace_task";
    child.request = "task " + std::to_string(i);
    child.client = "alice";
    child.parent = parent;
    child.parent_run = run;
    child.max_queued = 1;
    child.max_queued_per_client = 1;
    EXPECT_TRUE(store_->Submit(child).ok()) << i;
  }
  // Four jobs are queued, but the limits count the one top-level job only.
  top.request = "second";
  top.max_queued = 2;
  top.max_queued_per_client = 2;
  EXPECT_TRUE(store_->Submit(top).ok());
  top.request = "third";
  const StatusOr<SubmitResult> third = store_->Submit(top);
  ASSERT_FALSE(third.ok());
  EXPECT_EQ(third.status().code(), StatusCode::kResourceExhausted);
}

TEST_P(StoreChildrenTest, ARepeatedRequestIdReturnsTheSameChild) {
  std::string parent;
  const int64_t run = StartParent(&parent);
  SubmitRequest child;
  child.kind = "trace_task";
  child.request = "task";
  child.request_id = "task-1";
  child.parent = parent;
  child.parent_run = run;
  const SubmitResult first = Must(store_->Submit(child));
  const SubmitResult again = Must(store_->Submit(child));
  EXPECT_EQ(again.id, first.id);
  EXPECT_TRUE(again.deduplicated);
  // The same request_id for the same request under another parent is another request.
  std::string other;
  ASSERT_TRUE(store_->Complete(parent, run, "", 0).ok());
  const int64_t other_run = StartParent(&other);
  child.parent = other;
  child.parent_run = other_run;
  const StatusOr<SubmitResult> reused = store_->Submit(child);
  ASSERT_FALSE(reused.ok());
  EXPECT_EQ(reused.status().code(), StatusCode::kFailedPrecondition);
}

TEST_P(StoreChildrenTest, AClaimForOneParentTakesOnlyItsQueuedChildrenOldestFirst) {
  std::string p1, p2;
  const int64_t run1 = StartParent(&p1);
  const int64_t run2 = StartParent(&p2);
  const std::string c11 = SubmitChildOk(p1, run1, "1.1");
  const std::string c21 = SubmitChildOk(p2, run2, "2.1");
  const std::string c12_long = SubmitChildOk(p1, run1, "1.2", kLaneLong);
  const std::string c13 = SubmitChildOk(p1, run1, "1.3");
  SubmitTop("top-level");

  ClaimOptions short_lane;
  short_lane.parent = p1;
  short_lane.lanes = {kLaneShort};
  EXPECT_EQ(Claim(short_lane).id, c11);
  EXPECT_EQ(Claim(short_lane).id, c13);  // Lanes still apply: the long task is left.
  EXPECT_EQ(Claim(short_lane).id, "");
  EXPECT_EQ(ClaimChildOf(p1).id, c12_long);
  EXPECT_EQ(ClaimChildOf(p1).id, "");  // Never another parent's child or a top-level job.
  EXPECT_EQ(ClaimChildOf(p2).id, c21);
  EXPECT_EQ(Must(store_->Get(c11)).worker_id, "w");
}

TEST_P(StoreChildrenTest, AnyWorkerTakesChildrenOfRunningParentsBeforeOlderTopLevelJobs) {
  std::string parent;
  const int64_t run = StartParent(&parent);
  const std::string older1 = SubmitTop("older 1", "bob");
  const std::string older2 = SubmitTop("older 2", "carol");
  const std::string c1 = SubmitChildOk(parent, run, "task 1");
  const std::string c2_long = SubmitChildOk(parent, run, "task 2", kLaneLong);
  const std::string c3 = SubmitChildOk(parent, run, "task 3");
  ClaimOptions short_lane;
  short_lane.lanes = {kLaneShort};
  EXPECT_EQ(Claim(short_lane).id, c1);
  EXPECT_EQ(Claim(short_lane).id, c3);
  EXPECT_EQ(Claim(short_lane).id, older1);  // The long task waits for a long-lane worker.
  EXPECT_EQ(Claim().id, c2_long);
  EXPECT_EQ(Claim().id, older2);
  EXPECT_EQ(Claim().id, "");
}

TEST_P(StoreChildrenTest, AChildsLeaseAndRunAreFencedAsAnyJobs) {
  std::string parent;
  const int64_t run = StartParent(&parent);
  const std::string child = SubmitChildOk(parent, run, "task");
  const JobRecord first = ClaimChildOf(parent, /*lease_ms=*/1000);
  ASSERT_EQ(first.id, child);
  EXPECT_GT(first.lease_expires_ms, 0);
  ASSERT_TRUE(store_->RenewLease(child, first.run, 1000).ok());
  // Its worker stops renewing: the child goes back to the queue (its parent, claimed without a
  // lease, runs on) and the stale worker can no longer finish it.
  const RecoveryReport report = Must(store_->ReclaimExpiredLeases(kEndOfTime));
  EXPECT_EQ(report.requeued, 1);
  EXPECT_EQ(Must(store_->Get(parent)).state, JobState::kRunning);
  EXPECT_EQ(Must(store_->Get(child)).state, JobState::kQueued);
  EXPECT_EQ(store_->Complete(child, first.run, "late", 0).code(), StatusCode::kFailedPrecondition);
  const JobRecord second = Claim();
  ASSERT_EQ(second.id, child);
  EXPECT_EQ(second.run, first.run + 1);
  EXPECT_EQ(second.attempts, 2);
  EXPECT_EQ(store_->RenewLease(child, first.run, 1000).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->AppendResultChunk(child, first.run, 0, 0, 1, "x").code(),
            StatusCode::kFailedPrecondition);
  ASSERT_TRUE(store_->Complete(child, second.run, "done", 1).ok());
  EXPECT_EQ(Must(store_->GetResult(child)), "done");
}

TEST_P(StoreChildrenTest, CompletingAParentStopsItsUnfinishedChildren) {
  const Family f = StartFamily();
  ASSERT_TRUE(store_->Complete(f.parent, f.run, "whole", 3).ok());
  EXPECT_EQ(Must(store_->Get(f.parent)).state, JobState::kSucceeded);
  ExpectChildrenStopped(f);
}

TEST_P(StoreChildrenTest, FailingAParentStopsItsUnfinishedChildren) {
  const Family f = StartFamily();
  ASSERT_TRUE(store_->Fail(f.parent, f.run, StatusCode::kInternal, "broke").ok());
  EXPECT_EQ(Must(store_->Get(f.parent)).state, JobState::kFailed);
  ExpectChildrenStopped(f);
}

TEST_P(StoreChildrenTest, AParentMarkedCancelledStopsItsUnfinishedChildren) {
  const Family f = StartFamily();
  ASSERT_TRUE(store_->MarkCancelled(f.parent, f.run).ok());
  EXPECT_EQ(Must(store_->Get(f.parent)).state, JobState::kCancelled);
  ExpectChildrenStopped(f);
}

TEST_P(StoreChildrenTest, ARequeuedParentStopsItsChildrenAndItsNextRunStartsAfresh) {
  const Family f = StartFamily();
  ASSERT_TRUE(store_->Requeue(f.parent, f.run).ok());
  EXPECT_EQ(Must(store_->Get(f.parent)).state, JobState::kQueued);
  ExpectChildrenStopped(f);
  // The next claim is the parent's next run, not one of the old run's tasks.
  const JobRecord again = Claim();
  EXPECT_EQ(again.id, f.parent);
  EXPECT_EQ(again.run, f.run + 1);
}

TEST_P(StoreChildrenTest, AParentWhoseLeaseExpiredStopsItsChildren) {
  const Family f = StartFamily(/*parent_lease_ms=*/1000);  // Children claimed without a lease.
  const RecoveryReport report = Must(store_->ReclaimExpiredLeases(kEndOfTime));
  EXPECT_EQ(report.requeued, 1);
  EXPECT_EQ(Must(store_->Get(f.parent)).state, JobState::kQueued);
  ExpectChildrenStopped(f);
}

TEST_P(StoreChildrenTest, AParentTakenBackAsCancelledStopsItsChildren) {
  const Family f = StartFamily(/*parent_lease_ms=*/1000);
  // The cancel flag alone, as a Cancel leaves it, without Cancel's own cascade: the take-back
  // must stop the children by itself.
  ASSERT_EQ(
      SqlInt("UPDATE jobs SET cancel_requested = TRUE WHERE id = '" + f.parent + "' RETURNING 1"),
      1);
  const RecoveryReport report = Must(store_->ReclaimExpiredLeases(kEndOfTime));
  EXPECT_EQ(report.cancelled, 1);
  EXPECT_EQ(Must(store_->Get(f.parent)).state, JobState::kCancelled);
  ExpectChildrenStopped(f);
}

TEST_P(StoreChildrenTest, AParentTakenBackAsFailedStopsItsChildren) {
  std::string parent = SubmitTop("parent");
  ClaimOptions leased;
  leased.lease_ms = 1000;
  // Claimed and taken back until its last allowed attempt (the stores' max_attempts is 3).
  for (int attempt = 1; attempt < 3; ++attempt) {
    ASSERT_EQ(Claim(leased).id, parent);
    ASSERT_EQ(Must(store_->ReclaimExpiredLeases(kEndOfTime)).requeued, 1);
  }
  Family f;
  f.parent = parent;
  f.run = Claim(leased).run;
  ASSERT_EQ(f.run, 3);
  f.done = SubmitChildOk(parent, f.run, "task 0");
  const JobRecord done = ClaimChildOf(parent);
  ASSERT_TRUE(store_->Complete(f.done, done.run, "result 0", 1).ok());
  f.running = SubmitChildOk(parent, f.run, "task 1");
  f.queued = SubmitChildOk(parent, f.run, "task 2");
  f.running_run = ClaimChildOf(parent).run;
  const RecoveryReport report = Must(store_->ReclaimExpiredLeases(kEndOfTime));
  EXPECT_EQ(report.failed, 1);
  EXPECT_EQ(Must(store_->Get(parent)).state, JobState::kFailed);
  ExpectChildrenStopped(f);
}

TEST_P(StoreChildrenTest, RecoveryAfterARestartEndsTheChildrenOfARequeuedParent) {
  const Family f = StartFamily();
  // Every running job was interrupted: the parent runs again, and its running child, asked to
  // stop by the parent's requeue in the same pass, is cancelled rather than queued again.
  const RecoveryReport report = Must(store_->RecoverAfterRestart());
  EXPECT_EQ(report.requeued, 1);
  EXPECT_EQ(report.cancelled, 1);
  EXPECT_EQ(Must(store_->Get(f.parent)).state, JobState::kQueued);
  EXPECT_EQ(Must(store_->Get(f.running)).state, JobState::kCancelled);
  EXPECT_EQ(Must(store_->Get(f.queued)).state, JobState::kCancelled);
  EXPECT_EQ(Must(store_->Get(f.done)).state, JobState::kSucceeded);
  EXPECT_EQ(Claim().id, f.parent);
  EXPECT_EQ(Claim().id, "");
}

TEST_P(StoreChildrenTest, CancellingARunningParentReachesEveryTasksWorker) {
  const Family f = StartFamily();
  EXPECT_EQ(Must(store_->Cancel(f.parent)), JobState::kRunning);
  EXPECT_TRUE(Must(store_->IsCancelRequested(f.parent)));
  ExpectChildrenStopped(f);
  // The parent's worker stops last.
  ASSERT_TRUE(store_->MarkCancelled(f.parent, f.run).ok());
  EXPECT_EQ(Must(store_->Get(f.parent)).state, JobState::kCancelled);
}

TEST_P(StoreChildrenTest, ARunningChildFansOutAndItsStopReachesItsOwnChildren) {
  std::string parent;
  const int64_t run = StartParent(&parent);
  const std::string child = SubmitChildOk(parent, run, "task");
  const JobRecord claimed = ClaimChildOf(parent);
  ASSERT_EQ(claimed.id, child);
  const std::string grandchild = SubmitChildOk(child, claimed.run, "subtask");
  EXPECT_EQ(Must(store_->Get(grandchild)).parent, child);
  // The parent stops: its running child is asked to stop, and may spawn nothing more.
  ASSERT_TRUE(store_->Complete(parent, run, "whole", 1).ok());
  EXPECT_TRUE(Must(store_->IsCancelRequested(child)));
  EXPECT_EQ(SubmitChild(child, claimed.run, "more").status().code(),
            StatusCode::kFailedPrecondition);
  EXPECT_EQ(Must(store_->Get(grandchild)).state, JobState::kQueued);  // One level at a time.
  ASSERT_TRUE(store_->MarkCancelled(child, claimed.run).ok());
  EXPECT_EQ(Must(store_->Get(grandchild)).state, JobState::kCancelled);
  EXPECT_EQ(Claim().id, "");
}

TEST_P(StoreChildrenTest, ListShowsTopLevelJobsOrOneParentsChildrenInPages) {
  std::string parent;
  const int64_t run = StartParent(&parent);
  const std::string top = SubmitTop("top");
  std::vector<std::string> children;
  for (int i = 0; i < 5; ++i) children.push_back(SubmitChildOk(parent, run, std::to_string(i)));
  const std::string other_top = SubmitTop("other top");
  ASSERT_EQ(ClaimChildOf(parent).id, children[0]);

  EXPECT_EQ(Ids(Must(store_->List({}))), (std::vector<std::string>{parent, top, other_top}));
  ListRequest page;
  page.parent = parent;
  page.page_size = 2;
  std::vector<std::string> listed;
  int pages = 0;
  do {
    const ListResult result = Must(store_->List(page));
    for (const JobRecord& job : result.jobs) {
      EXPECT_EQ(job.parent, parent);
      listed.push_back(job.id);
    }
    page.page_token = result.next_page_token;
    ASSERT_LE(++pages, 3);
  } while (!page.page_token.empty());
  EXPECT_EQ(pages, 3);  // 2 + 2 + 1.
  EXPECT_EQ(listed, children);
  ListRequest queued;
  queued.parent = parent;
  queued.state = JobState::kQueued;
  EXPECT_EQ(Must(store_->List(queued)).jobs.size(), 4u);
  ListRequest none;
  none.parent = top;
  EXPECT_TRUE(Must(store_->List(none)).jobs.empty());
}

TEST_P(StoreChildrenTest, StatsCountChildrenInTheQueueDepth) {
  std::string parent;
  const int64_t run = StartParent(&parent);
  SubmitChildOk(parent, run, "a");
  SubmitChildOk(parent, run, "b");
  SubmitChildOk(parent, run, "c", kLaneLong);
  SubmitTop("top", "bob", kLaneLong);
  const StoreStats stats = Must(store_->Stats());
  EXPECT_EQ(stats.queue_depth, 4);
  EXPECT_EQ(stats.queue_depth_by_lane[kLaneShort], 2);
  EXPECT_EQ(stats.queue_depth_by_lane[kLaneLong], 2);
  EXPECT_EQ(stats.jobs_by_state[static_cast<int>(JobState::kQueued)], 4);
  EXPECT_EQ(stats.jobs_by_state[static_cast<int>(JobState::kRunning)], 1);
}

TEST_P(StoreChildrenTest, EvictionKeepsChildrenWhileTheirParentMayReadThem) {
  std::string parent;
  const int64_t run = StartParent(&parent);
  const std::string child = SubmitChildOk(parent, run, "task");
  ASSERT_TRUE(store_->Complete(child, ClaimChildOf(parent).run, "r", 1).ok());
  RetentionOptions everything_finished;
  everything_finished.max_age_ms = 1;
  EXPECT_EQ(Must(store_->Evict(everything_finished, kEndOfTime)).jobs_deleted, 0);
  EXPECT_EQ(Must(store_->GetResult(child)), "r");
  // Requeued, the parent is QUEUED: its next run may still find the child (its store is the
  // parent's business), so it stays.
  ASSERT_TRUE(store_->Requeue(parent, run).ok());
  EXPECT_EQ(Must(store_->Evict(everything_finished, kEndOfTime)).jobs_deleted, 0);
  const JobRecord again = Claim();
  ASSERT_EQ(again.id, parent);
  ASSERT_TRUE(store_->Complete(parent, again.run, "whole", 1).ok());
  EXPECT_EQ(Must(store_->Evict(everything_finished, kEndOfTime)).jobs_deleted, 2);
  EXPECT_EQ(store_->Get(child).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(SqlInt("SELECT COUNT(*) FROM results"), 0);
}

TEST_P(StoreChildrenTest, DeletingAParentDeletesItsFinishedChildren) {
  const Family f = StartFamily();
  const std::string unrelated = SubmitTop("unrelated");
  ASSERT_EQ(Must(store_->Cancel(f.parent)), JobState::kRunning);
  ASSERT_TRUE(store_->MarkCancelled(f.parent, f.run).ok());
  ASSERT_TRUE(store_->Delete(f.parent).ok());
  EXPECT_EQ(store_->Get(f.parent).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->Get(f.done).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->Get(f.queued).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(SqlInt("SELECT COUNT(*) FROM results"), 0);  // The done child's result went too.
  // The child still stopping stays until it has stopped; then eviction takes it.
  EXPECT_EQ(Must(store_->Get(f.running)).state, JobState::kRunning);
  ASSERT_TRUE(store_->MarkCancelled(f.running, f.running_run).ok());
  RetentionOptions everything_finished;
  everything_finished.max_age_ms = 1;
  EXPECT_EQ(Must(store_->Evict(everything_finished, kEndOfTime)).jobs_deleted, 1);
  EXPECT_EQ(store_->Get(f.running).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(Must(store_->Get(unrelated)).state, JobState::kQueued);
}

// Two workers claim a parent's children (each on its own connection, as two processes would)
// while a third connection cancels the parent. Whatever the interleaving, every child ends in
// exactly one way: claimed once (then RUNNING and asked to stop) or cancelled while queued.
TEST_P(StoreChildrenTest, ConcurrentClaimsAndACancelOfTheParentEndEveryChildOnce) {
  constexpr int kChildren = 60;
  constexpr int kClaimsBeforeCancel = 5;
  std::string parent;
  const int64_t run = StartParent(&parent);
  std::set<std::string> children;
  for (int i = 0; i < kChildren; ++i)
    children.insert(SubmitChildOk(parent, run, std::to_string(i)));

  std::atomic<int> claims{0};
  std::atomic<int> claimers_done{0};
  std::vector<std::vector<JobRecord>> claimed(2);
  std::vector<std::thread> threads;
  for (int w = 0; w < 2; ++w) {
    threads.emplace_back([&, w] {
      // Counted however the claimer ends, so that the cancel never waits for claims that
      // cannot come.
      struct Done {
        std::atomic<int>& done;
        ~Done() { ++done; }
      } done{claimers_done};
      std::unique_ptr<JobStore> store = under_test_.Open();
      if (store == nullptr) return;
      ClaimOptions options;
      options.parent = parent;
      for (;;) {
        StatusOr<std::optional<JobRecord>> job = store->ClaimNext("w" + std::to_string(w), options);
        EXPECT_TRUE(job.ok()) << job.status().ToString();
        if (!job.ok() || !job->has_value()) return;
        claimed[w].push_back(**job);
        ++claims;
        // A worker's poll, and a moment of work, between claims: without it SQLite's busy
        // handler (which sleeps while another connection writes) would let the claimers keep
        // the file's write lock until every child is taken, and the cancel would never race.
        EXPECT_TRUE(store->IsCancelRequested((**job).id).ok());
        std::this_thread::sleep_for(std::chrono::milliseconds(2));
      }
    });
  }
  threads.emplace_back([&] {
    std::unique_ptr<JobStore> store = under_test_.Open();
    if (store == nullptr) return;
    while (claims.load() < kClaimsBeforeCancel && claimers_done.load() < 2) {
      std::this_thread::yield();
    }
    EXPECT_EQ(Must(store->Cancel(parent)), JobState::kRunning);
  });
  for (std::thread& t : threads) t.join();

  std::map<std::string, int> times_claimed;
  for (const auto& list : claimed) {
    for (const JobRecord& job : list) {
      ++times_claimed[job.id];
      EXPECT_EQ(job.parent, parent);
      EXPECT_EQ(job.run, 1) << job.id;
    }
  }
  int running = 0;
  int cancelled = 0;
  for (const std::string& id : children) {
    const JobRecord job = Must(store_->Get(id));
    const auto it = times_claimed.find(id);
    if (it != times_claimed.end()) {
      EXPECT_EQ(it->second, 1) << id << " claimed twice";
      EXPECT_EQ(job.state, JobState::kRunning) << id;
      EXPECT_TRUE(job.cancel_requested) << id << " runs on without being asked to stop";
      EXPECT_TRUE(store_->MarkCancelled(id, job.run).ok()) << id;
      ++running;
    } else {
      EXPECT_EQ(job.state, JobState::kCancelled) << id;
      EXPECT_EQ(job.attempts, 0) << id;
      ++cancelled;
    }
  }
  EXPECT_EQ(running + cancelled, kChildren);
  EXPECT_GE(running, kClaimsBeforeCancel);
  std::printf("children claimed before the cancel reached them: %d, cancelled while queued: %d\n",
              running, cancelled);
  ASSERT_TRUE(store_->MarkCancelled(parent, run).ok());
  EXPECT_EQ(Must(store_->Stats()).jobs_by_state[static_cast<int>(JobState::kRunning)], 0);
}

// The interleaving a cancel must survive: a claim has taken a queued child (its row is locked,
// the change not yet committed) when the parent's cancel comes. The claim is made by hand on a
// connection of its own and held open; the cancel waits for it (SQLite: the file's write lock;
// PostgreSQL: the child's row lock) and must then ask the claimed child's worker to stop, not
// pass over a child that is no longer QUEUED.
TEST_P(StoreChildrenTest, ACancelThatWaitsForAClaimInProgressStopsTheClaimedChild) {
  std::string parent;
  const int64_t run = StartParent(&parent);
  const std::string child = SubmitChildOk(parent, run, "task");
  const std::string claim =
      "UPDATE jobs SET state = 1, run = run + 1, attempts = attempts + 1, worker_id = 'slow' "
      "WHERE id = '" +
      child + "' AND state = 0;";
  std::atomic<bool> holding{false};
  std::thread claimer;
  if (GetParam() == drillbif::testing::StoreKind::kSqlite) {
    claimer = std::thread([&] {
      sqlite3* db = nullptr;
      EXPECT_EQ(sqlite3_open(under_test_.path().c_str(), &db), SQLITE_OK);
      const bool claimed = sqlite3_exec(db, ("BEGIN IMMEDIATE; " + claim).c_str(), nullptr, nullptr,
                                        nullptr) == SQLITE_OK;
      EXPECT_TRUE(claimed) << sqlite3_errmsg(db);
      holding = true;  // Also on failure: the test goes on to report it, never waits forever.
      if (claimed) {
        std::this_thread::sleep_for(std::chrono::milliseconds(500));
        EXPECT_EQ(sqlite3_exec(db, "COMMIT", nullptr, nullptr, nullptr), SQLITE_OK);
      }
      sqlite3_close(db);
    });
  } else {
    // One psql command is one transaction: the row stays locked through the sleep. The claim
    // holds the row once its session sleeps; the table's lock alone is no sign of it, since
    // the UPDATE takes that lock while it is planned, before it reaches the row.
    claimer =
        std::thread([&] { EXPECT_EQ(SqlInt("SELECT 1; " + claim + " SELECT pg_sleep(1);"), 1); });
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
    while (!holding && std::chrono::steady_clock::now() < give_up) {
      holding = SqlInt("SELECT COUNT(*) FROM pg_stat_activity WHERE wait_event = 'PgSleep'") > 0;
    }
  }
  while (!holding && GetParam() == drillbif::testing::StoreKind::kSqlite) {
    std::this_thread::yield();
  }
  EXPECT_TRUE(holding) << "the claim never took the child's row";
  EXPECT_EQ(Must(store_->Cancel(parent)), JobState::kRunning);
  claimer.join();
  const JobRecord claimed = Must(store_->Get(child));
  EXPECT_EQ(claimed.worker_id, "slow");
  EXPECT_EQ(claimed.state, JobState::kRunning);
  EXPECT_TRUE(claimed.cancel_requested) << "the claimed child runs on, its cancel lost";
}

// Brings the store back to the previous schema version, as that version created it: the child
// column and indexes dropped, jobs_claimable as it was. The jobs in it stay.
void DowngradeToThePreviousSchema(drillbif::testing::StoreUnderTest& under_test) {
  constexpr const char* kDowngrade =
      "DROP INDEX jobs_by_parent; DROP INDEX jobs_queued_children; DROP INDEX jobs_claimable; "
      "ALTER TABLE jobs DROP COLUMN parent_id; "
      "CREATE INDEX jobs_claimable ON jobs(client, lane, seq) WHERE state = 0 AND shares IS NULL;";
  if (under_test.kind() == drillbif::testing::StoreKind::kSqlite) {
    sqlite3* db = nullptr;
    ASSERT_EQ(sqlite3_open(under_test.path().c_str(), &db), SQLITE_OK);
    const std::string sql = std::string(kDowngrade) + "PRAGMA user_version = 3;";
    EXPECT_EQ(sqlite3_exec(db, sql.c_str(), nullptr, nullptr, nullptr), SQLITE_OK)
        << sqlite3_errmsg(db);
    sqlite3_close(db);
  } else {
    // psql prints every statement's result: the SELECT comes first so that the first line is
    // its 1, and a statement failing after it fails the whole command (ON_ERROR_STOP).
    EXPECT_EQ(under_test.SqlInt(std::string("SELECT 1; ") + kDowngrade +
                                "UPDATE drillbif_schema SET version = 1;"),
              1);
  }
}

TEST_P(StoreChildrenTest, AStoreOfThePreviousSchemaMigratesKeepingItsJobsAsTopLevel) {
  const std::string done = SubmitTop("done");
  const JobRecord claimed = Claim();
  ASSERT_TRUE(store_->Complete(done, claimed.run, "result", 1).ok());
  const std::string running = SubmitTop("running");
  ASSERT_EQ(Claim().id, running);
  const std::string queued = SubmitTop("queued", "bob");
  store_.reset();
  DowngradeToThePreviousSchema(under_test_);
  ASSERT_FALSE(HasFailure());
  const bool sqlite = GetParam() == drillbif::testing::StoreKind::kSqlite;
  EXPECT_EQ(SqlInt(sqlite ? "PRAGMA user_version" : "SELECT version FROM drillbif_schema"),
            sqlite ? 3 : 1);

  store_ = under_test_.Open();
  ASSERT_NE(store_, nullptr);
  EXPECT_EQ(SqlInt(sqlite ? "PRAGMA user_version" : "SELECT version FROM drillbif_schema"),
            sqlite ? SqliteJobStore::kSchemaVersion : PostgresJobStore::kSchemaVersion);
  // The old jobs are top-level: listed, claimable, counted, with their results.
  EXPECT_EQ(Ids(Must(store_->List({}))), (std::vector<std::string>{done, running, queued}));
  EXPECT_EQ(Must(store_->Get(running)).parent, "");
  EXPECT_EQ(Must(store_->GetResult(done)), "result");
  EXPECT_EQ(Must(store_->Stats()).queue_depth, 1);
  // The running job may fan out now, and its children come first.
  const int64_t run = Must(store_->Get(running)).run;
  const std::string child = SubmitChildOk(running, run, "task");
  EXPECT_EQ(Claim().id, child);
  EXPECT_EQ(Claim().id, queued);
  // Claims and queue limits use the rebuilt index of top-level jobs.
  EXPECT_EQ(SqlInt(sqlite ? "SELECT sql LIKE '%parent_id%' FROM sqlite_master "
                            "WHERE name = 'jobs_claimable'"
                          : "SELECT (indexdef LIKE '%parent_id%')::int FROM pg_indexes "
                            "WHERE indexname = 'jobs_claimable'"),
            1);
}

}  // namespace
}  // namespace drillbif::server
