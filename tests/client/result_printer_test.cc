// ResultPrinter (client/output.h) prints a result that arrives in pages byte for byte as the whole
// result message prints: ToJson (protobuf's own printer, pretty and compact) and each kind's
// *ResultToCsv. Results come from small real runs of the job runners (a simulation with every
// output, a sweep both ways, a continuation with its period-doubled branch, a trace with its
// region, an optimum); the pages are cut here, independently of the server, as GetResult serves
// them: the summary in every page (the first-page-only fields in the first page only) and the
// next run of the paged fields' items, fields in order.
#include <gmock/gmock.h>
#include <google/protobuf/reflection.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <memory>
#include <string>
#include <vector>

#include "client/output.h"
#include "jobs/continue_job.h"
#include "jobs/optimum_job.h"
#include "jobs/registry.h"
#include "jobs/simulate_job.h"
#include "jobs/sweep_job.h"
#include "jobs/trace_job.h"
#include "support/small_requests.h"

namespace drillbif::client {
namespace {

using google::protobuf::FieldDescriptor;
using google::protobuf::Message;
using ::testing::HasSubstr;
using Pages = std::vector<std::unique_ptr<Message>>;

// The pages of `result` with `page_size` items each (0: the result itself as the one page).
Pages Split(const Message& result, int page_size) {
  Pages pages;
  if (page_size == 0) {
    pages.emplace_back(result.New());
    pages.back()->CopyFrom(result);
    return pages;
  }
  const jobs::JobKindSpec* kind = jobs::FindKind(result.GetDescriptor());
  const auto* reflection = result.GetReflection();
  std::vector<const FieldDescriptor*> paged;
  for (const std::string& name : kind->paged_fields) {
    paged.push_back(result.GetDescriptor()->FindFieldByName(name));
  }
  std::unique_ptr<Message> summary(result.New());
  summary->CopyFrom(result);
  for (const FieldDescriptor* field : paged) reflection->ClearField(summary.get(), field);
  // The items in order: (field, index in it).
  std::vector<std::pair<const FieldDescriptor*, int>> items;
  for (const FieldDescriptor* field : paged) {
    for (int i = 0; i < reflection->FieldSize(result, field); ++i) items.emplace_back(field, i);
  }
  for (size_t begin = 0; begin == 0 || begin < items.size(); begin += page_size) {
    std::unique_ptr<Message> page(result.New());
    page->CopyFrom(*summary);
    if (begin > 0) {
      for (const std::string& name : kind->first_page_fields) {
        reflection->ClearField(page.get(), result.GetDescriptor()->FindFieldByName(name));
      }
    }
    const size_t end = std::min(items.size(), begin + page_size);
    for (size_t k = begin; k < end; ++k) {
      const auto [field, i] = items[k];
      reflection->AddMessage(page.get(), field)
          ->CopyFrom(reflection->GetRepeatedMessage(result, field, i));
    }
    pages.push_back(std::move(page));
  }
  return pages;
}

// What a ResultPrinter prints of `pages`, or its error.
StatusOr<std::string> Print(Pages pages, const PrintOptions& options) {
  std::string text;
  StatusOr<std::unique_ptr<ResultPrinter>> printer =
      ResultPrinter::Create(pages.front()->GetDescriptor(), options, [&text](std::string_view s) {
        text.append(s);
        return Status::Ok();
      });
  if (!printer.ok()) return printer.status();
  for (const auto& page : pages) {
    if (Status s = (*printer)->AddPage(*page); !s.ok()) return s;
  }
  if (Status s = (*printer)->Finish(); !s.ok()) return s;
  return text;
}

// Where two texts first differ, with some context (gtest's diff of megabyte strings is slow).
std::string FirstDifference(const std::string& got, const std::string& want) {
  const size_t at =
      std::mismatch(got.begin(), got.begin() + std::min(got.size(), want.size()), want.begin())
          .first -
      got.begin();
  const size_t from = at < 80 ? 0 : at - 80;
  return "sizes " + std::to_string(got.size()) + " and " + std::to_string(want.size()) +
         ", first difference at " + std::to_string(at) + ":\n got: ..." + got.substr(from, 160) +
         "\nwant: ..." + want.substr(from, 160);
}

int64_t Items(const Message& result) {
  return jobs::FindKind(result.GetDescriptor())->ItemsOf(result);
}

// Page sizes: 1, 2, 7, all the items in one page, and the whole message as the page.
std::vector<int> PageSizes(const Message& result) {
  return {1, 2, 7, static_cast<int>(std::max<int64_t>(1, Items(result))), 0};
}

// Pages of every size print as ToJson prints the whole result, pretty and compact.
void ExpectJsonOfPagesIsWholeJson(const Message& result) {
  for (bool pretty : {true, false}) {
    const StatusOr<std::string> whole = ToJson(result, pretty);
    ASSERT_TRUE(whole.ok()) << whole.status().ToString();
    for (int page_size : PageSizes(result)) {
      PrintOptions options;
      options.pretty = pretty;
      const StatusOr<std::string> paged = Print(Split(result, page_size), options);
      ASSERT_TRUE(paged.ok()) << paged.status().ToString();
      EXPECT_TRUE(*paged == *whole) << "pretty " << pretty << ", pages of " << page_size << ": "
                                    << FirstDifference(*paged, *whole);
    }
  }
}

// Pages of every size print as `whole` (the kind's *ResultToCsv of the whole result).
void ExpectCsvOfPagesIs(const Message& result, const std::string& whole,
                        std::optional<SimulateTable> table = std::nullopt) {
  for (int page_size : PageSizes(result)) {
    PrintOptions options;
    options.csv = true;
    options.simulate_table = table;
    const StatusOr<std::string> paged = Print(Split(result, page_size), options);
    ASSERT_TRUE(paged.ok()) << paged.status().ToString();
    EXPECT_TRUE(*paged == whole) << "pages of " << page_size << ": "
                                 << FirstDifference(*paged, whole);
  }
}

v1::SimulateRequest SimulateEverything() {
  v1::SimulateRequest request;
  request.set_transient_periods(20);
  request.set_sample_periods(3);
  v1::SimulateRequest::Outputs* outputs = request.mutable_outputs();
  outputs->set_measures(true);
  outputs->set_poincare(true);
  outputs->set_events(true);
  outputs->set_modes(true);
  outputs->set_trajectory_dt(5.0);  // ~38 points over 3 forcing periods of 2 pi / 0.1
  return request;
}

TEST(ResultPrinter, SimulatePagesPrintAsTheWholeResult) {
  const StatusOr<v1::SimulateResult> result = jobs::RunSimulate(SimulateEverything());
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  // Every paged field holds items, so pages cross from one field to the next.
  ASSERT_GT(result->poincare_size(), 0);
  ASSERT_GT(result->events_size(), 0);
  ASSERT_GT(result->period_modes_size(), 0);
  ASSERT_GT(result->trajectory_size(), 10);
  ExpectJsonOfPagesIsWholeJson(*result);
  for (SimulateTable table :
       {SimulateTable::kNone, SimulateTable::kPoincare, SimulateTable::kEvents,
        SimulateTable::kModes, SimulateTable::kTrajectory}) {
    ExpectCsvOfPagesIs(*result, SimulateResultToCsv(*result, table), table);
  }
}

// `jobs result` does not know the request: the table is the one output the result holds.
TEST(ResultPrinter, SimulateCsvTableFromTheItemsThatCome) {
  v1::SimulateRequest request = SimulateEverything();
  request.mutable_outputs()->set_poincare(false);
  request.mutable_outputs()->set_modes(false);
  request.mutable_outputs()->set_trajectory_dt(0.0);
  const StatusOr<v1::SimulateResult> events = jobs::RunSimulate(request);
  ASSERT_TRUE(events.ok()) << events.status().ToString();
  ASSERT_GT(events->events_size(), 7);
  ExpectCsvOfPagesIs(*events, SimulateResultToCsv(*events, SimulateTable::kEvents));

  request.mutable_outputs()->set_events(false);
  const StatusOr<v1::SimulateResult> measures = jobs::RunSimulate(request);
  ASSERT_TRUE(measures.ok()) << measures.status().ToString();
  ExpectCsvOfPagesIs(*measures, SimulateResultToCsv(*measures, SimulateTable::kNone));

  // Two tables: refused, before anything is printed when they meet in the first page.
  const StatusOr<v1::SimulateResult> both = jobs::RunSimulate(SimulateEverything());
  ASSERT_TRUE(both.ok());
  PrintOptions options;
  options.csv = true;
  std::string text;
  StatusOr<std::unique_ptr<ResultPrinter>> printer =
      ResultPrinter::Create(v1::SimulateResult::descriptor(), options, [&](std::string_view s) {
        text.append(s);
        return Status::Ok();
      });
  ASSERT_TRUE(printer.ok());
  v1::SimulateResult page = *both;
  const Status refused = (*printer)->AddPage(page);
  EXPECT_EQ(refused.code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(refused.message(), HasSubstr("CSV holds one table"));
  EXPECT_EQ(text, "");
  // In pages of one item, at the first page of the second table.
  EXPECT_EQ(Print(Split(*both, 1), options).status().code(), StatusCode::kInvalidArgument);
}

// A sweep both ways with a value of each direction marked as failed: their comment lines come
// before the table, so they must gather from every page.
TEST(ResultPrinter, SweepPagesPrintAsTheWholeResult) {
  v1::SweepRequest request = testing::SmallSweep(0.12, 6);
  request.set_direction(v1::SweepRequest::BOTH);
  request.set_transient_periods(20);
  request.set_sample_periods(3);
  StatusOr<v1::SweepResult> result = jobs::RunSweep(request);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  ASSERT_EQ(result->up_size(), 6);
  ASSERT_EQ(result->down_size(), 6);
  for (v1::SweepPoint* pt : {result->mutable_up(4), result->mutable_down(1)}) {
    pt->set_status("FAILED");
    pt->set_message("no convergence, \"quoted\" <text>");
  }
  const std::string csv = SweepResultToCsv(*result);
  ASSERT_THAT(csv, HasSubstr("# up value="));
  ASSERT_THAT(csv, HasSubstr("# down value="));
  ExpectJsonOfPagesIsWholeJson(*result);
  ExpectCsvOfPagesIs(*result, csv);
}

// More than the 1 MiB that a sweep's CSV rows, and its failures of one direction, keep in
// memory (the rest waits in a temporary file), and more than one JSON chunk (1 MiB of items) in
// the whole-result page: 1000 values of 20 samples each (~1.4 MB of rows), every 5th failed
// with a 12 kB message (~1.2 MB of failure lines each way), built from a real value.
TEST(ResultPrinter, LargeSweepPagesPrintAsTheWholeResult) {
  v1::SweepRequest request = testing::SmallSweep(0.15, 2);
  request.set_transient_periods(20);
  request.set_sample_periods(20);
  const StatusOr<v1::SweepResult> run = jobs::RunSweep(request);
  ASSERT_TRUE(run.ok()) << run.status().ToString();
  ASSERT_EQ(run->up_size(), 2);
  v1::SweepResult result = *run;
  result.clear_up();
  result.clear_down();
  for (int i = 0; i < 1000; ++i) {
    v1::SweepPoint* pt = i % 2 == 0 ? result.add_up() : result.add_down();
    *pt = run->up(i % 2);
    pt->set_value(0.15 + 1e-5 * i);
    if (i % 5 < 2) {
      pt->set_status("FAILED");
      pt->set_message("value " + std::to_string(i) + " " + std::string(12000, 'x'));
    }
  }
  const std::string csv = SweepResultToCsv(result);
  ASSERT_GT(csv.size(), 3u << 20);
  const StatusOr<std::string> json = ToJson(result, /*pretty=*/true);
  ASSERT_TRUE(json.ok());
  for (int page_size : {7, 0}) {
    PrintOptions options;
    options.csv = true;
    const StatusOr<std::string> paged_csv = Print(Split(result, page_size), options);
    ASSERT_TRUE(paged_csv.ok()) << paged_csv.status().ToString();
    EXPECT_TRUE(*paged_csv == csv)
        << "pages of " << page_size << ": " << FirstDifference(*paged_csv, csv);
    options.csv = false;
    const StatusOr<std::string> paged_json = Print(Split(result, page_size), options);
    ASSERT_TRUE(paged_json.ok()) << paged_json.status().ToString();
    EXPECT_TRUE(*paged_json == *json)
        << "pages of " << page_size << ": " << FirstDifference(*paged_json, *json);
  }
}

// The period-doubled branch (a whole ContinueResult, in the first page only) prints inside the
// summary, after the top-level points it shares a field name with.
TEST(ResultPrinter, ContinuePagesWithAPeriodDoubledBranchPrintAsTheWholeResult) {
  v1::ContinueRequest request;
  request.set_param("b");
  request.set_min(0.09);
  request.set_max(0.12);
  request.set_max_steps(200);
  request.mutable_params()->set_b(0.115);
  request.set_follow_period_doubling(true);
  const StatusOr<v1::ContinueResult> result = jobs::RunContinue(request);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  ASSERT_GT(result->points_size(), 10);
  ASSERT_GT(result->period_doubled_branch().points_size(), 10);
  ASSERT_GT(result->special_points_size(), 0);
  ExpectJsonOfPagesIsWholeJson(*result);
  ExpectCsvOfPagesIs(*result, ContinueResultToCsv(*result));
}

TEST(ResultPrinter, TracePagesPrintAsTheWholeResult) {
  v1::TraceRequest request = testing::SmallBoxTrace();
  request.mutable_region()->add_grid(21);
  request.mutable_region()->add_grid(21);
  const StatusOr<v1::TraceResult> result = jobs::RunTrace(request);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  ASSERT_GT(result->curves_size(), 2);
  ASSERT_TRUE(result->has_region());
  ExpectJsonOfPagesIsWholeJson(*result);
  // Curve indices count on across pages; unverified ends gather from every page.
  v1::TraceResult with_ends = *result;
  with_ends.mutable_curves(1)->add_unverified_ends()->mutable_params()->set_a(0.5);
  with_ends.mutable_curves(2)->add_unverified_ends()->mutable_params()->set_omega(0.125);
  const std::string csv = TraceResultToCsv(with_ends);
  ASSERT_THAT(csv, HasSubstr("# UNVERIFIED_END curve=2 "));
  ExpectCsvOfPagesIs(with_ends, csv);
}

TEST(ResultPrinter, OptimumPrintsAsTheWholeResult) {
  v1::OptimumRequest request;
  *request.mutable_trace() = testing::SmallBoxTrace();
  request.add_margin(0.01);
  request.add_margin(0.02);
  request.add_grid(21);
  request.add_grid(21);
  const StatusOr<v1::OptimumResult> result = jobs::RunOptimum(request);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  ASSERT_TRUE(result->has_params());
  ExpectJsonOfPagesIsWholeJson(*result);
  ExpectCsvOfPagesIs(*result, OptimumResultToCsv(*result));
}

v1::SweepResult TwoWaySweep() {
  v1::SweepResult result;
  result.set_status("COMPLETED");
  for (int i = 0; i < 3; ++i) {
    result.add_up()->set_value(i);
    result.add_down()->set_value(-i);
  }
  return result;
}

TEST(ResultPrinter, RefusesPagesThatDoNotFitTogether) {
  // Items of `up` after items of `down`.
  Pages pages = Split(TwoWaySweep(), 4);  // up 0-2, down 0 | down 1-2
  ASSERT_EQ(pages.size(), 2u);
  static_cast<v1::SweepResult&>(*pages[1]).add_up()->set_value(7);
  const Status order = Print(std::move(pages), PrintOptions()).status();
  EXPECT_EQ(order.code(), StatusCode::kInternal);
  EXPECT_THAT(order.message(), HasSubstr("holds items of up after items of down"));
  // Another summary on the second page.
  pages = Split(TwoWaySweep(), 4);
  static_cast<v1::SweepResult&>(*pages[1]).set_periods_total(5);
  const Status summary = Print(std::move(pages), PrintOptions()).status();
  EXPECT_EQ(summary.code(), StatusCode::kInternal);
  EXPECT_THAT(summary.message(), HasSubstr("another summary"));
  // A page of another kind.
  pages = Split(TwoWaySweep(), 0);
  pages.push_back(std::make_unique<v1::ContinueResult>());
  EXPECT_EQ(Print(std::move(pages), PrintOptions()).status().code(), StatusCode::kInternal);
}

TEST(ResultPrinter, ReportsTheStatusAndStopsAtTheSinksError) {
  int writes = 0;
  StatusOr<std::unique_ptr<ResultPrinter>> printer =
      ResultPrinter::Create(v1::SweepResult::descriptor(), PrintOptions(), [&](std::string_view) {
        ++writes;
        return Internal("disk full");
      });
  ASSERT_TRUE(printer.ok());
  v1::SweepResult page = TwoWaySweep();
  page.set_message("all done");
  const Status s = (*printer)->AddPage(page);
  EXPECT_EQ(s.message(), "disk full");
  EXPECT_EQ(writes, 1);
  EXPECT_EQ((*printer)->status(), "COMPLETED");
  EXPECT_EQ((*printer)->message(), "all done");
  EXPECT_FALSE(
      ResultPrinter::Create(v1::SweepRequest::descriptor(), PrintOptions(), [](std::string_view) {
        return Status::Ok();
      }).ok());
  StatusOr<std::unique_ptr<ResultPrinter>> unused = ResultPrinter::Create(
      v1::SweepResult::descriptor(), PrintOptions(), [](std::string_view) { return Status::Ok(); });
  ASSERT_TRUE(unused.ok());
  EXPECT_EQ((*unused)->Finish().code(), StatusCode::kInternal);  // no page
}

}  // namespace
}  // namespace drillbif::client
