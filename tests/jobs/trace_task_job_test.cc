// The trace job with its tasks as child jobs, without a store: a runner that encodes every task as
// a child job's request (jobs/trace_task_codec.h), runs it through the registry's child kind as a
// worker does and decodes its result gives the result of the trace on its own threads; a batch's
// results are its tasks' own, in order; the child kind's checks name the field; a stopped batch is
// CANCELLED without results.
#include "jobs/trace_task_job.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <map>
#include <string>
#include <vector>

#include "drillbif/continuation/trace_tasks.h"
#include "drillbif/orbit/signature.h"
#include "jobs/job_common.h"
#include "jobs/registry.h"
#include "jobs/request_bytes.h"
#include "jobs/trace_job.h"
#include "jobs/trace_task_codec.h"
#include "support/same_result.h"
#include "support/small_requests.h"

namespace drillbif::jobs {
namespace {

using ::testing::HasSubstr;

// Runs each task as a child job's bytes, when it is taken.
class ChildJobRunner : public TraceTaskRunner {
 public:
  explicit ChildJobRunner(std::string parent_request) : parent_(std::move(parent_request)) {}
  size_t window() const override { return 3; }
  StatusOr<int64_t> Submit(const TraceTask& task) override {
    requests_.emplace(next_, EncodeTraceTaskBatch(parent_, {&task}));
    return next_++;
  }
  bool Ready(int64_t) override { return false; }
  StatusOr<TraceTaskResult> Take(int64_t ticket, const std::function<bool()>&) override {
    const std::string request = requests_.at(ticket);
    requests_.erase(ticket);
    const JobKindSpec* kind = FindChildKind(kTraceTaskKind);
    StatusOr<JobOutput> out = RunJob(*kind, request, {});
    if (!out.ok()) return out.status();
    EXPECT_EQ(out->status, "COMPLETED");
    ++ran_;
    StatusOr<std::vector<TraceTaskResult>> results =
        DecodeTraceTaskBatchResponse(DeterministicBytes(*out->result));
    if (!results.ok()) return results.status();
    EXPECT_EQ(results->size(), 1u);
    return std::move(results->front());
  }
  void Drop(int64_t ticket) override { requests_.erase(ticket); }
  int ran() const { return ran_; }

 private:
  std::string parent_;
  std::map<int64_t, std::string> requests_;
  int64_t next_ = 0;
  int ran_ = 0;
};

TEST(TraceTaskJob, TraceWithChildJobsEqualsTheTraceOnItsThreads) {
  v1::TraceRequest request = testing::SmallBoxTrace();
  StatusOr<v1::TraceResult> local = RunTrace(request);
  ASSERT_TRUE(local.ok()) << local.status().ToString();
  ChildJobRunner runner(DeterministicBytes(request));
  StatusOr<v1::TraceResult> fanned = RunTrace(request, {.trace_tasks = &runner});
  ASSERT_TRUE(fanned.ok()) << fanned.status().ToString();
  EXPECT_EQ(fanned->status(), "COMPLETED");
  EXPECT_GT(runner.ran(), 0);
  testing::ExpectSameResult(*fanned, *local);
}

TEST(TraceTaskJob, ClientsCannotSubmitTheChildKind) {
  EXPECT_EQ(FindKind(kTraceTaskKind), nullptr);
  for (const JobKindSpec* k : AllKinds()) EXPECT_NE(k->name, kTraceTaskKind);
  ASSERT_NE(FindChildKind(kTraceTaskKind), nullptr);
  EXPECT_EQ(FindChildKind("trace"), nullptr);
}

// A child request whose task is taken from a real located point, damaged one way at a time.
class TraceTaskChecks : public ::testing::Test {
 protected:
  void SetUp() override {
    v1::TraceRequest request = testing::SmallBoxTrace();
    parent_ = DeterministicBytes(request);
    ChildCapture capture;
    StatusOr<v1::TraceResult> r = RunTrace(request, {.trace_tasks = &capture});
    ASSERT_EQ(capture.tasks.size(), 2u);
    task_.task = capture.tasks[0];
    second_ = capture.tasks[1];
  }
  StatusOr<JobOutput> Run(const std::string& parent, const std::vector<const TraceTask*>& tasks,
                          const RunContext& context = {}) {
    return RunJob(*FindChildKind(kTraceTaskKind), EncodeTraceTaskBatch(parent, tasks), context);
  }
  StatusOr<JobOutput> Run(const std::string& parent, const TraceTask& task,
                          const RunContext& context = {}) {
    return Run(parent, std::vector<const TraceTask*>{&task}, context);
  }
  // Keeps the first two tasks the trace submits and fails the trace when it takes one.
  struct ChildCapture : TraceTaskRunner {
    size_t window() const override { return 2; }
    StatusOr<int64_t> Submit(const TraceTask& task) override {
      tasks.push_back(task);
      return static_cast<int64_t>(tasks.size());
    }
    bool Ready(int64_t) override { return false; }
    StatusOr<TraceTaskResult> Take(int64_t, const std::function<bool()>&) override {
      return Status(StatusCode::kUnavailable, "captured");
    }
    void Drop(int64_t) override {}
    std::vector<TraceTask> tasks;
  };
  // The results of a child job's run, decoded.
  static std::vector<TraceTaskResult> Results(const StatusOr<JobOutput>& out) {
    EXPECT_TRUE(out.ok()) << out.status().ToString();
    if (!out.ok()) return {};
    EXPECT_EQ(out->status, "COMPLETED");
    StatusOr<std::vector<TraceTaskResult>> results =
        DecodeTraceTaskBatchResponse(DeterministicBytes(*out->result));
    EXPECT_TRUE(results.ok()) << results.status().ToString();
    return results.ok() ? *results : std::vector<TraceTaskResult>{};
  }
  std::string parent_;
  DecodedTraceTask task_;
  TraceTask second_;
};

TEST_F(TraceTaskChecks, TheFirstTaskIsACurveThatRuns) {
  ASSERT_TRUE(std::holds_alternative<CurveTask>(task_.task));
  const std::vector<TraceTaskResult> results = Results(Run(parent_, task_.task));
  ASSERT_EQ(results.size(), 1u);
  EXPECT_FALSE(std::get<CurveResult>(results[0]).points.empty());
}

// A batch runs its tasks in order: its results are, byte for byte, those of each task run alone.
TEST_F(TraceTaskChecks, ABatchGivesEachTasksOwnResultInOrder) {
  const std::vector<TraceTaskResult> batch = Results(Run(parent_, {&second_, &task_.task}));
  const std::vector<TraceTaskResult> first = Results(Run(parent_, task_.task));
  const std::vector<TraceTaskResult> second = Results(Run(parent_, second_));
  ASSERT_EQ(batch.size(), 2u);
  ASSERT_EQ(first.size(), 1u);
  ASSERT_EQ(second.size(), 1u);
  EXPECT_NE(EncodeTraceTaskResult(first[0]), EncodeTraceTaskResult(second[0]));
  EXPECT_EQ(EncodeTraceTaskResult(batch[0]), EncodeTraceTaskResult(second[0]));
  EXPECT_EQ(EncodeTraceTaskResult(batch[1]), EncodeTraceTaskResult(first[0]));
}

TEST_F(TraceTaskChecks, BatchesOfNoTaskOrTooManyOrABadOneAreRefusedNamingTheTask) {
  StatusOr<JobOutput> none = Run(parent_, std::vector<const TraceTask*>{});
  EXPECT_EQ(none.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(none.status().message(), HasSubstr("TraceTaskBatch.tasks: 0 tasks"));
  const std::vector<const TraceTask*> many(kMaxTraceTaskBatch + 1, &task_.task);
  StatusOr<JobOutput> too_many = Run(parent_, many);
  EXPECT_EQ(too_many.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(too_many.status().message(), HasSubstr("65 tasks, not 1 .. 64"));
  CurveTask mode = std::get<CurveTask>(task_.task);
  mode.start.point.orbit.signature.segments[0].mode = 99;
  const TraceTask bad = mode;
  StatusOr<JobOutput> second_bad = Run(parent_, {&task_.task, &bad});
  EXPECT_EQ(second_bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(second_bad.status().message(), HasSubstr("tasks[1].curve.start.point.orbit"));
}

TEST_F(TraceTaskChecks, BadChildRequestsNameTheField) {
  StatusOr<JobOutput> garbage = RunJob(*FindChildKind(kTraceTaskKind), "\xff\xff", {});
  EXPECT_EQ(garbage.status().code(), StatusCode::kInvalidArgument);
  v1::TraceRequest bad_box = testing::SmallBoxTrace();
  bad_box.set_max(1, 0.0);
  StatusOr<JobOutput> box = Run(DeterministicBytes(bad_box), task_.task);
  EXPECT_EQ(box.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(box.status().message(), HasSubstr("trace_request: "));
  CurveTask mode = std::get<CurveTask>(task_.task);
  mode.start.point.orbit.signature.segments[0].mode = 99;
  StatusOr<JobOutput> bad_mode = Run(parent_, mode);
  EXPECT_EQ(bad_mode.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(bad_mode.status().message(), HasSubstr("curve.start.point.orbit.signature"));
  CurveTask starts = std::get<CurveTask>(task_.task);
  starts.start.point.orbit.starts.pop_back();
  StatusOr<JobOutput> few = Run(parent_, starts);
  EXPECT_EQ(few.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(few.status().message(), HasSubstr("curve.start.point.orbit: "));
  CurveTask params = std::get<CurveTask>(task_.task);
  params.start.point.orbit.params[0] = -1.0;
  StatusOr<JobOutput> bad_params = Run(parent_, params);
  EXPECT_EQ(bad_params.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(bad_params.status().message(), HasSubstr("curve.start.point.orbit.params"));
}

// The forms the trace passes between its steps are not all orbits a client may ask for: a
// candidate whose tangent end is followed by a segment of another mode (as the switching at
// grazings makes them) passes the child's checks, which refuse only indices the model does not
// have.
TEST_F(TraceTaskChecks, ACandidatesTangentEndBeforeAnotherModeIsAccepted) {
  const CurveTask& curve = std::get<CurveTask>(task_.task);
  PeriodicOrbit orbit = curve.start.point.orbit;
  ASSERT_GE(orbit.signature.segments.size(), 2u);
  ASSERT_NE(orbit.signature.segments[0].mode, orbit.signature.segments[1].mode);
  orbit.signature.segments[0].tangent = true;
  ASSERT_FALSE(ValidateSignature(internal::Model(), orbit.signature).ok());
  CandidateTask run;
  run.point.point.orbit = curve.start.point.orbit;
  run.candidate.orbit = orbit;
  const TraceTask task = run;
  v1::TraceTaskBatch request;
  ASSERT_TRUE(request.ParseFromString(EncodeTraceTaskBatch(parent_, {&task})));
  EXPECT_TRUE(PlanTraceTask(request).ok()) << PlanTraceTask(request).status().ToString();
  run.candidate.orbit->signature.segments[0].guard = 99;
  const TraceTask bad_guard = run;
  ASSERT_TRUE(request.ParseFromString(EncodeTraceTaskBatch(parent_, {&bad_guard})));
  const StatusOr<TraceTaskPlan> bad = PlanTraceTask(request);
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(bad.status().message(), HasSubstr("candidate_run.candidate.orbit.signature"));
}

TEST_F(TraceTaskChecks, AStoppedBatchIsCancelledWithoutResults) {
  // Stopped at the second task's first look: the first task's result is not handed out either.
  int looks = 0;
  bool second_started = false;
  StatusOr<JobOutput> out = Run(parent_, {&task_.task, &second_}, {.progress = [&](double f) {
                                  if (f >= 0.5) second_started = true;
                                  return ++looks < 2 || !second_started;
                                }});
  ASSERT_TRUE(out.ok()) << out.status().ToString();
  EXPECT_TRUE(second_started);
  EXPECT_EQ(out->status, "CANCELLED");
  const auto& response = static_cast<const v1::TraceTaskBatchResponse&>(*out->result);
  EXPECT_EQ(response.results_size(), 0);
}

}  // namespace
}  // namespace drillbif::jobs
