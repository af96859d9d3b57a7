// Streamed runs (RunContext::sink): every kind that has paged items hands them to the sink as the
// engine produces them, each call holding items of one paged field; the summary the run returns
// plus the streamed items, merged, equal the result of the same run without a sink (the engine is
// deterministic: bit for bit, wall times aside). A sink that refuses stops the run with its error.
#include <gmock/gmock.h>
#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include <memory>
#include <string>

#include "jobs/continue_job.h"
#include "jobs/registry.h"
#include "jobs/simulate_job.h"
#include "jobs/sweep_job.h"
#include "jobs/trace_job.h"
#include "support/small_requests.h"

namespace drillbif::jobs {
namespace {

using google::protobuf::Message;
using google::protobuf::util::MessageDifferencer;

// Merges what it receives; checks each call holds items of one paged field only.
class CollectingSink final : public ResultSink {
 public:
  explicit CollectingSink(const JobKindSpec& kind) : kind_(kind), items_(kind.NewResult()) {}

  Status Append(const Message& items, int64_t count) override {
    EXPECT_EQ(kind_.ItemsOf(items), count);
    std::vector<const google::protobuf::FieldDescriptor*> set;
    items.GetReflection()->ListFields(items, &set);
    EXPECT_EQ(set.size(), 1u) << items.ShortDebugString().substr(0, 200);
    ++calls_;
    if (refuse_after_ >= 0 && calls_ > refuse_after_) return ResourceExhausted("sink full");
    items_->MergeFrom(items);
    return Status::Ok();
  }

  // The streamed items merged into the summary a run returned.
  std::unique_ptr<Message> Merge(const Message& summary) const {
    std::unique_ptr<Message> whole(summary.New());
    whole->CopyFrom(summary);
    EXPECT_EQ(kind_.ItemsOf(summary), 0) << "items left in the summary of a streamed run";
    whole->MergeFrom(*items_);
    return whole;
  }

  int calls() const { return calls_; }
  void RefuseAfter(int calls) { refuse_after_ = calls; }

 private:
  const JobKindSpec& kind_;
  std::unique_ptr<Message> items_;
  int calls_ = 0;
  int refuse_after_ = -1;
};

// Runs `request` of `kind` with and without a sink and compares, ignoring wall_seconds.
void ExpectStreamedEqualsWhole(v1::JobKind kind_id, const Message& request, int min_calls) {
  const JobKindSpec& kind = *FindKind(kind_id);
  StatusOr<std::unique_ptr<Message>> whole = kind.run(request, {});
  ASSERT_TRUE(whole.ok()) << whole.status().ToString();
  CollectingSink sink(kind);
  StatusOr<std::unique_ptr<Message>> summary = kind.run(request, {.sink = &sink});
  ASSERT_TRUE(summary.ok()) << summary.status().ToString();
  std::unique_ptr<Message> merged = sink.Merge(**summary);
  MessageDifferencer differ;
  differ.IgnoreField(kind.result_type->FindFieldByName("wall_seconds"));
  std::string diff;
  differ.ReportDifferencesToString(&diff);
  EXPECT_TRUE(differ.Compare(*merged, **whole)) << diff.substr(0, 2000);
  EXPECT_GE(sink.calls(), min_calls);
  EXPECT_GT(kind.ItemsOf(**whole), 0);
}

TEST(Streaming, ASimulationStreamsEveryOutput) {
  v1::SimulateRequest request;
  request.set_transient_periods(50);
  request.set_sample_periods(300);
  v1::SimulateRequest::Outputs* outputs = request.mutable_outputs();
  outputs->set_measures(true);
  outputs->set_poincare(true);
  outputs->set_events(true);
  outputs->set_modes(true);
  outputs->set_trajectory_dt(2.0);
  // 300 samples, ~1200 events, 300 mode records: in batches of 64, one field each.
  ExpectStreamedEqualsWhole(v1::SIMULATE, request, 4 * 300 / 64);
}

TEST(Streaming, ASweepStreamsItsValuesInGridOrderInBothDirections) {
  v1::SweepRequest request = testing::SmallSweep(0.12, 130);
  request.set_direction(v1::SweepRequest::BOTH);
  request.set_transient_periods(100);
  request.set_sample_periods(3);
  request.set_threads(3);
  ExpectStreamedEqualsWhole(v1::SWEEP, request, 2 * 130 / 64);
  // Chunked: values of later chunks finish ahead and wait for their turn.
  request.set_chunks(3);
  ExpectStreamedEqualsWhole(v1::SWEEP, request, 2 * 130 / 64);
}

TEST(Streaming, AContinuationStreamsItsBranchPoints) {
  v1::ContinueRequest request;
  request.set_param("b");
  request.set_min(0.09);
  request.set_max(0.12);
  request.set_max_steps(200);
  request.mutable_params()->set_b(0.115);
  request.set_follow_period_doubling(true);  // the nested branch stays in the summary
  ExpectStreamedEqualsWhole(v1::CONTINUE, request, 1);
}

TEST(Streaming, ATraceStreamsItsCurves) {
  v1::TraceRequest request;
  request.add_trace_params(std::string("omega"));
  request.add_trace_params(std::string("a"));
  request.add_min(0.05);
  request.add_min(0.27);
  request.add_max(0.2);
  request.add_max(0.32);
  ExpectStreamedEqualsWhole(v1::TRACE, request, 1);
}

TEST(Streaming, ASinkThatRefusesStopsTheRunWithItsError) {
  const JobKindSpec& simulate = *FindKind(v1::SIMULATE);
  v1::SimulateRequest request;
  request.set_transient_periods(0);
  request.set_sample_periods(100000);
  CollectingSink sink(simulate);
  sink.RefuseAfter(3);
  StatusOr<std::unique_ptr<Message>> r = simulate.run(request, {.sink = &sink});
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kResourceExhausted);
  EXPECT_EQ(r.status().message(), "sink full");
  EXPECT_EQ(sink.calls(), 4);  // the refused call stops the engine at once

  const JobKindSpec& sweep = *FindKind(v1::SWEEP);
  CollectingSink sweep_sink(sweep);
  sweep_sink.RefuseAfter(0);
  v1::SweepRequest many = testing::SmallSweep(0.1, 2000);
  many.set_sample_periods(1);
  StatusOr<std::unique_ptr<Message>> s = sweep.run(many, {.sink = &sweep_sink});
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kResourceExhausted);
}

}  // namespace
}  // namespace drillbif::jobs
