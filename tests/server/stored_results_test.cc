// Results in the store as pages (server/stored_results.h): a run's items written in chunks while
// it runs (ResultWriter), read back as pages bounded in items and bytes (ReadResultPage); the pages
// merged in order give the result the run produced, whatever the page size; the runtime
// result-size limit; the summary an Operation carries for a large result.
#include "server/stored_results.h"

#include <gmock/gmock.h>
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include <memory>
#include <string>
#include <vector>

#include "jobs/registry.h"
#include "support/sqlite_store.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

using google::protobuf::util::MessageDifferencer;
using ::testing::HasSubstr;

class StoredResultsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    store_ = drillbif::testing::OpenSqliteStore(dir_);
    ASSERT_NE(store_, nullptr);
  }

  // A RUNNING job of `kind` (claimed), whose record carries its run.
  JobRecord Running(const std::string& kind) {
    SubmitRequest submit;
    submit.kind = kind;
    submit.request = std::to_string(++submitted_);  // distinct requests
    EXPECT_TRUE(store_->Submit(submit).ok());
    StatusOr<std::optional<JobRecord>> claimed = store_->ClaimNext("test");
    EXPECT_TRUE(claimed.ok() && claimed->has_value());
    return claimed.ok() && claimed->has_value() ? **claimed : JobRecord();
  }

  // Merges pages of `page_size` (0: the server's choice) into one result, as a client does: the
  // first page whole, the paged items of the others.
  StatusOr<v1::SweepResult> ReadAll(const std::string& id, int page_size,
                                    const PageOptions& options, int* pages = nullptr) {
    const jobs::JobKindSpec& sweep = *jobs::FindKind(v1::SWEEP);
    v1::SweepResult merged;
    std::string token;
    int n = 0;
    do {
      v1::GetResultResponse page;
      DRILLBIF_RETURN_IF_ERROR(
          ReadResultPage(*store_, sweep, id, page_size, token, options, &page));
      if (n == 0) {
        merged = page.sweep();
      } else {
        for (const auto& v : page.sweep().up()) *merged.add_up() = v;
        for (const auto& v : page.sweep().down()) *merged.add_down() = v;
      }
      EXPECT_EQ(page.total_points(), 100 + 30);
      token = page.next_page_token();
      ++n;
    } while (!token.empty() && n < 10000);
    if (pages != nullptr) *pages = n;
    return merged;
  }

  drillbif::testing::TempDir dir_{"drillbif_stored_results"};
  std::unique_ptr<JobStore> store_;
  int submitted_ = 0;
};

// A sweep value with `samples` samples, ~40 bytes each.
v1::SweepPoint Value(double value, int samples) {
  v1::SweepPoint point;
  point.set_value(value);
  point.set_status("COMPLETED");
  for (int k = 0; k < samples; ++k) {
    v1::PoincarePoint* p = point.add_samples();
    p->set_period(500 + k);
    p->set_p(value + k);
    p->set_y(-value);
    p->set_q(0.5 * k);
  }
  return point;
}

// Streams 100 up values then 30 down values (single-item appends, as a run does) into `writer`
// and returns the whole result they make with `summary`'s fields.
v1::SweepResult StreamSweep(ResultWriter& writer, const v1::SweepResult& summary) {
  v1::SweepResult whole = summary;
  for (int i = 0; i < 100; ++i) {
    v1::SweepResult items;
    *items.add_up() = Value(0.1 + 0.001 * i, 1 + i % 5);
    EXPECT_TRUE(writer.Append(items, 1).ok());
    *whole.add_up() = items.up(0);
  }
  for (int i = 0; i < 30; ++i) {
    v1::SweepResult items;
    *items.add_down() = Value(0.2 - 0.001 * i, 3);
    EXPECT_TRUE(writer.Append(items, 1).ok());
    *whole.add_down() = items.down(0);
  }
  EXPECT_TRUE(writer.Flush().ok());
  return whole;
}

TEST_F(StoredResultsTest, PagesOfAnySizeMergeIntoTheResultTheRunProduced) {
  const JobRecord job = Running("sweep");
  const jobs::JobKindSpec& sweep = *jobs::FindKind(v1::SWEEP);
  ResultWriter writer(store_.get(), job, sweep, 0, /*chunk_bytes=*/1024);
  v1::SweepResult summary;
  summary.set_status("COMPLETED");
  summary.set_periods_total(123456);
  const v1::SweepResult whole = StreamSweep(writer, summary);
  EXPECT_EQ(writer.items(), 130);
  ASSERT_TRUE(store_->Complete(job.id, job.run, summary.SerializeAsString(), writer.items()).ok());

  PageOptions options;
  for (int page_size : {1, 2, 7, 64, 130, 1000}) {
    int pages = 0;
    StatusOr<v1::SweepResult> merged = ReadAll(job.id, page_size, options, &pages);
    ASSERT_TRUE(merged.ok()) << merged.status().ToString();
    EXPECT_TRUE(MessageDifferencer::Equals(*merged, whole)) << "page_size " << page_size;
    EXPECT_EQ(pages, (130 + page_size - 1) / page_size) << "page_size " << page_size;
  }
  // page_size 0 with a result under the whole-result limit: everything in one answer.
  v1::GetResultResponse all;
  ASSERT_TRUE(ReadResultPage(*store_, sweep, job.id, 0, "", options, &all).ok());
  EXPECT_TRUE(all.next_page_token().empty());
  EXPECT_TRUE(MessageDifferencer::Equals(all.sweep(), whole));
}

TEST_F(StoredResultsTest, PagesStayWithinTheByteLimitAndAlwaysAdvance) {
  const JobRecord job = Running("sweep");
  const jobs::JobKindSpec& sweep = *jobs::FindKind(v1::SWEEP);
  ResultWriter writer(store_.get(), job, sweep, 0, /*chunk_bytes=*/1024);
  const v1::SweepResult whole = StreamSweep(writer, v1::SweepResult());
  ASSERT_TRUE(store_->Complete(job.id, job.run, "", writer.items()).ok());

  PageOptions options;
  options.max_page_bytes = 2048;
  options.max_whole_bytes = 4096;  // the result (~14 kB) is larger: page_size 0 pages too
  std::string token;
  int pages = 0;
  do {
    v1::GetResultResponse page;
    ASSERT_TRUE(ReadResultPage(*store_, sweep, job.id, 0, token, options, &page).ok());
    // At most the byte limit plus one chunk (a page ends after the chunk that reaches it).
    EXPECT_LE(page.sweep().ByteSizeLong(), 2048u + 1024u + 200u);
    EXPECT_GT(page.sweep().up_size() + page.sweep().down_size(), 0);
    token = page.next_page_token();
    ++pages;
  } while (!token.empty() && pages < 1000);
  EXPECT_GE(pages, 5);
  StatusOr<v1::SweepResult> merged = ReadAll(job.id, 0, options);
  ASSERT_TRUE(merged.ok());
  EXPECT_TRUE(MessageDifferencer::Equals(*merged, whole));
}

TEST_F(StoredResultsTest, BadPageArgumentsAreInvalidArgument) {
  const JobRecord job = Running("sweep");
  const jobs::JobKindSpec& sweep = *jobs::FindKind(v1::SWEEP);
  ResultWriter writer(store_.get(), job, sweep, 0, 1024);
  (void)StreamSweep(writer, v1::SweepResult());
  ASSERT_TRUE(store_->Complete(job.id, job.run, "", writer.items()).ok());
  const PageOptions options;
  v1::GetResultResponse page;
  for (const std::string token :
       {"x", "o-1", "o12x", "o131", "o9223372036854775807", "o99999999999999999999"}) {
    const Status s = ReadResultPage(*store_, sweep, job.id, 5, token, options, &page);
    EXPECT_EQ(s.code(), StatusCode::kInvalidArgument) << token;
    EXPECT_THAT(s.message(), HasSubstr("page_token")) << token;
  }
  EXPECT_EQ(ReadResultPage(*store_, sweep, job.id, -1, "", options, &page).code(),
            StatusCode::kInvalidArgument);
  EXPECT_EQ(ReadResultPage(*store_, sweep, job.id, 100001, "", options, &page).code(),
            StatusCode::kInvalidArgument);
  // The end itself is a valid (empty, last) page.
  v1::GetResultResponse end;
  ASSERT_TRUE(ReadResultPage(*store_, sweep, job.id, 5, "o130", options, &end).ok());
  EXPECT_EQ(end.sweep().up_size() + end.sweep().down_size(), 0);
  EXPECT_TRUE(end.next_page_token().empty());
}

TEST_F(StoredResultsTest, TheWriterRefusesItemsBeyondTheResultLimitNamingIt) {
  const JobRecord job = Running("sweep");
  ResultWriter writer(store_.get(), job, *jobs::FindKind(v1::SWEEP), /*max_result_bytes=*/3000,
                      1024);
  Status refused;
  int accepted = 0;
  for (int i = 0; i < 1000 && refused.ok(); ++i) {
    v1::SweepResult items;
    *items.add_up() = Value(i, 3);
    refused = writer.Append(items, 1);
    accepted += refused.ok() ? 1 : 0;
  }
  EXPECT_EQ(refused.code(), StatusCode::kResourceExhausted);
  EXPECT_THAT(refused.message(), HasSubstr("max_result_bytes of sweep jobs"));
  EXPECT_LE(writer.bytes(), 3000);
  EXPECT_GT(accepted, 10);
  EXPECT_EQ(writer.error().code(), StatusCode::kResourceExhausted);
  // Items of another field, or of two fields at once, are not what a run may stream.
  v1::SweepResult two;
  two.add_up();
  two.add_down();
  ResultWriter other(store_.get(), Running("sweep"), *jobs::FindKind(v1::SWEEP), 0, 1024);
  EXPECT_EQ(other.Append(two, 2).code(), StatusCode::kInternal);
}

TEST_F(StoredResultsTest, AWholeResultIsMovedIntoChunksLeavingItsSummary) {
  const JobRecord job = Running("simulate");
  const jobs::JobKindSpec& simulate = *jobs::FindKind(v1::SIMULATE);
  v1::SimulateResult result;
  result.set_status("COMPLETED");
  result.set_rop(0.5);
  for (int i = 0; i < 50; ++i) result.add_poincare()->set_period(i);
  for (int i = 0; i < 20; ++i) result.add_events()->set_period(i);
  const v1::SimulateResult whole = result;
  ResultWriter writer(store_.get(), job, simulate, 0, 256);
  ASSERT_TRUE(writer.MoveItemsOf(&result).ok());
  ASSERT_TRUE(writer.Flush().ok());
  EXPECT_EQ(result.poincare_size() + result.events_size(), 0);
  EXPECT_EQ(result.rop(), 0.5);
  EXPECT_EQ(writer.items(), 70);
  ASSERT_TRUE(store_->Complete(job.id, job.run, result.SerializeAsString(), writer.items()).ok());

  // Pages of 9 items, merged: the same samples and events in the same order.
  v1::SimulateResult merged;
  std::string token;
  int n = 0;
  do {
    v1::GetResultResponse page;
    ASSERT_TRUE(ReadResultPage(*store_, simulate, job.id, 9, token, PageOptions(), &page).ok());
    EXPECT_EQ(page.total_points(), 70);
    if (n++ == 0) {
      merged = page.simulate();
    } else {
      for (const auto& p : page.simulate().poincare()) *merged.add_poincare() = p;
      for (const auto& e : page.simulate().events()) *merged.add_events() = e;
    }
    token = page.next_page_token();
  } while (!token.empty());
  EXPECT_TRUE(MessageDifferencer::Equals(merged, whole));

  // An operation carries the whole result under the inline limit, its summary above it.
  bool summary_only = true;
  StatusOr<std::string> inline_bytes = ResultForOperation(*store_, job.id, 1 << 20, &summary_only);
  ASSERT_TRUE(inline_bytes.ok());
  EXPECT_FALSE(summary_only);
  v1::SimulateResult from_operation;
  ASSERT_TRUE(from_operation.ParseFromString(*inline_bytes));
  EXPECT_TRUE(MessageDifferencer::Equals(from_operation, whole));
  StatusOr<std::string> summary_bytes = ResultForOperation(*store_, job.id, 100, &summary_only);
  ASSERT_TRUE(summary_bytes.ok());
  EXPECT_TRUE(summary_only);
  v1::SimulateResult summary;
  ASSERT_TRUE(summary.ParseFromString(*summary_bytes));
  EXPECT_EQ(summary.poincare_size() + summary.events_size(), 0);
  EXPECT_EQ(summary.status(), "COMPLETED");
}

// A simulation produces its samples and events interleaved; pages hold each field's items
// together, fields in their order (all samples, then all events), as a client prints them.
TEST_F(StoredResultsTest, InterleavedItemsArePagedFieldByField) {
  const JobRecord job = Running("simulate");
  const jobs::JobKindSpec& simulate = *jobs::FindKind(v1::SIMULATE);
  ResultWriter writer(store_.get(), job, simulate, 0, /*chunk_bytes=*/64);
  v1::SimulateResult whole;
  for (int period = 0; period < 40; ++period) {
    for (int e = 0; e < 3; ++e) {
      v1::SimulateResult event;
      event.add_events()->set_period(period);
      event.mutable_events(0)->set_s(e);
      ASSERT_TRUE(writer.Append(event, 1).ok());
      *whole.add_events() = event.events(0);
    }
    v1::SimulateResult sample;
    sample.add_poincare()->set_period(period);
    ASSERT_TRUE(writer.Append(sample, 1).ok());
    *whole.add_poincare() = sample.poincare(0);
  }
  ASSERT_TRUE(writer.Flush().ok());
  ASSERT_TRUE(store_->Complete(job.id, job.run, "", writer.items()).ok());
  std::vector<int> fields_per_page;
  v1::SimulateResult merged;
  std::string token;
  bool events_started = false;
  do {
    v1::GetResultResponse page;
    ASSERT_TRUE(ReadResultPage(*store_, simulate, job.id, 7, token, PageOptions(), &page).ok());
    // Once events appear, no sample comes any more.
    if (events_started) {
      EXPECT_EQ(page.simulate().poincare_size(), 0);
    }
    events_started = events_started || page.simulate().events_size() > 0;
    for (const auto& p : page.simulate().poincare()) *merged.add_poincare() = p;
    for (const auto& e : page.simulate().events()) *merged.add_events() = e;
    EXPECT_EQ(page.simulate().poincare_size() + page.simulate().events_size(),
              page.next_page_token().empty() ? 160 % 7 : 7);
    token = page.next_page_token();
  } while (!token.empty());
  EXPECT_TRUE(MessageDifferencer::Equals(merged, whole));
  // And whole: the summary and every chunk.
  const StatusOr<std::string> bytes = store_->GetResult(job.id);
  ASSERT_TRUE(bytes.ok());
  v1::SimulateResult parsed;
  ASSERT_TRUE(parsed.ParseFromString(*bytes));
  EXPECT_TRUE(MessageDifferencer::Equals(parsed, whole));
}

TEST_F(StoredResultsTest, TheFirstPageOnlyCarriesTheNestedPeriodDoubledBranch) {
  const JobRecord job = Running("continue");
  const jobs::JobKindSpec& kind = *jobs::FindKind(v1::CONTINUE);
  v1::ContinueResult result;
  result.set_status("COMPLETED");
  for (int i = 0; i < 10; ++i) result.add_points()->set_value(i);
  result.mutable_period_doubled_branch()->add_points()->set_value(42);
  ResultWriter writer(store_.get(), job, kind, 0, 1024);
  ASSERT_TRUE(writer.MoveItemsOf(&result).ok());
  ASSERT_TRUE(writer.Flush().ok());
  ASSERT_TRUE(store_->Complete(job.id, job.run, result.SerializeAsString(), writer.items()).ok());
  v1::GetResultResponse first, second;
  ASSERT_TRUE(ReadResultPage(*store_, kind, job.id, 4, "", PageOptions(), &first).ok());
  ASSERT_TRUE(
      ReadResultPage(*store_, kind, job.id, 4, first.next_page_token(), PageOptions(), &second)
          .ok());
  EXPECT_TRUE(first.continue_().has_period_doubled_branch());
  EXPECT_FALSE(second.continue_().has_period_doubled_branch());
  EXPECT_EQ(second.continue_().points(0).value(), 4);
  EXPECT_EQ(second.continue_().status(), "COMPLETED");  // the summary is in every page
}

}  // namespace
}  // namespace drillbif::server
