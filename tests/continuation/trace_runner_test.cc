// TraceCurves with its tasks on a TraceTaskRunner (continuation/trace_tasks.h) instead of its
// threads: the same network as one thread, whatever order the runner computes the tasks in and
// whichever are ready when asked; every ticket taken or dropped once; a runner's error ends the
// trace failed with it, a stop while waiting ends it cancelled.
#include <gtest/gtest.h>

#include <map>
#include <set>
#include <string>
#include <vector>

#include "drillbif/continuation/trace.h"
#include "drillbif/continuation/trace_tasks.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_box.h"
#include "problems/reference_orbit.h"
#include "support/same_curves.h"
#include "support/small_trace_box.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

// A runner that computes the tasks on a propagator of its own, out of order: a ticket asked
// whether it is ready is computed then for two tickets in three; a ticket taken first computes
// every task submitted after it, newest first. Counts what the trace did with its tickets.
class ShuffledRunner : public TraceTaskRunner {
 public:
  ShuffledRunner(const TraceOptions& options, size_t window) : options_(options), window_(window) {}

  size_t window() const override { return window_; }
  StatusOr<int64_t> Submit(const TraceTask& task) override {
    if (fail_after_ >= 0 && submitted_ >= fail_after_)
      return Status(StatusCode::kUnavailable, "store gone");
    pending_.emplace(next_, task);
    ++submitted_;
    return next_++;
  }
  bool Ready(int64_t ticket) override {
    ++ready_calls_;
    if (ticket % 3 != 0) Compute(ticket);
    return done_.count(ticket) > 0;
  }
  StatusOr<TraceTaskResult> Take(int64_t ticket, const std::function<bool()>& keep_going) override {
    EXPECT_TRUE(open(ticket)) << ticket;
    closed_.insert(ticket);
    ++taken_;
    std::vector<int64_t> later;
    for (const auto& [t, task] : pending_) {
      if (t > ticket) later.push_back(t);
    }
    for (auto it = later.rbegin(); it != later.rend(); ++it) Compute(*it);
    if (!keep_going() || (cancel_after_ >= 0 && taken_ > cancel_after_)) {
      return Status(StatusCode::kCancelled, "stopped");
    }
    Compute(ticket);
    TraceTaskResult r = std::move(done_.at(ticket));
    done_.erase(ticket);
    return r;
  }
  void Drop(int64_t ticket) override {
    EXPECT_TRUE(open(ticket)) << ticket;
    closed_.insert(ticket);
    ++dropped_;
    pending_.erase(ticket);
    done_.erase(ticket);
  }

  void FailAfter(int64_t submits) { fail_after_ = submits; }
  // Take answers CANCELLED from the given count of takes on, as a runner whose tasks were
  // cancelled with their trace (the trace's own stop not seen yet).
  void CancelAfter(int64_t takes) { cancel_after_ = takes; }
  int64_t submitted() const { return submitted_; }
  int64_t taken() const { return taken_; }
  int64_t dropped() const { return dropped_; }
  int64_t ready_calls() const { return ready_calls_; }
  size_t kinds() const { return kinds_.size(); }

 private:
  bool open(int64_t ticket) const {
    return ticket >= 0 && ticket < next_ && closed_.count(ticket) == 0;
  }
  void Compute(int64_t ticket) {
    const auto it = pending_.find(ticket);
    if (it == pending_.end()) return;
    kinds_.insert(it->second.index());
    done_.emplace(ticket, RunTraceTask(model_, prop_, options_, it->second));
    pending_.erase(it);
  }

  DO model_;
  ExactPropagator prop_{model_};
  TraceOptions options_;
  size_t window_;
  std::map<int64_t, TraceTask> pending_;
  std::map<int64_t, TraceTaskResult> done_;
  std::set<int64_t> closed_;
  std::set<size_t> kinds_;
  int64_t next_ = 0, submitted_ = 0, taken_ = 0, dropped_ = 0, ready_calls_ = 0;
  int64_t fail_after_ = -1;
  int64_t cancel_after_ = -1;
};

class TraceRunner : public testing::SmallTraceBox {};

// Period 1 and period 2 (omega up to 0.45: period-2 curves, their switching and the merge at
// flip-grazings): the runner's network equals one thread's, curve by curve to the bit, with the
// same notes; each of the three task kinds was run; every ticket was taken or dropped once.
TEST_F(TraceRunner, SameNetworkAsOneThread) {
  for (const int max_period : {1, 2}) {
    SCOPED_TRACE("max_period " + std::to_string(max_period));
    TraceOptions o = SmallBox();
    o.max_period = max_period;
    if (max_period == 2) o.max1 = 0.45;
    const TraceResult one = TraceCurves(model_, prop_, start_, o);
    ASSERT_TRUE(one.summary.completed()) << one.summary.message;
    ShuffledRunner runner(o, 4);
    o.task_runner = &runner;
    const TraceResult remote = TraceCurves(model_, prop_, start_, o);
    ASSERT_TRUE(remote.summary.completed()) << remote.summary.message;
    ASSERT_EQ(remote.curves.size(), one.curves.size());
    for (size_t k = 0; k < one.curves.size(); ++k) {
      testing::ExpectSameCurve(remote.curves[k], one.curves[k], static_cast<int>(k));
    }
    EXPECT_EQ(remote.summary.notes, one.summary.notes);
    EXPECT_EQ(remote.summary.branch_points, one.summary.branch_points);
    EXPECT_EQ(runner.kinds(), 3u);
    EXPECT_GT(runner.ready_calls(), 0);
    EXPECT_GT(runner.submitted(), static_cast<int64_t>(one.curves.size()) / 2);
    EXPECT_EQ(runner.taken() + runner.dropped(), runner.submitted());
  }
}

// A runner that cannot take more tasks (its store gone): the trace ends failed with its error,
// keeping the curves applied before; every ticket handed out was taken or dropped.
TEST_F(TraceRunner, RunnerErrorFailsTheTrace) {
  TraceOptions o = SmallBox();
  ShuffledRunner runner(o, 4);
  runner.FailAfter(12);
  o.task_runner = &runner;
  const TraceResult r = TraceCurves(model_, prop_, start_, o);
  EXPECT_TRUE(r.summary.failed());
  EXPECT_EQ(r.summary.status.code(), StatusCode::kUnavailable);
  EXPECT_EQ(r.summary.status.message(), "store gone");
  EXPECT_FALSE(r.curves.empty());
  EXPECT_EQ(runner.submitted(), 12);
  EXPECT_EQ(runner.taken() + runner.dropped(), runner.submitted());
}

// Stopped while the tasks run (at the first report of the switching rounds): the trace ends
// cancelled and drops the tickets it holds.
TEST_F(TraceRunner, StopWhileWaitingCancelsTheTrace) {
  TraceOptions o = SmallBox();
  ShuffledRunner runner(o, 4);
  o.task_runner = &runner;
  const TraceResult r =
      TraceCurves(model_, prop_, start_, o, [](double fraction) { return fraction < 0.99; });
  EXPECT_TRUE(r.summary.cancelled());
  EXPECT_FALSE(r.curves.empty());
  EXPECT_EQ(runner.taken() + runner.dropped(), runner.submitted());
}

// A runner that answers CANCELLED (its tasks cancelled with the trace) while the trace itself was
// not stopped yet: the trace ends cancelled, in the curves' stage as in the switching rounds,
// never completed with results missing.
TEST_F(TraceRunner, ARunnersCancelEndsTheTraceCancelled) {
  TraceOptions o = SmallBox();
  int64_t total = 0;
  {
    ShuffledRunner all(o, 4);
    o.task_runner = &all;
    ASSERT_TRUE(TraceCurves(model_, prop_, start_, o).summary.completed());
    total = all.taken();
  }
  ASSERT_GT(total, 4);
  for (const int64_t after : {int64_t{1}, total / 2, total - 2}) {
    ShuffledRunner runner(o, 4);
    runner.CancelAfter(after);
    o.task_runner = &runner;
    const TraceResult r = TraceCurves(model_, prop_, start_, o);
    EXPECT_TRUE(r.summary.cancelled())
        << after << " of " << total << ": " << r.summary.BriefReport();
    EXPECT_EQ(runner.taken() + runner.dropped(), runner.submitted());
  }
}

}  // namespace
}  // namespace drillbif
