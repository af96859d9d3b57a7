#include "drillbif/continuation/trace.h"

#include <algorithm>
#include <cmath>
#include <deque>
#include <functional>
#include <future>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <tuple>
#include <type_traits>
#include <unordered_set>
#include <utility>
#include <variant>
#include <vector>

#include "common/phase_progress.h"
#include "continuation/curve_tasks.h"
#include "continuation/runner_tasks.h"
#include "continuation/tangent_grazing.h"
#include "continuation/trace_internal.h"
#include "drillbif/common/threads.h"
#include "region/segment_index.h"

namespace drillbif {

Status TraceOptions::Validate() const {
  if (param1.empty() || param2.empty() || param1 == param2) {
    return InvalidArgument("param1 and param2 must name two different parameters");
  }
  if (!(std::isfinite(min1) && std::isfinite(max1) && min1 < max1)) {
    return InvalidArgument("the box in " + param1 + ": need finite min1 < max1");
  }
  if (!(std::isfinite(min2) && std::isfinite(max2) && min2 < max2)) {
    return InvalidArgument("the box in " + param2 + ": need finite min2 < max2");
  }
  if (!(duplicate_distance > 0.0 && std::isfinite(duplicate_distance))) {
    return InvalidArgument("duplicate_distance: need a finite value > 0");
  }
  for (const double s : seeds1) {
    if (!(std::isfinite(s) && s >= min1 && s <= max1)) {
      return InvalidArgument("seeds1: each value of " + param1 + " must lie in the box [" +
                             std::to_string(min1) + ", " + std::to_string(max1) + "], got " +
                             std::to_string(s));
    }
  }
  if (threads < 0 || threads > kMaxTraceThreads) {
    return InvalidArgument("threads: need 0 (every core) .. " + std::to_string(kMaxTraceThreads) +
                           ", got " + std::to_string(threads));
  }
  if (doubled_branch_target_iterations < 1 ||
      doubled_branch_target_iterations > branch.steps.max_iterations) {
    return InvalidArgument("doubled_branch_target_iterations: need 1 .. branch max_iterations (" +
                           std::to_string(branch.steps.max_iterations) + "), got " +
                           std::to_string(doubled_branch_target_iterations));
  }
  if (max_period < 1 || max_period > 16 || (max_period & (max_period - 1)) != 0) {
    return InvalidArgument(
        "max_period: need 1, 2, 4, 8 or 16 (periods of a doubling cascade), got " +
        std::to_string(max_period));
  }
  return Status::Ok();
}

ContinuationOptions TraceOptions::BranchOptions(int periods) const {
  ContinuationOptions o = branch;
  if (periods > 1) o.steps.target_iterations = doubled_branch_target_iterations;
  return o;
}

namespace internal {

CurveOutline OutlineOf(const CurveResult& c) {
  CurveOutline o;
  const size_t n = c.points.size();
  o.values1.reserve(n), o.values2.reserve(n), o.signature.reserve(n);
  for (const CurvePoint& p : c.points) {
    o.values1.push_back(p.value1);
    o.values2.push_back(p.value2);
    // A curve's signature changes only at its switches: the last one first.
    const Signature& s = p.orbit.signature;
    int k = static_cast<int>(o.signatures.size()) - 1;
    for (; k >= 0 && !(o.signatures[k] == s); --k) {
    }
    if (k < 0) {
      k = static_cast<int>(o.signatures.size());
      o.signatures.push_back(s);
    }
    o.signature.push_back(k);
    o.durations.insert(o.durations.end(), p.orbit.durations.begin(), p.orbit.durations.end());
  }
  o.durations.shrink_to_fit();
  return o;
}

void AppendCurve(const SpecialPoint& start, std::string start_param, CurveResult curve,
                 TraceResult* result, int from_curve, int from_codim2) {
  TracedCurve& t = result->curves.emplace_back();
  t.start = start;
  t.start_param = std::move(start_param);
  t.outline = OutlineOf(curve);
  t.curve = std::move(curve);
  t.from_curve = from_curve;
  t.from_codim2 = from_codim2;
}

double DistanceToCurve(const CurveOutline& c, double u, double v, double w1, double w2) {
  const Eigen::Vector2d x(u / w1, v / w2);
  const size_t n = c.size();
  auto at = [&](size_t k) { return Eigen::Vector2d(c.values1[k] / w1, c.values2[k] / w2); };
  double best = std::numeric_limits<double>::infinity();
  for (size_t k = 0; k < n; ++k)
    best = std::min(best, DistanceL2(x, at(k), at(k + 1 < n ? k + 1 : k)));
  return best;
}

bool OnCurve(const CurveOutline& c, double u, double v, double w1, double w2, double tol) {
  const Eigen::Vector2d x(u / w1, v / w2);
  const size_t n = c.size();
  auto at = [&](size_t k) { return Eigen::Vector2d(c.values1[k] / w1, c.values2[k] / w2); };
  // The turning angle at vertex k (0 at the ends).
  auto turn = [&](size_t k) {
    if (k == 0 || k + 1 >= n) return 0.0;
    const Eigen::Vector2d d0 = at(k) - at(k - 1), d1 = at(k + 1) - at(k);
    const double nn = d0.norm() * d1.norm();
    return nn > 0.0 ? std::acos(std::clamp(d0.dot(d1) / nn, -1.0, 1.0)) : 0.0;
  };
  if (n == 1) return (at(0) - x).norm() <= tol;
  for (size_t k = 0; k + 1 < n; ++k) {
    const Eigen::Vector2d a = at(k), b = at(k + 1);
    // The bow lies in [0, |b - a| / 8]: the turning angles only decide a distance between.
    const double distance = DistanceL2(x, a, b), length = (b - a).norm();
    if (distance <= tol) return true;
    if (distance > tol + length * 0.5 / 4.0) continue;
    const double bow = length * std::min(std::max(turn(k), turn(k + 1)), 0.5) / 4.0;
    if (distance <= tol + bow) return true;
  }
  return false;
}

bool OnTracedCurve(const TracedCurve& t, double u, double v, double w1, double w2, double tol) {
  const CurveOutline& line = t.outline;
  if (OnCurve(line, u, v, w1, w2, tol)) return true;
  const size_t n = line.size();
  if (n == 0) return false;
  const Eigen::Vector2d x(u / w1, v / w2);
  auto at = [&](size_t k) { return Eigen::Vector2d(line.values1[k] / w1, line.values2[k] / w2); };
  // How far an end's durations lie from the first (k = 0) or last vertex's, the end's tangent
  // segments merged with the segment of the same mode after them (the vertices' form); infinite
  // where they do not pair. From the outline, not the curve's points: switching's workers call
  // this while the trace releases the vertices of curves handed over (CurveStream).
  auto durations_off = [&](const PeriodicOrbit& end, size_t k) {
    const size_t count = line.SignatureAt(k).segments.size();
    const float* d = line.durations.data() + (k == 0 ? 0 : line.durations.size() - count);
    std::vector<double> merged;
    const std::vector<SegmentSpec>& segs = end.signature.segments;
    for (size_t j = 0; j < end.durations.size(); ++j) {
      merged.push_back(end.durations[j]);
      if (j < segs.size() && segs[j].tangent && j + 1 < end.durations.size()) {
        merged.back() += end.durations[++j];
      }
    }
    if (merged.size() != count) return std::numeric_limits<double>::infinity();
    double off = 0.0;
    for (size_t j = 0; j < count; ++j) off = std::max(off, std::abs(merged[j] - d[j]));
    return off;
  };
  for (const Codim2Point& end : t.curve.codim2) {
    if (end.violation.admissible) continue;  // a root between two vertices, not an end
    const Eigen::Vector2d e(end.point.value1 / w1, end.point.value2 / w2);
    const double off_first = durations_off(end.point.orbit, 0);
    const double off_last = durations_off(end.point.orbit, n - 1);
    // Where neither pairs (a section crossing between), the end vertex nearer in the box.
    const bool last = std::isfinite(off_first) || std::isfinite(off_last)
                          ? off_last < off_first
                          : (e - at(n - 1)).norm() < (e - at(0)).norm();
    const size_t k = last ? n - 1 : 0;
    // The chord allowance with the turn from the polyline's end chord onto the stretch.
    double turn = 0.0;
    if (n >= 2) {
      const Eigen::Vector2d d0 = last ? at(k) - at(k - 1) : at(k) - at(k + 1), d1 = e - at(k);
      const double nn = d0.norm() * d1.norm();
      turn = nn > 0.0 ? std::acos(std::clamp(d0.dot(d1) / nn, -1.0, 1.0)) : 0.0;
    }
    const double bow = (e - at(k)).norm() * std::min(turn, 0.5) / 4.0;
    if (DistanceL2(x, at(k), e) <= tol + bow) return true;
  }
  return false;
}

void SwapValues(CurveResult* c) {
  for (CurvePoint& p : c->points) std::swap(p.value1, p.value2);
  for (CurvePoint& p : c->crossings) std::swap(p.value1, p.value2);
  for (Codim2Point& q : c->codim2) std::swap(q.point.value1, q.point.value2);
}

std::string PeriodPrefix(int periods) {
  return periods == 1 ? "" : "period-" + std::to_string(periods) + " ";
}

bool IsGrazing(SpecialPointKind kind) {
  return kind == SpecialPointKind::kGrazingL1 || kind == SpecialPointKind::kGrazingL2 ||
         kind == SpecialPointKind::kGrazingPi;
}

}  // namespace internal

namespace {

// The message of a cancelled trace: the curves traced until then are its result.

using internal::DistanceToCurve;
using internal::GrazingKind;
using internal::kCancelledMessage;
using internal::PeriodPrefix;
using internal::SwapValues;
using internal::SwitchAtCodim2;
using internal::SwitchTally;
using internal::TallyNotes;

// The threads of the curve tasks: TraceOptions::threads, 0 meaning every core.
int ThreadsOf(const TraceOptions& options) { return ThreadsOrCores(options.threads); }

// Whether ContinueCurve starts from a point of this kind.
bool Traceable(SpecialPointKind kind) {
  return kind == SpecialPointKind::kFold || kind == SpecialPointKind::kPeriodDoubling ||
         kind == SpecialPointKind::kNeimarkSacker || internal::IsGrazing(kind);
}

// Releases a handed-over curve's interior vertices (TraceOptions::vertex_states false): `points`
// keeps its first and last.
void ReleaseInterior(int max_period, TracedCurve* c) {
  std::vector<CurvePoint>& points = c->curve.points;
  if (points.size() < 3 || internal::KeptWhole(max_period, c->curve)) return;
  points.erase(points.begin() + 1, points.end() - 1);
  points.shrink_to_fit();
}

// Hands the curves to TraceCurves' on_curve, each once it is final (the held-back ones at the
// end); without TraceOptions::vertex_states, first drops the vertex states of the curves appended
// since the last call (DropVertexStates), and releases the interior vertices of those handed over
// (ReleaseInterior), so that memory does not hold them until the trace's end.
class CurveStream {
 public:
  CurveStream(const TracedCurveCallback& on_curve, const TraceOptions& options, TraceResult& result)
      : on_curve_(on_curve), options_(options), result_(result) {}
  // Hands over the curves final by now (`all`: every one, the trace having ended). False when
  // on_curve asked to stop.
  bool Flush(bool all) {
    std::vector<TracedCurve>& curves = result_.curves;
    for (; !options_.vertex_states && dropped_ < curves.size(); ++dropped_) {
      internal::DropVertexStates(options_.max_period, &curves[dropped_].curve);
    }
    if (!on_curve_ || stopped_) return !stopped_;
    for (; next_ < curves.size(); ++next_) {
      if (!all && internal::MayMergeAtFlipGrazing(curves[next_])) {
        held_.push_back(next_);
      } else if (!HandOver(next_)) {
        return false;
      }
    }
    if (all) {
      for (const size_t c : held_) {
        if (!HandOver(c)) return false;
      }
      held_.clear();
    }
    return true;
  }

 private:
  bool HandOver(size_t c) {
    if (!on_curve_(static_cast<int>(c), result_.curves[c])) {
      stopped_ = true;  // called no more
      return false;
    }
    if (!options_.vertex_states) ReleaseInterior(options_.max_period, &result_.curves[c]);
    return true;
  }

  const TracedCurveCallback& on_curve_;
  const TraceOptions& options_;
  TraceResult& result_;
  size_t next_ = 0;           // curves from here on not looked at yet
  std::vector<size_t> held_;  // curves held back until the end (index order)
  size_t dropped_ = 0;        // curves whose vertex states are dropped (vertex_states false)
  bool stopped_ = false;
};

// One trace, in named stages: the seeds' attractors (Seeds), the branches through the start and
// through them (StartBranchJobs), the period-2n branches (DoubledBranchJobs), the curves from
// their located points (TraceStarts; BranchesAndStarts runs these three), switching at
// codimension-2 points (SwitchFrom), the edge rounds
// (EdgeRounds), the last-resort step-offs (LastResortStepOffs) and the notes (Notes). Each stage
// returns false when the trace was cancelled. The branches, curves and switching run as tasks on
// the workers (continuation/curve_tasks.h), each applied on the calling thread in the order of a
// plain loop: the notes, branch point counts, starts and curves are the same whatever the threads.
class TraceDriver {
 public:
  TraceDriver(const HybridModel& model, Propagator& propagator, const PeriodicOrbit& start,
              const TraceOptions& options, const TraceProgress& progress, CurveStream* stream,
              TraceResult* result)
      : model_(model),
        propagator_(propagator),
        start_(start),
        options_(options),
        phase_(propagator, progress),
        stream_(*stream),
        result_(*result),
        sum_(result->summary) {}

  // Branches computed ahead end at their next poll; their threads are joined (prefetched_).
  ~TraceDriver() { prefetch_abandon_ = true; }

  // TraceCurves without its notes' last pass and the last curves' hand-over.
  void Run() {
    if (!Validate()) return;
    // The curve tasks' threads (none of its own with a task runner); while the calling thread
    // waits for one, it polls the trace's throttle and abandons the tasks at a stop.
    workers_.emplace(propagator_, options_.task_runner != nullptr ? 1 : ThreadsOf(options_));
    wait_ = [this] {
      if (phase_.Continue()) return;
      workers_->Abandon();
      prefetch_abandon_ = true;
    };
    // The first edge round's branches computed ahead, while the curves are traced and switched
    // (AdvanceEdgeChains): with more than one thread, on threads of their own.
    prefetching_ =
        options_.edge_branches && options_.task_runner == nullptr && workers_->threads() > 1;
    if (!Seeds() || !BranchesAndStarts() || !SwitchFrom(0) || Stopped()) return;
    if (!EdgeRounds() || !LastResortStepOffs()) return;
    Notes();
  }

 private:
  struct Axis {
    const std::string* name;
    int index;
    double min, max;
  };
  // A located point on a branch along an edge (EdgeRounds).
  struct EdgePoint {
    int edge;  // 0 / 1: param1 at min1 / max1; 2 / 3: param2 at min2 / max2
    SpecialPointKind kind;
    int periods;
    double value;  // of the parameter along the edge
  };
  // A curve's end on the box's edge, where an edge branch may start (EdgeRounds).
  struct EdgeEnd {
    EdgePoint at;
    int along;             // the axis of the branch along the edge
    PeriodicOrbit orbit;   // the curve's end vertex
    std::string from_end;  // where it is, for the branch's note
    size_t curve;          // the curve's index
    int end;               // 0: its first point, 1: its last
  };
  // An edge end's place (curve, end, edge): the key of a branch computed ahead.
  using EdgeKey = std::tuple<size_t, int, int>;
  static EdgeKey KeyOf(const EdgeEnd& e) { return {e.curve, e.end, e.at.edge}; }
  // One edge's chain of the first edge round, followed ahead (AdvanceEdgeChains).
  struct EdgeChain {
    std::deque<EdgeEnd> ends;        // the ends on the edge of the curves seen, not decided on
    std::vector<EdgePoint> located;  // the points of the chain's branches so far
    std::optional<EdgeEnd> running;  // the end whose branch runs ahead
  };

  bool Validate();
  // Progress: the two branches take the first tenth, the curves the rest (one share each); the
  // edge rounds (their work not known ahead) stay where switching left it. Never backwards.
  // Also hands over the curves final by now (stream). False once cancelled.
  bool Report(double fraction) {
    if (prefetching_) AdvanceEdgeChains();
    reported_ = std::max(reported_, fraction);
    if (!sum_.cancelled() && (!phase_.Continue(reported_) || !stream_.Flush(false))) {
      sum_.Cancel(kCancelledMessage);
    }
    return !sum_.cancelled();
  }
  // Whether the trace was stopped (meanwhile, by a flow's poll; then nothing since is kept), or
  // failed (a task runner's error).
  bool Stopped() {
    if (phase_.stopped() && !sum_.cancelled() && !sum_.failed()) sum_.Cancel(kCancelledMessage);
    return sum_.cancelled() || sum_.failed();
  }
  // Ends the trace with a task runner's error: cancelled for CANCELLED (the trace was stopped),
  // else failed with it. False.
  bool TaskFailed(const Status& why) {
    if (why.code() == StatusCode::kCancelled) {
      if (!sum_.cancelled()) sum_.Cancel(kCancelledMessage);
    } else {
      sum_.Fail(why);
    }
    return false;
  }
  // A branch as a worker computes it (ComputeBranch), for ApplyBranch.
  struct BranchRun {
    std::string note;  // non-empty: no branch to run (a doubling without one), the note instead
    int periods = 1;   // of the branch's orbits
    // The branch's points are dropped once it has run (ComputeBranch): the trace reads its
    // located points and counts the others. An edge branch computed ahead is held until its round
    // takes it; whole, it would hold ~6500 points with their orbits.
    ContinuationResult r;
    int64_t points = 0;  // r.points' count before they were dropped
    // Per located point (r.special_points): a fold on the period-n orbit traversed twice
    // (internal::TraversedTwice, which simulates: tested on the worker); false where not tested.
    std::vector<bool> twice;
  };
  // A seed's attractor (SeedAttractor).
  struct Attractor {
    std::string note;  // non-empty: none (why), the note for it
    PeriodicOrbit orbit;
  };
  // One step of a stage that InOrder runs: its computation, a task on the workers, and its
  // application on the calling thread, in the stage's order.
  template <class Result>
  struct Job {
    double from = 0.0, to = 0.0;  // progress while it runs on the calling thread
    // The computation on a worker's propagator, reading no state the trace changes meanwhile;
    // `report` the progress callback when it runs on the calling thread, else empty. Null:
    // nothing to compute (apply gets null).
    std::function<Result(Propagator&, const ContinuationCallback& report)> compute;
    // Applies the result; false when the trace was stopped.
    std::function<bool(Result*)> apply;
  };
  // A branch computed ahead, and the end it runs through.
  struct Ahead {
    EdgeEnd end;
    std::shared_future<BranchRun> run;
  };
  template <class Result>
  bool InOrder(std::vector<Job<Result>>& jobs);
  // Queues `job` on `tasks` (whose results are Result, or a variant holding it): a task unless it
  // computes nothing; `queued` records which.
  template <class Result, class Computed>
  void QueueJob(Job<Result>* job, std::deque<bool>* queued,
                internal::OrderedTasks<Computed>* tasks);
  // Applies `job`, the first of `queued`, with its result from `tasks` (its progress reported
  // first). False when the trace was stopped.
  template <class Result, class Computed>
  bool ApplyJob(Job<Result>& job, std::deque<bool>* queued,
                internal::OrderedTasks<Computed>* tasks);
  BranchRun ComputeBranch(const PeriodicOrbit& orbit, int axis, ContinuationDirection direction,
                          Propagator& p, const ContinuationCallback& report) const;
  static bool TurnOfDoubled(const ContinuationResult& r, const SpecialPoint& s);
  std::vector<std::pair<int, SpecialPoint>> Located(const BranchRun& run, int axis) const;
  bool ApplyBranch(const BranchRun& run, int axis, const std::string& edge);
  ContinuationCallback ReportHere(double from, double to);
  bool EdgeBranches(const std::vector<EdgeEnd>& ends, std::vector<EdgePoint>* on_edge_branches);
  Job<BranchRun> BranchJob(PeriodicOrbit orbit, int axis, double from, double to,
                           ContinuationDirection direction);
  Attractor SeedAttractor(double seed, Propagator& p) const;
  bool Seeds();
  std::vector<Job<BranchRun>> StartBranchJobs();
  std::vector<Job<BranchRun>> DoubledBranchJobs(int period, int level, int levels,
                                                size_t* level_begin);
  bool BranchesAndStarts();
  std::string WhereOf(const SpecialPoint& s) const;
  const TracedCurve* KnownCurve(const SpecialPoint& s) const;
  CurveResult CurveFrom(const SpecialPoint& s, int axis, Propagator& p) const;
  bool TraceStarts(size_t first, double from, double to,
                   std::vector<Job<BranchRun>>* branches = nullptr);
  bool SwitchFrom(size_t first_curve);
  bool EdgeRounds();
  std::vector<EdgeEnd> EdgeEndsOf(size_t c) const;
  bool Covered(const std::vector<EdgePoint>& located, const EdgePoint& at, int along) const;
  void RecordEdgePoints(const EdgeEnd& e, const BranchRun& run,
                        std::vector<EdgePoint>* located) const;
  void AdvanceEdgeChains();
  static bool SameEnd(const EdgeEnd& a, const EdgeEnd& b);
  std::shared_future<BranchRun> ComputeAhead(const EdgeEnd& e);
  bool LastResortStepOffs();
  void Notes();

  const HybridModel& model_;
  Propagator& propagator_;
  const PeriodicOrbit& start_;
  const TraceOptions& options_;
  internal::PhaseProgress phase_;
  CurveStream& stream_;
  TraceResult& result_;
  TraceSummary& sum_;
  int i1_ = 0, i2_ = 0;
  double w1_ = 0.0, w2_ = 0.0;  // the box's widths
  Axis axes_[2] = {};
  double reported_ = 0.0;
  std::optional<internal::WorkerPropagators> workers_;
  std::function<void()> wait_;
  std::vector<std::pair<int, SpecialPoint>> starts_;  // (axis, located point)
  std::vector<Attractor> attractors_;                 // the seeds', from Seeds to StartBranchJobs
  SwitchTally tally_;
  int edge_runs_ = 0;
  // The first edge round's branches computed ahead (AdvanceEdgeChains). Declared in this order:
  // the futures are destroyed first, joining their threads, before the propagators they run on.
  bool prefetching_ = false;
  size_t prefetch_seen_ = 0;  // the curves whose edge ends were handed to the chains
  EdgeChain chains_[4];
  std::atomic<bool> prefetch_abandon_{false};
  std::vector<std::unique_ptr<ProgressThrottle>> prefetch_throttles_;
  std::vector<std::unique_ptr<Propagator>> prefetch_propagators_;
  std::map<EdgeKey, Ahead> prefetched_;
};

bool TraceDriver::Validate() {
  if (Status s = options_.Validate(); !s.ok()) {
    sum_.Fail(s);
    return false;
  }
  const StatusOr<int> i1 = model_.ParamIndex(options_.param1);
  const StatusOr<int> i2 = model_.ParamIndex(options_.param2);
  if (!i1.ok() || !i2.ok()) {
    sum_.Fail(InvalidArgument((!i1.ok() ? i1 : i2).status().message()));
    return false;
  }
  i1_ = *i1, i2_ = *i2;
  w1_ = options_.width1(), w2_ = options_.width2();
  axes_[0] = {&options_.param1, i1_, options_.min1, options_.max1};
  axes_[1] = {&options_.param2, i2_, options_.min2, options_.max2};
  for (const Axis& a : axes_) {
    const double v0 = start_.params[a.index];
    if (v0 < a.min || v0 > a.max) {
      sum_.Fail(InvalidArgument("the start orbit's " + *a.name + " lies outside the box"));
      return false;
    }
  }
  // Completed unless a stop says otherwise: a curve or branch that fails is a note.
  sum_.Complete();
  return true;
}

// The branch through `orbit` in the axis' parameter over the box, on propagator `p` (a worker's):
// the continuation and the tests of its located points that need flows. Touches no state of the
// trace. `report`: the continuation's callback (progress on the calling thread), or empty.
TraceDriver::BranchRun TraceDriver::ComputeBranch(const PeriodicOrbit& orbit, int axis,
                                                  ContinuationDirection direction, Propagator& p,
                                                  const ContinuationCallback& report) const {
  const Axis& a = axes_[axis];
  ContinuationOptions branch = options_.BranchOptions(orbit.signature.periods);
  branch.direction = direction;
  // Only the branches' bifurcations start curves: no ROP / Pc maxima, no measures kept.
  branch.locate_measure_maxima = false;
  branch.point_measures = 0u;
  branch.param = *a.name;
  branch.min = a.min;
  branch.max = a.max;
  // A period-2 branch that reaches a branch point has met the doubled period-1 branch at
  // another doubling; beyond it run the same orbits shifted by one period: it stops there
  // (BranchTracer::NoteStop).
  const bool doubled = orbit.signature.periods > 1;
  BranchRun run;
  run.periods = orbit.signature.periods;
  run.r = Continue(model_, p, orbit, branch, report);
  run.points = static_cast<int64_t>(run.r.points.size());
  std::vector<ContinuationPoint>().swap(run.r.points);
  const std::vector<SpecialPoint>& specials = run.r.special_points;
  run.twice.assign(specials.size(), false);
  for (size_t k = 0; k < specials.size(); ++k) {
    const SpecialPoint& s = specials[k];
    if (doubled && s.kind == SpecialPointKind::kFold && !TurnOfDoubled(run.r, s)) {
      run.twice[k] = internal::TraversedTwice(model_, p, s.point.orbit);
    }
  }
  return run;
}

// At a branch point the period-2 branch's parameter turns (its two halves meet): a fold located
// there is that turn, not a fold of the orbits.
bool TraceDriver::TurnOfDoubled(const ContinuationResult& r, const SpecialPoint& s) {
  return s.kind == SpecialPointKind::kFold &&
         std::any_of(r.special_points.begin(), r.special_points.end(), [&](const SpecialPoint& b) {
           return b.kind == SpecialPointKind::kBranchPoint &&
                  std::abs(b.point.value - s.point.value) <= 1e-6 * (1.0 + std::abs(b.point.value));
         });
}

// Applies a branch computed by ComputeBranch: its notes, its point count, its traceable points
// appended to starts_. `edge`: where an edge branch starts ("" for the others), for its note if
// it stops early. False when the trace was stopped.
bool TraceDriver::ApplyBranch(const BranchRun& run, int axis, const std::string& edge) {
  const Axis& a = axes_[axis];
  const ContinuationResult& r = run.r;
  // Cut short on a worker: only a stop of the trace abandons the workers' runs.
  if (r.summary.termination == Termination::kCancelled) {
    if (!sum_.cancelled()) sum_.Cancel(kCancelledMessage);
    return false;
  }
  sum_.branch_points += run.points;
  if (r.summary.termination == Termination::kFailed && edge.empty()) {
    sum_.notes.push_back("the " + PeriodPrefix(run.periods) + *a.name +
                         "-branch failed: " + r.summary.message);
  } else if (r.summary.termination == Termination::kFailed) {
    // An edge branch searches for more curves; where it stops, the curves crossing the edge
    // beyond are found only if another edge branch or switching reaches them (in the
    // reference box one period-2 edge branch stops with max_period 2; two period-1 ones did at
    // omega = 0.05, a = 0.2153, before branch_tracer.cc's CrossGrazing saw a touch hidden
    // behind a vanishing segment). Not a failure of the curves asked for.
    sum_.notes.push_back("the " + PeriodPrefix(run.periods) + *a.name +
                         "-branch along the box's edge from " + edge +
                         " stopped early: " + r.summary.message);
  }
  for (size_t k = 0; k < r.special_points.size(); ++k) {
    // A fold of the period-2n system on the period-n orbit traversed twice is that orbit's
    // doubling (multiplier -1, squared): the period-2 omega-branch from the doubling at
    // omega = 0.2698 (a = 0.3) ran on through its other birth at 1.6258 onto the doubled
    // branch and located a fold at 1.62585, 8e-5 from the branch point (so not its turn,
    // TurnOfDoubled); its "fold curve" was the period-1 PD curve, one point each way.
    if (run.twice[k]) {
      sum_.notes.push_back(PeriodPrefix(run.periods) + "FOLD at " + *a.name + " = " +
                           std::to_string(r.special_points[k].point.value) + " on the period-" +
                           std::to_string(run.periods / 2) +
                           " orbit traversed twice (its period doubling): not traced");
    }
  }
  for (std::pair<int, SpecialPoint>& start : Located(run, axis)) {
    starts_.push_back(std::move(start));
  }
  return true;
}

// The starts of a branch's located points, (axis, point), in the order located: its traceable
// points but the turns of a doubled branch and its folds on the orbit traversed twice.
std::vector<std::pair<int, SpecialPoint>> TraceDriver::Located(const BranchRun& run,
                                                               int axis) const {
  std::vector<std::pair<int, SpecialPoint>> located;
  const std::vector<SpecialPoint>& specials = run.r.special_points;
  for (size_t k = 0; k < specials.size(); ++k) {
    const SpecialPoint& s = specials[k];
    if ((run.periods > 1 && TurnOfDoubled(run.r, s)) || run.twice[k]) continue;
    if (Traceable(s.kind)) {
      located.emplace_back(axis, s);
    } else if (s.kind == SpecialPointKind::kSignatureChange &&
               internal::CornerSegment(model_, s.point.orbit) >= 0) {
      // A signature change at a corner (a segment vanishing between events of two surfaces,
      // e.g. an impact going straight into progression) is a grazing: its corner's curve.
      SpecialPoint corner = s;
      corner.kind = GrazingKind(model_, s.point.orbit);
      located.emplace_back(axis, std::move(corner));
    }
  }
  return located;
}

// The progress callback of a branch run on the calling thread (one thread), else empty: a
// worker reports nothing, the calling thread reports while it waits.
ContinuationCallback TraceDriver::ReportHere(double from, double to) {
  if (workers_->threads() > 1) return {};
  return [this, from, to](const ContinuationPoint&, double f) {
    return Report(from + (to - from) * f);
  };
}

// The job of the branch through `orbit` (ComputeBranch, then ApplyBranch), progress from `from`
// to `to`.
TraceDriver::Job<TraceDriver::BranchRun> TraceDriver::BranchJob(PeriodicOrbit orbit, int axis,
                                                                double from, double to,
                                                                ContinuationDirection direction) {
  Job<BranchRun> job;
  job.from = from, job.to = to;
  job.compute = [this, orbit = std::move(orbit), axis, direction](
                    Propagator& p, const ContinuationCallback& report) {
    return ComputeBranch(orbit, axis, direction, p, report);
  };
  job.apply = [this, axis](BranchRun* run) { return ApplyBranch(*run, axis, ""); };
  return job;
}

// Runs the jobs as tasks on the workers (with one thread, each on the calling thread when its
// turn comes, as a plain loop would), applying each in order on the calling thread, which
// reports progress and polls for a stop while it waits (wait_).
template <class Result>
bool TraceDriver::InOrder(std::vector<Job<Result>>& jobs) {
  internal::TaskStage<Result> stage(*workers_);
  std::deque<bool> queued;  // per job queued and not applied: whether a task computes it
  size_t next = 0;
  for (size_t k = 0; k < jobs.size(); ++k) {
    for (; next < jobs.size() && queued.size() < stage.window(); ++next) {
      QueueJob(&jobs[next], &queued, &stage.tasks());
    }
    if (!ApplyJob(jobs[k], &queued, &stage.tasks())) return false;
  }
  return true;
}

template <class Result, class Computed>
void TraceDriver::QueueJob(Job<Result>* job, std::deque<bool>* queued,
                           internal::OrderedTasks<Computed>* tasks) {
  queued->push_back(static_cast<bool>(job->compute));
  if (!job->compute) return;
  tasks->Push([this, job](int worker) -> Computed {
    return job->compute(workers_->at(worker), ReportHere(job->from, job->to));
  });
}

template <class Result, class Computed>
bool TraceDriver::ApplyJob(Job<Result>& job, std::deque<bool>* queued,
                           internal::OrderedTasks<Computed>* tasks) {
  if (!Report(job.from)) return false;
  const bool computed = queued->front();
  queued->pop_front();
  std::optional<Computed> result;
  if (computed) {
    result = tasks->TakeFront(wait_);
    if (Stopped()) return false;
  }
  if (!result) return job.apply(nullptr);
  if constexpr (std::is_same_v<Result, Computed>) {
    return job.apply(&*result);
  } else {
    return job.apply(&std::get<Result>(*result));
  }
}

// The seeds' attractor (on propagator `p`), or the note why there is none.
TraceDriver::Attractor TraceDriver::SeedAttractor(double seed, Propagator& p) const {
  Params params = start_.params;
  params[i1_] = seed;
  const StateVector x0 =
      options_.seed_state.size() > 0 ? options_.seed_state : DefaultInitialState(model_);
  const std::string where = "seed " + options_.param1 + " = " + std::to_string(seed) + ": ";
  StatusOr<PeriodicOrbit> found = OrbitFromSimulation(model_, p, params, x0);
  if (!found.ok()) return {where + found.status().message(), {}};
  Attractor a{"", *std::move(found)};
  const OrbitSolveSummary solved = SolveOrbit(model_, p, {}, &a.orbit);
  if (!solved.completed()) {
    return {where + "the attractor's orbit did not solve: " + solved.message, {}};
  }
  if (a.orbit.signature.periods > options_.max_period) {
    return {where + "the attractor has period " + std::to_string(a.orbit.signature.periods) +
                " > max_period",
            {}};
  }
  return a;
}

bool TraceDriver::Seeds() {
  // The seeds' attractors (progress stays at the start meanwhile), their branches run with the
  // start's (StartBranchJobs).
  std::vector<Job<Attractor>> jobs(options_.seeds1.size());
  attractors_.resize(options_.seeds1.size());
  for (size_t k = 0; k < jobs.size(); ++k) {
    jobs[k].compute = [this, seed = options_.seeds1[k]](Propagator& p,
                                                        const ContinuationCallback&) {
      return SeedAttractor(seed, p);
    };
    jobs[k].apply = [this, k](Attractor* a) {
      attractors_[k] = std::move(*a);
      return true;
    };
  }
  return InOrder(jobs);
}

// The start's two branches, then each seed's (or the note why it has none), independent of each
// other: tasks on the workers, applied in this order.
std::vector<TraceDriver::Job<TraceDriver::BranchRun>> TraceDriver::StartBranchJobs() {
  std::vector<Job<BranchRun>> jobs;
  for (int axis = 0; axis < 2; ++axis) {
    jobs.push_back(
        BranchJob(start_, axis, 0.05 * axis, 0.05 * (axis + 1), options_.branch.direction));
  }
  for (Attractor& a : attractors_) {
    if (!a.note.empty()) {
      Job<BranchRun>& note = jobs.emplace_back();
      note.from = note.to = 0.1;
      note.apply = [this, text = a.note](BranchRun*) {
        sum_.notes.push_back(text);
        return true;
      };
      continue;
    }
    for (int axis = 0; axis < 2; ++axis) {
      jobs.push_back(BranchJob(a.orbit, axis, 0.1, 0.1, options_.branch.direction));
    }
  }
  attractors_.clear();
  return jobs;
}

// The period-2p branches born at the doublings of the period-p branches (p = `period`, level
// `level` of `levels`) applied since *level_begin in starts_ (moved to the end): independent of
// each other, tasks on the workers.
std::vector<TraceDriver::Job<TraceDriver::BranchRun>> TraceDriver::DoubledBranchJobs(
    int period, int level, int levels, size_t* level_begin) {
  const std::vector<std::pair<int, SpecialPoint>> parents(starts_.begin() + *level_begin,
                                                          starts_.end());
  *level_begin = starts_.size();
  std::vector<Job<BranchRun>> jobs;
  for (size_t k = 0; k < parents.size(); ++k) {
    const int axis = parents[k].first;
    const SpecialPoint& s = parents[k].second;
    if (s.kind != SpecialPointKind::kPeriodDoubling || s.point.orbit.signature.periods != period) {
      continue;
    }
    Job<BranchRun>& job = jobs.emplace_back();
    const double share = 0.1 / levels;
    job.from = 0.1 + share * (level + static_cast<double>(k) / parents.size());
    job.to = 0.1 + share * (level + static_cast<double>(k + 1) / parents.size());
    job.compute = [this, s, axis, period](Propagator& p, const ContinuationCallback& report) {
      // Algebraic switching finds sub- and supercritical branches; simulation is the fallback.
      // From the algebraic switch's orbit (next to the branch point) the branch is continued
      // away from the doubling only: towards it, it runs through the branch point (where its
      // parameter turns, a spurious fold) onto the same orbits shifted by one period.
      const int index = axes_[axis].index;
      ContinuationDirection direction = options_.branch.direction;
      StatusOr<PeriodicOrbit> doubled =
          SwitchAtPeriodDoublingAlgebraic(model_, p, s.point.orbit, *axes_[axis].name);
      if (doubled.ok()) {
        direction = doubled->params[index] > s.point.orbit.params[index]
                        ? ContinuationDirection::kIncreasing
                        : ContinuationDirection::kDecreasing;
      } else {
        doubled = SwitchAtPeriodDoubling(model_, p, s, *axes_[axis].name);
      }
      if (!doubled.ok()) {
        BranchRun none;
        none.note = PeriodPrefix(period) + "PERIOD_DOUBLING at " + options_.param1 + " = " +
                    std::to_string(s.point.orbit.params[i1_]) + ", " + options_.param2 + " = " +
                    std::to_string(s.point.orbit.params[i2_]) + ": no period-" +
                    std::to_string(2 * period) + " branch: " + doubled.status().message();
        return none;
      }
      return ComputeBranch(*doubled, axis, direction, p, report);
    };
    job.apply = [this, axis](BranchRun* run) {
      if (run->note.empty()) return ApplyBranch(*run, axis, "");
      sum_.notes.push_back(run->note);
      return true;
    };
  }
  return jobs;
}

// The branches and the curves from their located points: the start's and the seeds' branches,
// then the period-2p branches born at the period-p branches' doublings, p = 1, 2, ... while
// 2p <= max_period (each level's doublings are those of the branches the level before added),
// then the curves. The last level's branches share the curves' queue (TraceStarts): the curves
// of the branches applied are traced while a longer branch still runs.
bool TraceDriver::BranchesAndStarts() {
  std::vector<Job<BranchRun>> branches = StartBranchJobs();
  int levels = 0;
  for (int p = 1; 2 * p <= options_.max_period; p *= 2) ++levels;
  size_t level_begin = 0;
  for (int level = 0, period = 1; level < levels; ++level, period *= 2) {
    if (!InOrder(branches)) return false;
    branches = DoubledBranchJobs(period, level, levels, &level_begin);
  }
  return TraceStarts(0, options_.max_period > 1 ? 0.2 : 0.1, 1.0, &branches);
}

std::string TraceDriver::WhereOf(const SpecialPoint& s) const {
  return PeriodPrefix(s.point.orbit.signature.periods) + std::string(SpecialPointKindName(s.kind)) +
         " at " + options_.param1 + " = " + std::to_string(s.point.orbit.params[i1_]) + ", " +
         options_.param2 + " = " + std::to_string(s.point.orbit.params[i2_]);
}

// The curve traced already that the start lies on, or null: within duplicate_distance of it,
// with the allowance for the chords' error (which grows as the square of the step) and its end
// stretches (OnTracedCurve).
const TracedCurve* TraceDriver::KnownCurve(const SpecialPoint& s) const {
  const double u = s.point.orbit.params[i1_], v = s.point.orbit.params[i2_];
  const auto it =
      std::find_if(result_.curves.begin(), result_.curves.end(), [&](const TracedCurve& c) {
        return c.start.kind == s.kind &&
               c.start.point.orbit.signature.periods == s.point.orbit.signature.periods &&
               internal::OnTracedCurve(c, u, v, w1_, w2_, options_.duplicate_distance);
      });
  return it == result_.curves.end() ? nullptr : &*it;
}

// The curve through a start, on a worker's propagator (values in the start axis' order).
CurveResult TraceDriver::CurveFrom(const SpecialPoint& s, int axis, Propagator& p) const {
  return internal::CurveThroughStart(model_, p, options_, s, axis);
}

// The curves through starts_[first..], progress from `from` to `to`. Each start's curve is a task
// on the workers; each is applied in the order of the starts: a start on a curve traced already
// (from an earlier start) is named in a note, its curve dropped if it was computed meanwhile.
// `branches` (null: none): jobs of branches that add starts (ApplyBranch), queued and applied
// first, the starts' tasks queued behind them as they are added.
bool TraceDriver::TraceStarts(size_t first, double from, double to,
                              std::vector<Job<BranchRun>>* branches) {
  // A branch's run or a start's curve.
  using Computed = std::variant<BranchRun, CurveResult>;
  internal::TaskStage<Computed> stage(*workers_);
  internal::OrderedTasks<Computed>& tasks = stage.tasks();
  // With a task runner (TraceOptions::task_runner) the curves' tasks go there instead.
  std::optional<internal::RunnerTickets> remote;
  if (options_.task_runner != nullptr) {
    remote.emplace(*options_.task_runner, [this] { return phase_.Continue(); });
  }
  const size_t window = remote ? remote->window() : stage.window();
  const size_t jobs = branches != nullptr ? branches->size() : 0;
  // Per branch or start queued: whether a task computes it (a start: false when it was on a
  // traced curve when queued).
  std::deque<bool> queued;
  std::deque<int64_t> tickets;  // the runner's, per start computed
  size_t next_job = 0, next = first;
  // Queues the branches, then the starts up to the window, each unless it is on a curve applied
  // already. False on a runner's error.
  auto queue_more = [&] {
    for (; next_job < jobs && queued.size() < window; ++next_job) {
      QueueJob(&(*branches)[next_job], &queued, &tasks);
    }
    for (; next_job == jobs && next < starts_.size() && queued.size() < window; ++next) {
      const bool known = KnownCurve(starts_[next].second) != nullptr;
      queued.push_back(!known);
      if (known) continue;
      if (remote) {
        StatusOr<int64_t> ticket =
            remote->Submit(CurveTask{starts_[next].second, starts_[next].first});
        if (!ticket.ok()) return TaskFailed(ticket.status());
        tickets.push_back(*ticket);
        continue;
      }
      // A copy: the branches applied meanwhile append to starts_.
      tasks.Push([this, start = starts_[next]](int worker) -> Computed {
        return CurveFrom(start.second, start.first, workers_->at(worker));
      });
    }
    return true;
  };
  for (size_t job = 0; job < jobs; ++job) {
    if (!queue_more() || !ApplyJob((*branches)[job], &queued, &tasks)) return false;
  }
  for (size_t k = first; k < starts_.size(); ++k) {
    if (!queue_more()) return false;
    if (!Report(from + (to - from) * static_cast<double>(k - first) /
                           static_cast<double>(starts_.size() - first))) {
      return false;
    }
    const bool computed = queued.front();
    queued.pop_front();
    const int axis = starts_[k].first;
    const SpecialPoint& s = starts_[k].second;
    // (A start on a traced curve when queued is on it now: the curves only grow.)
    if (const TracedCurve* on = KnownCurve(s); on != nullptr) {
      if (computed && remote) remote->Drop(tickets.front()), tickets.pop_front();
      if (computed && !remote) tasks.DropFront();
      sum_.notes.push_back(WhereOf(s) + ": on the curve traced from " +
                           SpecialPointKindName(on->start.kind) + " already");
      continue;
    }
    CurveResult curve;
    if (remote) {
      StatusOr<CurveResult> taken = remote->Take<CurveResult>(tickets.front());
      tickets.pop_front();
      if (!taken.ok()) return TaskFailed(taken.status());
      curve = *std::move(taken);
    } else {
      curve = std::get<CurveResult>(*tasks.TakeFront(wait_));
    }
    if (curve.summary.termination == Termination::kFailed) {
      sum_.notes.push_back(WhereOf(s) + ": not traced: " + curve.summary.message);
      continue;
    }
    if (axis == 1) SwapValues(&curve);
    // Cut short by a stop: kept with what it has (termination kCancelled), if anything, and the
    // trace ends cancelled (Stopped() records it; `cut ||` before it would skip the record).
    const bool cut = curve.summary.termination == Termination::kCancelled;
    if (!cut || !curve.points.empty()) {
      internal::AppendCurve(s, *axes_[axis].name, std::move(curve), &result_);
    }
    if (cut && !sum_.cancelled()) sum_.Cancel(kCancelledMessage);
    if (Stopped()) return false;
  }
  return true;
}

// The curves leaving the codimension-2 points of the curves from first_curve on.
bool TraceDriver::SwitchFrom(size_t first_curve) {
  if (!options_.switch_at_codim2) return true;
  const std::function<bool(double)> report = [this](double f) { return Report(f); };
  if (!SwitchAtCodim2(model_, propagator_, *workers_, wait_, options_, report, first_curve, &tally_,
                      &result_)) {
    return false;
  }
  return options_.max_period == 1 ||
         internal::GrazingCurvesAtFlipGrazings(model_, propagator_, options_, report, first_curve,
                                               &result_);
}

// Edge rounds (TraceOptions::edge_branches): the branch along the box's edge through each fold /
// PD / NS curve's end on it, unless a branch run along that edge located that end's point already;
// the curves of their points, and the curves leaving those curves' codimension-2 points; again for
// the ends of the curves added, until no end is new.
bool TraceDriver::EdgeRounds() {
  prefetching_ = false;  // the branches computed ahead are the first round's
  std::vector<EdgePoint> on_edge_branches;
  size_t ends_from = 0;
  while (options_.edge_branches) {
    const size_t starts_before = starts_.size(), curves_before = result_.curves.size();
    // Copied: the reports while the branches run may release the vertices of curves handed over
    // (CurveStream).
    std::vector<EdgeEnd> ends;
    for (size_t c = ends_from; c < curves_before; ++c) {
      for (EdgeEnd& e : EdgeEndsOf(c)) ends.push_back(std::move(e));
    }
    if (!EdgeBranches(ends, &on_edge_branches)) return false;
    ends_from = curves_before;
    if (starts_.size() == starts_before) break;
    if (!TraceStarts(starts_before, 0.99, 0.99) || !SwitchFrom(curves_before) || Stopped()) {
      return false;
    }
  }
  return true;
}

// The ends of curve c on the box's edges (fold, PD and NS curves), in the order the edge rounds
// take them: its first point's, then its last's, each on edges 0 .. 3.
std::vector<TraceDriver::EdgeEnd> TraceDriver::EdgeEndsOf(size_t c) const {
  std::vector<EdgeEnd> ends;
  const double bounds[4] = {options_.min1, options_.max1, options_.min2, options_.max2};
  const CurveResult& curve = result_.curves[c].curve;
  if (curve.kind == CurveKind::kGrazing || curve.points.empty()) return ends;
  const SpecialPointKind kind = curve.kind == CurveKind::kFold ? SpecialPointKind::kFold
                                : curve.kind == CurveKind::kPeriodDoubling
                                    ? SpecialPointKind::kPeriodDoubling
                                    : SpecialPointKind::kNeimarkSacker;
  for (int which = 0; which < 2; ++which) {
    const CurvePoint* end = which == 0 ? &curve.points.front() : &curve.points.back();
    for (int edge = 0; edge < 4; ++edge) {
      // A curve that leaves the box ends on it exactly: its last point is solved there.
      if ((edge < 2 ? end->value1 : end->value2) != bounds[edge]) continue;
      const int along = edge < 2 ? 1 : 0;
      ends.push_back(
          {{edge, kind, end->orbit.signature.periods, along == 0 ? end->value1 : end->value2},
           along,
           end->orbit,
           std::string(CurveKindName(curve.kind)) + " curve's end at " + options_.param1 + " = " +
               std::to_string(end->value1) + ", " + options_.param2 + " = " +
               std::to_string(end->value2),
           c,
           which});
    }
  }
  return ends;
}

// Whether a branch along the same edge located the end's point already.
bool TraceDriver::Covered(const std::vector<EdgePoint>& located, const EdgePoint& at,
                          int along) const {
  const double tol = 1e-6 * (axes_[along].max - axes_[along].min);
  return std::any_of(located.begin(), located.end(), [&](const EdgePoint& e) {
    return e.edge == at.edge && e.kind == at.kind && e.periods == at.periods &&
           std::abs(e.value - at.value) <= tol;
  });
}

// The edge points a branch through end e adds for the decisions on the ends after it along the
// same edge: e's own, and those it located (none where it was cancelled).
void TraceDriver::RecordEdgePoints(const EdgeEnd& e, const BranchRun& run,
                                   std::vector<EdgePoint>* located) const {
  located->push_back(e.at);
  if (run.r.summary.termination == Termination::kCancelled) return;
  for (const auto& [axis, s] : Located(run, e.along)) {
    located->push_back({e.at.edge, s.kind, s.point.orbit.signature.periods, s.point.value});
  }
}

// Whether two edge ends are the same point of the same orbit, to the bit (a branch computed ahead
// through one is the other's).
bool TraceDriver::SameEnd(const EdgeEnd& a, const EdgeEnd& b) {
  const PeriodicOrbit &x = a.orbit, &y = b.orbit;
  return a.at.edge == b.at.edge && a.at.kind == b.at.kind && a.at.value == b.at.value &&
         a.along == b.along && x.signature == y.signature && x.params == y.params &&
         x.starts == y.starts && x.durations == y.durations;
}

// The branch through an edge end, started on a thread and a propagator of its own.
std::shared_future<TraceDriver::BranchRun> TraceDriver::ComputeAhead(const EdgeEnd& e) {
  std::unique_ptr<Propagator> p = propagator_.Clone();
  if (p == nullptr) return {};
  prefetch_throttles_.push_back(std::make_unique<ProgressThrottle>(
      [this](double) { return !prefetch_abandon_.load(std::memory_order_relaxed); }));
  p->set_progress(prefetch_throttles_.back().get());
  Propagator* on = p.get();
  prefetch_propagators_.push_back(std::move(p));
  return std::async(std::launch::async,
                    [this, e, on] {
                      return ComputeBranch(e.orbit, e.along, ContinuationDirection::kBoth, *on, {});
                    })
      .share();
}

// The first edge round's chains (EdgeBranches), followed ahead while the curves are traced and
// switched: the round takes each edge's ends in the curves' order, and whether an end needs its
// branch depends only on the branches before it along that edge. So once the curves before an
// end are applied and its edge's branches before it have run, its decision is the round's: its
// branch is computed then, on a thread of its own, and the round takes it from prefetched_ (the
// same bytes: a branch reads only its end). In the reference box both branches of the round
// (~0.4 s each, one after the other, the other cores idle) start from curves of the located
// starts, and run while the curves are switched.
void TraceDriver::AdvanceEdgeChains() {
  for (; prefetch_seen_ < result_.curves.size(); ++prefetch_seen_) {
    for (EdgeEnd& e : EdgeEndsOf(prefetch_seen_)) chains_[e.at.edge].ends.push_back(std::move(e));
  }
  for (EdgeChain& chain : chains_) {
    if (chain.running) {
      const std::shared_future<BranchRun>& run = prefetched_.at(KeyOf(*chain.running)).run;
      if (run.wait_for(std::chrono::seconds(0)) != std::future_status::ready) continue;
      if (run.get().r.summary.termination == Termination::kCancelled) {
        prefetching_ = false;  // stopped: the round computes what it needs
        return;
      }
      RecordEdgePoints(*chain.running, run.get(), &chain.located);
      chain.running.reset();
    }
    while (!chain.ends.empty() && !chain.running) {
      EdgeEnd e = std::move(chain.ends.front());
      chain.ends.pop_front();
      if (Covered(chain.located, e.at, e.along)) continue;
      std::shared_future<BranchRun> run = ComputeAhead(e);
      if (!run.valid()) return;
      prefetched_.emplace(KeyOf(e), Ahead{e, std::move(run)});
      chain.running = std::move(e);
    }
  }
}

// One edge round's branches, through the ends in order, each unless a branch along the same edge
// located its point already (on_edge_branches: the rounds' edge points, this one's added). Whether
// an end needs its branch depends on the branches before it along the same edge only (each
// branch adds points of its own edge): each edge's branches are a chain, one after the other, and
// the chains of the four edges run as tasks side by side. The branches are applied in the order
// of the ends, each as soon as those before it are: the same as one after the other, whatever
// the threads and the schedule, and no branch computed in vain.
bool TraceDriver::EdgeBranches(const std::vector<EdgeEnd>& ends,
                               std::vector<EdgePoint>* on_edge_branches) {
  internal::TaskStage<BranchRun> stage(*workers_);
  internal::OrderedTasks<BranchRun>& tasks = stage.tasks();
  std::vector<std::optional<BranchRun>> runs(ends.size());
  std::vector<bool> skipped(ends.size(), false);
  size_t next[4] = {0, 0, 0, 0};  // per edge: its first end not decided on
  bool running[4] = {};           // per edge: its chain's branch is queued
  std::deque<size_t> queued;      // the ends whose branches are queued, in queue order
  size_t applied = 0;             // the ends before it are applied
  for (;;) {
    // Each edge without a branch queued: its next end that needs one, queued.
    for (int edge = 0; edge < 4; ++edge) {
      for (size_t& j = next[edge]; !running[edge] && j < ends.size(); ++j) {
        const EdgeEnd& e = ends[j];
        if (e.at.edge != edge) continue;
        if (Covered(*on_edge_branches, e.at, e.along)) {
          skipped[j] = true;
          continue;
        }
        running[edge] = true;
        queued.push_back(j);
        // Computed ahead (AdvanceEdgeChains) through this very end: taken, and no longer held.
        if (const auto ahead = prefetched_.find(KeyOf(e));
            ahead != prefetched_.end() && SameEnd(ahead->second.end, e)) {
          tasks.Push([run = std::move(ahead->second.run)](int) { return run.get(); });
          prefetched_.erase(ahead);
          continue;
        }
        tasks.Push([this, &e](int worker) {
          return ComputeBranch(e.orbit, e.along, ContinuationDirection::kBoth, workers_->at(worker),
                               ReportHere(0.99, 0.99));
        });
      }
    }
    // The ends decided on, in order: skipped, or their branch applied.
    for (; applied < ends.size(); ++applied) {
      const EdgeEnd& e = ends[applied];
      if (skipped[applied]) continue;
      if (!runs[applied]) break;
      ++edge_runs_;
      if (!ApplyBranch(*runs[applied], e.along, e.from_end)) return false;
      runs[applied].reset();
    }
    if (queued.empty()) return true;
    if (!Report(0.99)) return false;
    const size_t j = queued.front();
    queued.pop_front();
    BranchRun run = *tasks.TakeFront(wait_);
    if (Stopped()) return false;
    // Its edge points now, for the decisions on the ends after it along the same edge.
    const EdgeEnd& e = ends[j];
    RecordEdgePoints(e, run, on_edge_branches);
    running[e.at.edge] = false;
    runs[j] = std::move(run);
  }
}

bool TraceDriver::LastResortStepOffs() {
  // The step-offs at codimension-2 roots that only a last-resort length starts (SwitchAtCodim2),
  // and the curves leaving the codimension-2 points of the curves they add.
  while (!tally_.deferred.empty()) {
    const size_t before = result_.curves.size();
    if (!SwitchAtCodim2(
            model_, propagator_, *workers_, wait_, options_, [this](double f) { return Report(f); },
            before, &tally_, &result_, true) ||
        !SwitchFrom(before) || Stopped()) {
      return false;
    }
  }
  return true;
}

void TraceDriver::Notes() {
  if (edge_runs_ > 0) {
    sum_.notes.push_back(std::to_string(edge_runs_) + " branches run along the box's edges from " +
                         "curve ends on them");
  }
  TallyNotes(tally_, &sum_);
  if (const int merged = internal::EndsAtFlipGrazings(model_, options_, &result_); merged > 0) {
    sum_.notes.push_back(std::to_string(merged) +
                         " curve ends where a period-2n orbit becomes the period-n orbit traversed "
                         "twice, reported as that period-n FLIP_GRAZING");
  }
  // Points the required 1e-8 does not cover: their `bracket` says how far they are known.
  // Per period: codimension-2 points with bracket > 1e-8, and curve ends not claimed as points.
  std::map<int, int> wide, unverified;
  for (const TracedCurve& c : result_.curves) {
    for (const Codim2Point& q : c.curve.codim2) {
      if (q.bracket > 1e-8) ++wide[q.point.orbit.signature.periods];
    }
    for (const Codim2Point& e : c.curve.unverified_ends) {
      ++unverified[e.point.orbit.signature.periods];
    }
  }
  for (const auto& [period, count] : wide) {
    sum_.notes.push_back(std::to_string(count) + " " + PeriodPrefix(period) +
                         "codimension-2 points located only to a bracket above 1e-8 (see each "
                         "one's bracket: the corrector failed next to the curve's end)");
  }
  for (const auto& [period, count] : unverified) {
    sum_.notes.push_back(std::to_string(count) + " " + PeriodPrefix(period) +
                         "curve ends not located: the steps failed or collapsed next to them and "
                         "only a prediction beyond, not a solved orbit, is inadmissible (no point "
                         "claimed; named in the curves' messages)");
  }
  Report(1.0);
}

}  // namespace

std::string TraceSummary::BriefReport() const {
  return RunSummary::BriefReport(CountOf(curves, "curve") + ", " +
                                 CountOf(branch_points, "branch point") + ", " +
                                 CountOf(static_cast<int64_t>(notes.size()), "note"));
}

TraceResult TraceCurves(const HybridModel& model, Propagator& propagator,
                        const PeriodicOrbit& start, const TraceOptions& options,
                        const TraceProgress& progress, const TracedCurveCallback& on_curve) {
  TraceResult result;
  CurveStream stream(on_curve, options, result);
  TraceDriver(model, propagator, start, options, progress, &stream, &result).Run();
  // However the trace ended, the curves not handed over yet are final now.
  if (!stream.Flush(true) && result.summary.completed()) result.summary.Cancel(kCancelledMessage);
  result.summary.curves = static_cast<int64_t>(result.curves.size());
  // Each note once, in the order first written: a located point met from both directions of a
  // branch, or a codimension-2 point met from every curve through it, gives the same text each
  // time (the --period2 box had 106 notes on curves not started for 80 distinct ones).
  std::vector<std::string>& notes = result.summary.notes;
  std::unordered_set<std::string> seen;
  notes.erase(std::remove_if(notes.begin(), notes.end(),
                             [&](const std::string& n) { return !seen.insert(n).second; }),
              notes.end());
  return result;
}

}  // namespace drillbif
