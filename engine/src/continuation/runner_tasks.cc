#include "continuation/runner_tasks.h"

namespace drillbif::internal {

Status RunnerSwitchQueue::Queue(CurveKind from_kind, const Codim2Point& point,
                                const std::optional<SwitchCandidate>& fixed) {
  Point p;
  p.point = point;
  if (fixed.has_value()) {
    p.list = std::vector<SwitchCandidate>{*fixed};
    StatusOr<int64_t> run = tickets_.Submit(CandidateTask{point, *fixed, last_resort_});
    if (!run.ok()) return run.status();
    p.runs = {*run};
  } else {
    StatusOr<int64_t> t = tickets_.Submit(CandidatesTask{from_kind, point});
    if (!t.ok()) return t.status();
    p.candidates = *t;
  }
  points_.push_back(std::move(p));
  return Status::Ok();
}

// The runs of p's candidates that are not known now (p's candidates are in).
Status RunnerSwitchQueue::PromoteRuns(Point& p) {
  p.runs.resize(p.list->size());
  for (size_t i = 0; i < p.list->size(); ++i) {
    const SwitchCandidate& candidate = (*p.list)[i];
    if (p.runs[i].has_value() || !candidate.orbit.ok() || known_(candidate)) continue;
    StatusOr<int64_t> run = tickets_.Submit(CandidateTask{p.point, candidate, last_resort_});
    if (!run.ok()) return run.status();
    p.runs[i] = *run;
  }
  return Status::Ok();
}

Status RunnerSwitchQueue::Promote() {
  for (Point& p : points_) {
    if (!p.candidates.has_value() || !tickets_.Ready(*p.candidates)) continue;
    StatusOr<std::vector<SwitchCandidate>> list =
        tickets_.Take<std::vector<SwitchCandidate>>(*p.candidates);
    p.candidates.reset();
    if (!list.ok()) return list.status();
    p.list = *std::move(list);
    if (Status s = PromoteRuns(p); !s.ok()) return s;
  }
  return Status::Ok();
}

StatusOr<std::vector<SwitchCandidate>> RunnerSwitchQueue::FrontCandidates() {
  Point& p = points_.front();
  if (p.candidates.has_value()) {
    StatusOr<std::vector<SwitchCandidate>> list =
        tickets_.Take<std::vector<SwitchCandidate>>(*p.candidates);
    p.candidates.reset();
    if (!list.ok()) return list.status();
    p.list = *std::move(list);
  }
  p.runs.resize(p.list->size());
  return *p.list;
}

StatusOr<CandidateRun> RunnerSwitchQueue::TakeRun(size_t i) {
  Point& p = points_.front();
  if (!p.runs[i].has_value()) {
    StatusOr<int64_t> run = tickets_.Submit(CandidateTask{p.point, (*p.list)[i], last_resort_});
    if (!run.ok()) return run.status();
    p.runs[i] = *run;
  }
  const int64_t ticket = *p.runs[i];
  p.runs[i].reset();
  return tickets_.Take<CandidateRun>(ticket);
}

void RunnerSwitchQueue::DropRun(size_t i) {
  Point& p = points_.front();
  if (i < p.runs.size() && p.runs[i].has_value()) tickets_.Drop(*p.runs[i]);
  if (i < p.runs.size()) p.runs[i].reset();
}

void RunnerSwitchQueue::PopFront() {
  Point& p = points_.front();
  if (p.candidates.has_value()) tickets_.Drop(*p.candidates);
  for (const std::optional<int64_t>& run : p.runs) {
    if (run.has_value()) tickets_.Drop(*run);
  }
  points_.pop_front();
}

}  // namespace drillbif::internal
