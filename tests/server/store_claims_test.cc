// Lanes, clients and fair claims in the job store: claims restricted to lanes, fairness across
// clients (fewest RUNNING first, then the oldest job), and queue limits checked atomically in
// Submit (per client and in total) that never refuse cache hits, followers or repeated
// request_ids. Run on every store implementation (support/store_under_test.h).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <atomic>
#include <latch>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "server/store/job_store.h"
#include "support/store_under_test.h"

namespace drillbif::server {
namespace {

using ::testing::HasSubstr;

template <typename T>
T Must(StatusOr<T> result) {
  EXPECT_TRUE(result.ok()) << result.status().ToString();
  return result.ok() ? std::move(result).value() : T{};
}

SubmitRequest Request(const std::string& body, const std::string& client, int lane = kLaneShort) {
  SubmitRequest submit;
  submit.kind = "sweep";
  submit.request = body;
  submit.client = client;
  submit.lane = lane;
  return submit;
}

class StoreClaimsTest : public ::testing::TestWithParam<drillbif::testing::StoreKind> {
 protected:
  void SetUp() override {
    ASSERT_TRUE(under_test_.Create());
    store_ = Open();
    ASSERT_NE(store_, nullptr);
  }

  std::unique_ptr<JobStore> Open() { return under_test_.Open(); }

  std::string SubmitOk(const SubmitRequest& request) { return Must(store_->Submit(request)).id; }

  // The id of the job a worker of `lanes` claims ("" when none).
  std::string Claim(std::vector<int> lanes = {}) {
    ClaimOptions options;
    options.lanes = std::move(lanes);
    std::optional<JobRecord> job = Must(store_->ClaimNext("w", options));
    return job ? job->id : std::string();
  }

  drillbif::testing::StoreUnderTest under_test_{GetParam()};
  std::unique_ptr<JobStore> store_;
};

INSTANTIATE_TEST_SUITE_P(Stores, StoreClaimsTest,
                         ::testing::ValuesIn(drillbif::testing::kStoreKinds),
                         drillbif::testing::StoreKindName);

TEST_P(StoreClaimsTest, WorkersClaimOnlyTheirLanes) {
  const std::string short1 = SubmitOk(Request("s1", "alice", kLaneShort));
  const std::string long1 = SubmitOk(Request("l1", "alice", kLaneLong));
  const std::string short2 = SubmitOk(Request("s2", "alice", kLaneShort));
  EXPECT_EQ(Claim({kLaneLong}), long1);
  EXPECT_EQ(Claim({kLaneLong}), "");
  EXPECT_EQ(Claim({kLaneShort}), short1);
  EXPECT_EQ(Claim({kLaneShort, kLaneLong}), short2);
  EXPECT_EQ(Claim(), "");

  const JobRecord job = Must(store_->Get(long1));
  EXPECT_EQ(job.client, "alice");
  EXPECT_EQ(job.lane, kLaneLong);
  EXPECT_STREQ(LaneName(kLaneLong), "long");
  EXPECT_STREQ(LaneName(kLaneShort), "short");

  ClaimOptions bad;
  bad.lanes = {kLaneCount};
  EXPECT_EQ(store_->ClaimNext("w", bad).status().code(), StatusCode::kInvalidArgument);
  bad.lanes = {-1};
  EXPECT_EQ(store_->ClaimNext("w", bad).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->Submit(Request("x", "alice", 2)).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->Submit(Request("x", "alice", -1)).status().code(),
            StatusCode::kInvalidArgument);
}

TEST_P(StoreClaimsTest, ClaimsAreFairAcrossClients) {
  // alice floods the queue first; bob and carol come later.
  std::map<std::string, std::string> name;  // id -> "a1", ...
  for (const char* tag : {"a1", "a2", "a3", "a4"}) name[SubmitOk(Request(tag, "alice"))] = tag;
  for (const char* tag : {"b1", "b2"}) name[SubmitOk(Request(tag, "bob"))] = tag;
  name[SubmitOk(Request("c1", "carol"))] = "c1";
  // Nothing completes, so each claim raises its client's RUNNING count. By the rule (fewest
  // RUNNING, then oldest): a1 (all at 0, a1 oldest); b1 (bob 0 < alice 1); c1 (carol 0); a2
  // (all at 1, a2 older than b2); b2 (bob 1 < alice 2); then alice's rest.
  std::vector<std::string> order;
  for (std::string id = Claim(); !id.empty(); id = Claim()) order.push_back(name[id]);
  EXPECT_EQ(order, (std::vector<std::string>{"a1", "b1", "c1", "a2", "b2", "a3", "a4"}));
}

TEST_P(StoreClaimsTest, FinishedJobsNoLongerCountAgainstTheirClient) {
  const std::string a1 = SubmitOk(Request("a1", "alice"));
  const std::string a2 = SubmitOk(Request("a2", "alice"));
  const std::string b1 = SubmitOk(Request("b1", "bob"));
  const std::string b2 = SubmitOk(Request("b2", "bob"));
  ASSERT_EQ(Claim(), a1);
  ASSERT_EQ(Claim(), b1);
  // Both have one job running; bob's finishes, so bob goes first although a2 is older.
  ASSERT_TRUE(store_->Complete(b1, "r", 0).ok());
  EXPECT_EQ(Claim(), b2);
  EXPECT_EQ(Claim(), a2);
}

TEST_P(StoreClaimsTest, FairnessCountsTheRunningJobsOfTheWorkersLanes) {
  // alice keeps the long lane busy; a short-lane worker still treats her as idle there.
  const std::string long1 = SubmitOk(Request("l1", "alice", kLaneLong));
  const std::string long2 = SubmitOk(Request("l2", "alice", kLaneLong));
  ASSERT_EQ(Claim({kLaneLong}), long1);
  ASSERT_EQ(Claim({kLaneLong}), long2);
  const std::string alice_short = SubmitOk(Request("s1", "alice", kLaneShort));
  const std::string bob_short = SubmitOk(Request("s2", "bob", kLaneShort));
  EXPECT_EQ(Claim({kLaneShort}), alice_short);  // Both at 0 running short jobs: the oldest.
  EXPECT_EQ(Claim({kLaneShort}), bob_short);
}

TEST_P(StoreClaimsTest, AnonymousJobsAreOneClient) {
  const std::string anon1 = SubmitOk(Request("1", ""));
  const std::string anon2 = SubmitOk(Request("2", ""));
  const std::string named = SubmitOk(Request("3", "dave"));
  EXPECT_EQ(Claim(), anon1);
  EXPECT_EQ(Claim(), named);
  EXPECT_EQ(Claim(), anon2);
}

TEST_P(StoreClaimsTest, PerClientLimitRefusesWithWhoHowManyAndTheLimit) {
  SubmitRequest request = Request("x", "alice");
  request.max_queued_per_client = 2;
  ASSERT_TRUE(store_->Submit(request).ok());
  ASSERT_TRUE(store_->Submit(request).ok());
  StatusOr<SubmitResult> refused = store_->Submit(request);
  EXPECT_EQ(refused.status().code(), StatusCode::kResourceExhausted);
  EXPECT_EQ(refused.status().message(), "client 'alice' has 2 jobs waiting (limit 2); retry later");
  // Another client is not held back by alice's queue.
  SubmitRequest bob = request;
  bob.client = "bob";
  EXPECT_TRUE(store_->Submit(bob).ok());
  // A claim makes room: the limit counts waiting jobs, not running ones.
  ASSERT_FALSE(Claim().empty());
  EXPECT_TRUE(store_->Submit(request).ok());

  SubmitRequest anonymous = Request("y", "");
  anonymous.max_queued_per_client = 1;
  ASSERT_TRUE(store_->Submit(anonymous).ok());
  EXPECT_EQ(store_->Submit(anonymous).status().message(),
            "anonymous clients have 1 jobs waiting (limit 1); retry later");
}

TEST_P(StoreClaimsTest, TotalLimitCountsEveryClientsWaitingJobs) {
  for (const char* client : {"a", "b", "c"}) ASSERT_TRUE(store_->Submit(Request("x", client)).ok());
  SubmitRequest request = Request("x", "d");
  request.max_queued = 3;
  StatusOr<SubmitResult> refused = store_->Submit(request);
  EXPECT_EQ(refused.status().code(), StatusCode::kResourceExhausted);
  EXPECT_EQ(refused.status().message(),
            "the job queue is full: 3 jobs waiting (limit 3); retry later");
  request.max_queued = 4;
  EXPECT_TRUE(store_->Submit(request).ok());
  EXPECT_EQ(store_->Submit(Request("x", "e")).status().code(), StatusCode::kOk)
      << "no limit given: none applies";
}

TEST_P(StoreClaimsTest, CacheHitsFollowersAndRepeatedRequestIdsAreNeverRefused) {
  // A finished result for key "done", a queued job for key "waiting" with a request_id.
  SubmitRequest done = Request("done", "alice");
  done.cache_key = "done";
  ASSERT_TRUE(store_->Submit(done).ok());
  const std::string ran = Claim();
  ASSERT_TRUE(store_->Complete(ran, "result", 1).ok());
  SubmitRequest waiting = Request("waiting", "alice");
  waiting.cache_key = "waiting";
  waiting.request_id = "rid-1";
  const std::string queued = SubmitOk(waiting);

  // Limits that refuse any new work.
  for (SubmitRequest request : {done, waiting}) {
    request.max_queued = 1;
    request.max_queued_per_client = 1;
    request.request_id.clear();
    StatusOr<SubmitResult> result = store_->Submit(request);
    ASSERT_TRUE(result.ok()) << result.status().ToString();
    EXPECT_TRUE(result->cache_hit || result->shared_with == queued);
  }
  SubmitRequest repeated = waiting;
  repeated.max_queued = 1;
  repeated.max_queued_per_client = 1;
  StatusOr<SubmitResult> again = store_->Submit(repeated);
  ASSERT_TRUE(again.ok()) << again.status().ToString();
  EXPECT_TRUE(again->deduplicated);
  EXPECT_EQ(again->id, queued);
  // New work is refused.
  SubmitRequest fresh = Request("fresh", "alice");
  fresh.max_queued = 1;
  EXPECT_EQ(store_->Submit(fresh).status().code(), StatusCode::kResourceExhausted);
}

// Four connections claim at once (with three clients, leases, and cancels of queued jobs
// arriving meanwhile): every job that was not cancelled is claimed exactly once, by one
// connection, in one run; a cancel that meets a claim leaves the job RUNNING with its cancel
// asked, never a claimed job CANCELLED under its worker.
TEST_P(StoreClaimsTest, ConcurrentClaimsTakeEachJobOnce) {
  constexpr int kJobs = 120;
  constexpr int kConnections = 4;
  std::vector<std::string> ids;
  for (int i = 0; i < kJobs; ++i) {
    ids.push_back(SubmitOk(Request("job " + std::to_string(i), "client" + std::to_string(i % 3))));
  }
  std::vector<std::unique_ptr<JobStore>> stores;
  for (int c = 0; c < kConnections; ++c) {
    stores.push_back(Open());
    ASSERT_NE(stores.back(), nullptr);
  }
  std::vector<std::vector<std::string>> claimed(kConnections);
  std::atomic<int> errors{0};
  std::latch start(kConnections + 1);
  std::vector<std::thread> threads;
  for (int c = 0; c < kConnections; ++c) {
    threads.emplace_back([&, c] {
      ClaimOptions options;
      options.lease_ms = 60000;
      start.arrive_and_wait();
      for (;;) {
        StatusOr<std::optional<JobRecord>> job =
            stores[c]->ClaimNext("w" + std::to_string(c), options);
        if (!job.ok()) {
          ++errors;
          continue;
        }
        if (!job->has_value()) break;
        claimed[c].push_back((*job)->id);
      }
    });
  }
  // Cancels of every tenth job, racing the claims.
  std::vector<JobState> after_cancel;
  start.arrive_and_wait();
  for (int i = 0; i < kJobs; i += 10) after_cancel.push_back(Must(store_->Cancel(ids[i])));
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(errors.load(), 0);
  std::map<std::string, int> times;
  for (const auto& list : claimed) {
    for (const std::string& id : list) ++times[id];
  }
  for (int i = 0; i < kJobs; ++i) {
    const JobRecord job = Must(store_->Get(ids[i]));
    if (job.state == JobState::kCancelled) {
      EXPECT_EQ(times.count(ids[i]), 0u) << "cancelled job " << i << " was claimed";
      continue;
    }
    EXPECT_EQ(job.state, JobState::kRunning) << i;
    EXPECT_EQ(times[ids[i]], 1) << i;
    EXPECT_EQ(job.attempts, 1) << i;
    EXPECT_EQ(job.run, 1) << i;
    if (i % 10 == 0) {
      EXPECT_TRUE(job.cancel_requested) << "claimed before its cancel: " << i;
    }
  }
  for (int k = 0; k < static_cast<int>(after_cancel.size()); ++k) {
    const JobRecord job = Must(store_->Get(ids[10 * k]));
    EXPECT_EQ(after_cancel[k], job.state) << "Cancel's answer for job " << 10 * k;
  }
}

// Eight threads on two store objects (two SQLite connections) submit 20 jobs each for one
// client with a limit of 10: exactly 10 are accepted, because the count and the insert are one
// transaction (a check outside it would let several threads see 9 and all insert).
TEST_P(StoreClaimsTest, LimitsHoldUnderConcurrentSubmits) {
  std::unique_ptr<JobStore> second = Open();
  ASSERT_NE(second, nullptr);
  constexpr int kThreads = 8;
  constexpr int kPerThread = 20;
  constexpr int kLimit = 10;
  std::atomic<int> accepted{0};
  std::atomic<int> refused{0};
  std::atomic<int> other_errors{0};
  std::latch start(kThreads);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      JobStore& store = t % 2 == 0 ? *store_ : *second;
      start.arrive_and_wait();
      for (int i = 0; i < kPerThread; ++i) {
        SubmitRequest request = Request(std::to_string(t) + "-" + std::to_string(i), "alice");
        request.max_queued_per_client = kLimit;
        StatusOr<SubmitResult> result = store.Submit(request);
        if (result.ok()) {
          ++accepted;
        } else if (result.status().code() == StatusCode::kResourceExhausted) {
          ++refused;
        } else {
          ++other_errors;
        }
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(accepted.load(), kLimit);
  EXPECT_EQ(refused.load(), kThreads * kPerThread - kLimit);
  EXPECT_EQ(other_errors.load(), 0);
  EXPECT_EQ(Must(store_->Stats()).queue_depth, kLimit);
}

TEST_P(StoreClaimsTest, StatsCountTheQueuePerLane) {
  SubmitOk(Request("s1", "a", kLaneShort));
  SubmitOk(Request("s2", "a", kLaneShort));
  SubmitOk(Request("l1", "a", kLaneLong));
  SubmitRequest follower = Request("l1", "b", kLaneLong);
  follower.cache_key = "L";
  SubmitOk(follower);
  SubmitOk(follower);  // Follows the previous one: waiting, but not claimable.
  const StoreStats stats = Must(store_->Stats());
  EXPECT_EQ(stats.queue_depth_by_lane[kLaneShort], 2);
  EXPECT_EQ(stats.queue_depth_by_lane[kLaneLong], 2);
  EXPECT_EQ(stats.queue_depth, 4);
  EXPECT_GT(stats.used_bytes, 0);
}

TEST_P(StoreClaimsTest, BadClientsAndLimitsAreRejected) {
  SubmitRequest request = Request("x", std::string(kMaxClientBytes + 1, 'c'));
  StatusOr<SubmitResult> long_client = store_->Submit(request);
  EXPECT_EQ(long_client.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(long_client.status().message(), HasSubstr("client"));
  request.client = std::string(kMaxClientBytes, 'c');
  EXPECT_TRUE(store_->Submit(request).ok());
  request.max_queued = -1;
  EXPECT_EQ(store_->Submit(request).status().code(), StatusCode::kInvalidArgument);
  request.max_queued = 0;
  request.max_queued_per_client = -1;
  EXPECT_EQ(store_->Submit(request).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace drillbif::server
