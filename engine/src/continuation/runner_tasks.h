// A trace's tasks on a TraceTaskRunner (continuation/trace_tasks.h) instead of its threads: the
// tickets of one stage, and the switching stage's pipeline of candidates and runs.
#ifndef DRILLBIF_CONTINUATION_RUNNER_TASKS_H_
#define DRILLBIF_CONTINUATION_RUNNER_TASKS_H_

#include <cstdint>
#include <deque>
#include <functional>
#include <optional>
#include <set>
#include <utility>
#include <variant>
#include <vector>

#include "drillbif/continuation/trace_tasks.h"

namespace drillbif::internal {

// The tickets of one stage; at its end (scope exit) those neither taken nor dropped are dropped.
class RunnerTickets {
 public:
  RunnerTickets(TraceTaskRunner& runner, std::function<bool()> keep_going)
      : runner_(runner), keep_going_(std::move(keep_going)) {}
  ~RunnerTickets() {
    for (const int64_t t : live_) runner_.Drop(t);
  }
  RunnerTickets(const RunnerTickets&) = delete;
  RunnerTickets& operator=(const RunnerTickets&) = delete;

  size_t window() const { return runner_.window(); }
  StatusOr<int64_t> Submit(const TraceTask& task) {
    StatusOr<int64_t> ticket = runner_.Submit(task);
    if (ticket.ok()) live_.insert(*ticket);
    return ticket;
  }
  bool Ready(int64_t ticket) { return runner_.Ready(ticket); }
  // The result of the task, of type R (the task's alternative of TraceTaskResult).
  template <class R>
  StatusOr<R> Take(int64_t ticket) {
    live_.erase(ticket);
    StatusOr<TraceTaskResult> r = runner_.Take(ticket, keep_going_);
    if (!r.ok()) return r.status();
    if (R* value = std::get_if<R>(&*r)) return std::move(*value);
    return Internal("a trace task's result is of another kind than its task");
  }
  void Drop(int64_t ticket) {
    if (live_.erase(ticket) > 0) runner_.Drop(ticket);
  }

 private:
  TraceTaskRunner& runner_;
  std::function<bool()> keep_going_;
  std::set<int64_t> live_;
};

// Switching at codimension-2 points on a runner, with the local threads' speculation: per point a
// CandidatesTask (a deferred candidate: its CandidateTask at once); as soon as a point's
// candidates are in (Promote), a CandidateTask for each not `known` among the curves applied so
// far. The caller applies the points in order, as with the threads.
class RunnerSwitchQueue {
 public:
  RunnerSwitchQueue(TraceTaskRunner& runner, std::function<bool()> keep_going,
                    std::function<bool(const SwitchCandidate&)> known, bool last_resort)
      : tickets_(runner, std::move(keep_going)),
        known_(std::move(known)),
        last_resort_(last_resort) {}

  size_t window() const { return tickets_.window(); }
  size_t size() const { return points_.size(); }

  // Queues point `point` of a curve of kind `from_kind`, or, given, one deferred candidate of it.
  Status Queue(CurveKind from_kind, const Codim2Point& point,
               const std::optional<SwitchCandidate>& fixed);
  // Submits the runs of the candidates that have come in.
  Status Promote();
  // The front point's candidates (waiting for them).
  StatusOr<std::vector<SwitchCandidate>> FrontCandidates();
  // The run of the front point's candidate i (waiting; submitted now if it was not).
  StatusOr<CandidateRun> TakeRun(size_t i);
  // The run of the front point's candidate i is not needed.
  void DropRun(size_t i);
  // Done with the front point: what remains of it is dropped.
  void PopFront();

 private:
  struct Point {
    Codim2Point point;
    std::optional<int64_t> candidates;  // the CandidatesTask's ticket until taken
    std::optional<std::vector<SwitchCandidate>> list;
    std::vector<std::optional<int64_t>> runs;  // per candidate, once promoted
  };
  Status PromoteRuns(Point& p);

  RunnerTickets tickets_;
  std::function<bool(const SwitchCandidate&)> known_;
  bool last_resort_;
  std::deque<Point> points_;
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_RUNNER_TASKS_H_
