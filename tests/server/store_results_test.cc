// Streamed results in the job store: chunks appended during a run, fenced by run and state,
// contiguous and in order, dropped when a run does not complete, shared by cache hits and
// followers, and read back in pages (ReadResultChunks) or whole (GetResult). Chunk rows are also
// counted behind the store's back, through a separate connection. Run on every store
// implementation (support/store_under_test.h).
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <string>
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

// A chunk as the test expects it back.
struct Expected {
  int64_t first_item;
  int64_t item_count;
  std::string bytes;
};

class StoreResultsTest : public ::testing::TestWithParam<drillbif::testing::StoreKind> {
 protected:
  void SetUp() override {
    ASSERT_TRUE(under_test_.Create());
    store_ = Open();
    ASSERT_NE(store_, nullptr);
  }

  std::unique_ptr<JobStore> Open() { return under_test_.Open(); }

  std::string SubmitOk(const std::string& request, const std::string& cache_key = "") {
    SubmitRequest submit;
    submit.kind = "sweep";
    submit.request = request;
    submit.cache_key = cache_key;
    return Must(store_->Submit(submit)).id;
  }

  // Claims the next job; a record with an empty id when none.
  JobRecord ClaimOk() {
    std::optional<JobRecord> job = Must(store_->ClaimNext("w"));
    EXPECT_TRUE(job.has_value());
    return job.value_or(JobRecord());
  }

  // Appends `chunks` to run `run` of `id`, each expected to succeed.
  void AppendAll(const std::string& id, int64_t run, const std::vector<Expected>& chunks) {
    for (const Expected& chunk : chunks) {
      Status s =
          store_->AppendResultChunk(id, run, 0, chunk.first_item, chunk.item_count, chunk.bytes);
      EXPECT_TRUE(s.ok()) << s.ToString();
    }
  }

  // Chunk rows in the file (all runs).
  int64_t ChunkRows() { return under_test_.SqlInt("SELECT COUNT(*) FROM result_chunks"); }

  drillbif::testing::StoreUnderTest under_test_{GetParam()};
  std::unique_ptr<JobStore> store_;
};

INSTANTIATE_TEST_SUITE_P(Stores, StoreResultsTest,
                         ::testing::ValuesIn(drillbif::testing::kStoreKinds),
                         drillbif::testing::StoreKindName);

void ExpectChunks(const std::vector<ResultChunk>& got, const std::vector<Expected>& want) {
  ASSERT_EQ(got.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(got[i].first_item, want[i].first_item) << i;
    EXPECT_EQ(got[i].item_count, want[i].item_count) << i;
    EXPECT_EQ(got[i].bytes, want[i].bytes) << i;
  }
}

// Three chunks with bytes that are not C strings.
const std::vector<Expected> kThreeChunks = {
    {0, 2, std::string("\x0a\x02p0\x0a\x02p1", 8)},
    {2, 3, std::string("\x0a\x01\0\x0a\x01\0\x0a\x01\0", 9)},
    {5, 1, std::string("\x0a\x02p5", 4)},
};

TEST_P(StoreResultsTest, AppendedChunksBecomeTheResultAtCompletion) {
  const std::string id = SubmitOk("r");
  const JobRecord job = ClaimOk();
  ASSERT_EQ(job.id, id);
  EXPECT_EQ(job.run, 1);
  AppendAll(id, job.run, kThreeChunks);
  // Not a result before completion.
  EXPECT_EQ(store_->GetResultInfo(id).status().code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->ReadResultChunks(id, 0, 0, 100).status().code(),
            StatusCode::kFailedPrecondition);
  ASSERT_TRUE(store_->Complete(id, job.run, "SUMMARY", 6).ok());

  const ResultInfo info = Must(store_->GetResultInfo(id));
  EXPECT_EQ(info.summary, "SUMMARY");
  EXPECT_EQ(info.total_items, 6);
  EXPECT_EQ(info.total_bytes, 7 + 8 + 9 + 4);
  EXPECT_EQ(info.points, 6);
  ExpectChunks(Must(store_->ReadResultChunks(id, 0, 0, std::numeric_limits<int64_t>::max())),
               kThreeChunks);
  // The whole result: the summary, then every chunk in order.
  EXPECT_EQ(Must(store_->GetResult(id)),
            "SUMMARY" + kThreeChunks[0].bytes + kThreeChunks[1].bytes + kThreeChunks[2].bytes);
}

TEST_P(StoreResultsTest, ACompletionWithoutChunksIsAllSummary) {
  const std::string id = SubmitOk("r");
  ASSERT_TRUE(store_->Complete(ClaimOk().id, "whole", 2).ok());
  const ResultInfo info = Must(store_->GetResultInfo(id));
  EXPECT_EQ(info.total_items, 0);
  EXPECT_EQ(info.total_bytes, 5);
  EXPECT_TRUE(Must(store_->ReadResultChunks(id, 0, 0, 10)).empty());
  EXPECT_EQ(Must(store_->GetResult(id)), "whole");
}

TEST_P(StoreResultsTest, ChunksMustBeContiguousAndInOrder) {
  const std::string id = SubmitOk("r");
  const int64_t run = ClaimOk().run;
  ASSERT_TRUE(store_->AppendResultChunk(id, run, 0, 0, 2, "ab").ok());
  struct Bad {
    int64_t first_item;
    int64_t item_count;
    const char* why;
  };
  for (const Bad& bad :
       {Bad{0, 1, "again"}, Bad{3, 1, "gap"}, Bad{1, 1, "overlap"}, Bad{2, 0, "no items"},
        Bad{2, -1, "negative count"}, Bad{-1, 1, "negative start"},
        Bad{std::numeric_limits<int64_t>::max(), 1, "end beyond INT64"}}) {
    Status s = store_->AppendResultChunk(id, run, 0, bad.first_item, bad.item_count, "x");
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << bad.why;
  }
  Status gap = store_->AppendResultChunk(id, run, 0, 3, 1, "x");
  EXPECT_THAT(gap.message(), HasSubstr("has 2 items there so far"));
  ASSERT_TRUE(store_->AppendResultChunk(id, run, 0, 2, 1, "c").ok());
  // Streams count their items apart: stream 3 starts at 0 whatever stream 0 holds.
  EXPECT_EQ(store_->AppendResultChunk(id, run, 3, 1, 1, "z").code(), StatusCode::kInvalidArgument);
  ASSERT_TRUE(store_->AppendResultChunk(id, run, 3, 0, 2, "yz").ok());
  for (int stream : {-1, kMaxResultStreams}) {
    EXPECT_EQ(store_->AppendResultChunk(id, run, stream, 0, 1, "x").code(),
              StatusCode::kInvalidArgument)
        << stream;
  }
  ASSERT_TRUE(store_->Complete(id, run, "", 5).ok());
  ExpectChunks(Must(store_->ReadResultChunks(id, 0, 0, 100)), {{0, 2, "ab"}, {2, 1, "c"}});
  ExpectChunks(Must(store_->ReadResultChunks(id, 3, 0, 100)), {{0, 2, "yz"}});
  EXPECT_TRUE(Must(store_->ReadResultChunks(id, 1, 0, 100)).empty());
  const ResultInfo info = Must(store_->GetResultInfo(id));
  EXPECT_EQ(info.total_items, 5);
  EXPECT_EQ(info.stream_items, (std::vector<int64_t>{3, 0, 0, 2}));
  // Whole: streams in order, each stream's chunks in order.
  EXPECT_EQ(Must(store_->GetResult(id)), "abcyz");
}

TEST_P(StoreResultsTest, AppendAndFinishAreFencedByStateAndRun) {
  const std::string id = SubmitOk("r", "K");
  const std::string follower = SubmitOk("r", "K");
  EXPECT_EQ(store_->AppendResultChunk(id, 1, 0, 0, 1, "x").code(), StatusCode::kFailedPrecondition)
      << "QUEUED";
  EXPECT_EQ(store_->AppendResultChunk("nope", 1, 0, 0, 1, "x").code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->AppendResultChunk(id, 0, 0, 0, 1, "x").code(), StatusCode::kInvalidArgument);
  const JobRecord first = ClaimOk();
  ASSERT_EQ(first.id, id);
  EXPECT_EQ(store_->AppendResultChunk(follower, 1, 0, 0, 1, "x").code(),
            StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->AppendResultChunk(id, 2, 0, 0, 1, "x").code(), StatusCode::kFailedPrecondition)
      << "a run that does not exist yet";
  ASSERT_TRUE(store_->AppendResultChunk(id, 1, 0, 0, 1, "old").ok());

  // A graceful requeue gives the attempt back: the next claim has the same attempts as the
  // first, so only the run number tells the stale worker apart.
  ASSERT_TRUE(store_->Requeue(id, 1).ok());
  const JobRecord second = ClaimOk();
  ASSERT_EQ(second.id, id);
  EXPECT_EQ(second.attempts, first.attempts);
  EXPECT_EQ(second.run, 2);
  Status stale = store_->AppendResultChunk(id, 1, 0, 0, 1, "stale");
  EXPECT_EQ(stale.code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(stale.message(), HasSubstr("stale"));
  EXPECT_EQ(store_->Complete(id, 1, "stale", 1).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->Fail(id, 1, StatusCode::kInternal, "stale").code(),
            StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->MarkCancelled(id, 1).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(store_->UpdateProgress(id, 1, 0.5, std::nullopt, 1).code(),
            StatusCode::kFailedPrecondition);
  ASSERT_TRUE(store_->UpdateProgress(id, 2, 0.25, std::nullopt, 1).ok());
  EXPECT_EQ(Must(store_->Get(id)).progress, 0.25);
  EXPECT_EQ(store_->Requeue(id, 1).code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(Must(store_->Get(id)).state, JobState::kRunning);  // None of them touched it.

  // The current run starts from item 0 again and completes; its follower reads the result.
  ASSERT_TRUE(store_->AppendResultChunk(id, 2, 0, 0, 1, "new").ok());
  ASSERT_TRUE(store_->Complete(id, 2, "S", 1).ok());
  EXPECT_EQ(Must(store_->GetResult(id)), "Snew");
  EXPECT_EQ(Must(store_->GetResult(follower)), "Snew");
  EXPECT_EQ(store_->AppendResultChunk(id, 2, 0, 1, 1, "late").code(),
            StatusCode::kFailedPrecondition)
      << "SUCCEEDED";
  EXPECT_EQ(ChunkRows(), 1);
}

TEST_P(StoreResultsTest, RunsThatDoNotCompleteLeaveNoChunks) {
  // Requeue: the next run starts over.
  const std::string requeued = SubmitOk("a");
  int64_t run = ClaimOk().run;
  AppendAll(requeued, run, kThreeChunks);
  EXPECT_EQ(ChunkRows(), 3);
  ASSERT_TRUE(store_->Requeue(requeued, run).ok());
  EXPECT_EQ(ChunkRows(), 0);
  run = ClaimOk().run;
  EXPECT_EQ(store_->AppendResultChunk(requeued, run, 0, 2, 1, "x").code(),
            StatusCode::kInvalidArgument)
      << "the count restarted at 0";
  ASSERT_TRUE(store_->AppendResultChunk(requeued, run, 0, 0, 1, "x").ok());
  ASSERT_TRUE(store_->Complete(requeued, run, "S", 1).ok());
  EXPECT_EQ(Must(store_->GetResult(requeued)), "Sx");
  EXPECT_EQ(ChunkRows(), 1);

  // Fail.
  const std::string failed = SubmitOk("b");
  run = ClaimOk().run;
  AppendAll(failed, run, kThreeChunks);
  ASSERT_TRUE(store_->Fail(failed, run, StatusCode::kInternal, "boom").ok());
  EXPECT_EQ(ChunkRows(), 1);

  // Cancel.
  const std::string cancelled = SubmitOk("c");
  run = ClaimOk().run;
  AppendAll(cancelled, run, kThreeChunks);
  ASSERT_EQ(Must(store_->Cancel(cancelled)), JobState::kRunning);
  ASSERT_TRUE(store_->MarkCancelled(cancelled, run).ok());
  EXPECT_EQ(ChunkRows(), 1);

  // A restart: the interrupted run's chunks go with RecoverAfterRestart.
  const std::string interrupted = SubmitOk("d");
  run = ClaimOk().run;
  AppendAll(interrupted, run, kThreeChunks);
  EXPECT_EQ(ChunkRows(), 4);
  store_ = Open();
  ASSERT_NE(store_, nullptr);
  EXPECT_EQ(ChunkRows(), 4);  // Opening alone does not touch the jobs.
  ASSERT_EQ(Must(store_->RecoverAfterRestart()).requeued, 1);
  EXPECT_EQ(ChunkRows(), 1);
  EXPECT_EQ(Must(store_->GetResult(requeued)), "Sx");  // The completed result stays.
}

TEST_P(StoreResultsTest, CacheHitsAndFollowersReadTheSharedChunksUntilTheLastHolderIsDeleted) {
  const std::string runner = SubmitOk("same", "K");
  const std::string follower = SubmitOk("same", "K");
  const int64_t run = ClaimOk().run;
  AppendAll(runner, run, kThreeChunks);
  ASSERT_TRUE(store_->Complete(runner, run, "S", 6).ok());
  StatusOr<SubmitResult> hit = store_->Submit({"sweep", "same", "K", ""});
  ASSERT_TRUE(hit.ok() && hit->cache_hit);

  const std::string whole = Must(store_->GetResult(runner));
  for (const std::string& id : {follower, hit->id}) {
    EXPECT_EQ(Must(store_->GetResult(id)), whole) << id;
    EXPECT_EQ(Must(store_->GetResultInfo(id)).total_items, 6) << id;
    ExpectChunks(Must(store_->ReadResultChunks(id, 0, 0, 1000)), kThreeChunks);
  }
  EXPECT_EQ(ChunkRows(), 3);  // Stored once.

  ASSERT_TRUE(store_->Delete(runner).ok());  // The job that ran goes; its chunks stay.
  ExpectChunks(Must(store_->ReadResultChunks(hit->id, 0, 0, 1000)), kThreeChunks);
  ASSERT_TRUE(store_->Delete(follower).ok());
  EXPECT_EQ(ChunkRows(), 3);
  ASSERT_TRUE(store_->Delete(hit->id).ok());  // The last holder: result and chunks go.
  EXPECT_EQ(ChunkRows(), 0);
  EXPECT_EQ(under_test_.SqlInt("SELECT COUNT(*) FROM results"), 0);
}

TEST_P(StoreResultsTest, ADoubleCompletionKeepsTheFirstResultAndDropsTheSecondRunsChunks) {
  // The first job's cancel is requested, so the identical second one does not follow it and
  // runs too; the first completes anyway (its worker finished before seeing the cancel).
  const std::string first = SubmitOk("same", "K");
  const int64_t first_run = ClaimOk().run;
  ASSERT_EQ(Must(store_->Cancel(first)), JobState::kRunning);
  const std::string second = SubmitOk("same", "K");
  ASSERT_TRUE(Must(store_->Get(second)).shared_with.empty());
  const int64_t second_run = ClaimOk().run;
  ASSERT_TRUE(store_->AppendResultChunk(first, first_run, 0, 0, 1, "first item").ok());
  ASSERT_TRUE(store_->AppendResultChunk(second, second_run, 0, 0, 2, "second items").ok());
  EXPECT_EQ(ChunkRows(), 2);
  ASSERT_TRUE(store_->Complete(first, first_run, "A", 1).ok());
  ASSERT_TRUE(store_->Complete(second, second_run, "B", 2).ok());
  EXPECT_EQ(Must(store_->Get(second)).state, JobState::kSucceeded);
  EXPECT_EQ(Must(store_->GetResult(second)), "Afirst item");
  EXPECT_EQ(Must(store_->GetResultInfo(second)).total_items, 1);
  EXPECT_EQ(ChunkRows(), 1);
}

TEST_P(StoreResultsTest, ReadResultChunksStopsAtTheByteBudgetAndStartsInsideAChunk) {
  const std::vector<Expected> chunks = {
      {0, 3, std::string(100, 'a')},
      {3, 2, std::string(50, 'b')},
      {5, 1, std::string(10, 'c')},
      {6, 4, std::string(200, 'd')},
  };
  const std::string id = SubmitOk("r");
  const int64_t run = ClaimOk().run;
  AppendAll(id, run, chunks);
  ASSERT_TRUE(store_->Complete(id, run, "S", 10).ok());
  const auto read = [&](int64_t first_item, int64_t max_bytes) {
    return Must(store_->ReadResultChunks(id, 0, first_item, max_bytes));
  };
  // At least one chunk, however small the budget.
  ExpectChunks(read(0, 1), {chunks[0]});
  // Stops once the bytes reach the budget: 100 + 50 = 150.
  ExpectChunks(read(0, 150), {chunks[0], chunks[1]});
  ExpectChunks(read(0, 151), {chunks[0], chunks[1], chunks[2]});
  // Starts with the chunk that contains first_item.
  ExpectChunks(read(4, 1), {chunks[1]});
  ExpectChunks(read(3, 1), {chunks[1]});
  ExpectChunks(read(5, 1000), {chunks[2], chunks[3]});
  ExpectChunks(read(9, 1), {chunks[3]});
  EXPECT_TRUE(read(10, 1000).empty());
  EXPECT_TRUE(read(std::numeric_limits<int64_t>::max(), 1000).empty());

  EXPECT_EQ(store_->ReadResultChunks(id, 0, -1, 10).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->ReadResultChunks(id, 0, 0, 0).status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(store_->ReadResultChunks("nope", 0, 0, 10).status().code(), StatusCode::kNotFound);
  EXPECT_EQ(store_->GetResultInfo("nope").status().code(), StatusCode::kNotFound);
}

}  // namespace
}  // namespace drillbif::server
