// TraceCurves: cancellation within the bound (support/cancel_probe.h) in its branches and curves
// and while it switches at codimension-2 points, on one thread and on several (the branches
// running as tasks on the workers too); the curves handed to on_curve (each once it is final, as
// the result holds them at the end; the result keeping only the ends and outline of a handed-over
// curve's vertices without vertex_states); and the same result whatever the number of threads the
// branch and curve tasks run on.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <string>
#include <vector>

#include "drillbif/continuation/trace.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_box.h"
#include "problems/reference_orbit.h"
#include "support/cancel_probe.h"
#include "support/same_curves.h"
#include "support/small_trace_box.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;
using std::chrono::milliseconds;
using testing::CancelProbe;
using testing::ExpectSameCurve;
using testing::SameBits;

constexpr milliseconds kDelay(200);  // as in simulation_cancel_test.cc

class TraceStream : public testing::SmallTraceBox {};

// The whole box of problems/reference_box.h (seconds of branches, hundreds of curves), stopped
// 200 ms in.
TEST_F(TraceStream, StopsPromptly) {
  CancelProbe probe(kDelay);
  const TraceResult r =
      TraceCurves(model_, prop_, start_, testing::ReferenceBox(), probe.Callback());
  probe.Returned();
  EXPECT_EQ(r.summary.termination, Termination::kCancelled) << r.summary.BriefReport();
  EXPECT_EQ(r.summary.status.code(), StatusCode::kCancelled);
  EXPECT_EQ(r.summary.curves, static_cast<int64_t>(r.curves.size()));
  for (const TracedCurve& c : r.curves) {
    for (const CurvePoint& p : c.curve.points) ASSERT_TRUE(p.stability.monodromy.allFinite());
  }
  probe.ExpectPrompt("trace: branches and curves");
}

// Stopped at the first report of the switching and edge rounds (fraction 0.99 and beyond, after
// every curve of the branches' points is traced).
TEST_F(TraceStream, StopsPromptlyWhileSwitching) {
  CancelProbe probe([](double fraction) { return fraction >= 0.99; });
  const TraceResult r = TraceCurves(model_, prop_, start_, SmallBox(), probe.Callback());
  probe.Returned();
  EXPECT_TRUE(r.summary.cancelled());
  EXPECT_FALSE(r.curves.empty());
  probe.ExpectPrompt("trace: switching at codimension-2 points");
}

// Period 1: every curve is handed over once, in index order, equal to the result's at the end;
// and during the trace (a consumer that stops at the second curve leaves the trace with fewer
// curves than a full one).
TEST_F(TraceStream, CurvesAreHandedOverInOrderAsTraced) {
  std::vector<TracedCurve> seen;
  const TraceResult full =
      TraceCurves(model_, prop_, start_, SmallBox(), {}, [&](int index, const TracedCurve& c) {
        EXPECT_EQ(index, static_cast<int>(seen.size()));
        seen.push_back(c);
        return true;
      });
  ASSERT_FALSE(full.summary.cancelled());
  ASSERT_GE(full.curves.size(), 3u);
  ASSERT_EQ(seen.size(), full.curves.size());
  for (size_t k = 0; k < seen.size(); ++k) {
    ExpectSameCurve(seen[k], full.curves[k], static_cast<int>(k));
  }

  int calls = 0;
  const TraceResult stopped = TraceCurves(model_, prop_, start_, SmallBox(), {},
                                          [&](int, const TracedCurve&) { return ++calls < 2; });
  EXPECT_TRUE(stopped.summary.cancelled());
  EXPECT_EQ(calls, 2);
  EXPECT_LT(stopped.curves.size(), full.curves.size());
}

// The indices in the order handed over: each curve once, in index order but for the curves held
// back to the end (their end may merge at a flip-grazing: curves of even period), themselves in
// index order.
void ExpectHeldBackLast(const std::vector<int>& order, const TraceResult& r) {
  std::vector<int> sorted = order;
  std::sort(sorted.begin(), sorted.end());
  ASSERT_EQ(sorted.size(), r.curves.size());
  for (size_t k = 0; k < sorted.size(); ++k) ASSERT_EQ(sorted[k], static_cast<int>(k));
  size_t held = 1;  // where the held-back curves start: after the last descent
  for (size_t k = 1; k < order.size(); ++k) {
    if (order[k] < order[k - 1]) held = k;
  }
  if (held == 1 && std::is_sorted(order.begin(), order.end())) return;
  EXPECT_TRUE(std::is_sorted(order.begin(), order.begin() + held));
  EXPECT_TRUE(std::is_sorted(order.begin() + held, order.end()));
  for (size_t k = held; k < order.size(); ++k) {
    const TracedCurve& c = r.curves[order[k]];
    ASSERT_FALSE(c.curve.points.empty());
    EXPECT_EQ(c.curve.points.front().orbit.signature.periods % 2, 0) << order[k];
  }
}

// Period 2 (a box where period-2 curves end next to period-1 flip-grazings, which the trace's
// last pass reports as those points): each curve handed over once, equal to what the result holds
// at the end, so after that pass; the curves held back for it handed over at the end, those after
// them without waiting. With vertex_states false the same curves are handed over, and the result
// keeps of a handed-over curve its ends and its outline (every vertex's parameters).
TEST_F(TraceStream, PeriodTwoCurvesAreHandedOverFinal) {
  TraceOptions o = testing::ReferenceBox();
  o.max1 = 0.45;
  o.min2 = 0.25, o.max2 = 0.35;
  o.max_period = 2;
  std::vector<TracedCurve> seen;
  std::vector<int> order;
  auto keep = [&](int index, const TracedCurve& c) {
    if (seen.size() <= static_cast<size_t>(index)) seen.resize(index + 1);
    seen[index] = c;
    order.push_back(index);
    return true;
  };
  const TraceResult r = TraceCurves(model_, prop_, start_, o, {}, keep);
  ASSERT_FALSE(r.summary.cancelled());
  ASSERT_EQ(seen.size(), r.curves.size());
  for (size_t k = 0; k < seen.size(); ++k) {
    ExpectSameCurve(seen[k], r.curves[k], static_cast<int>(k));
  }
  ExpectHeldBackLast(order, r);
  // The last pass did change curves here (else the check above would not see a curve handed
  // over too early), and a curve after a held one was handed over before it.
  int merged = 0;
  for (const TracedCurve& c : r.curves) {
    for (const Codim2Point& q : c.curve.codim2) {
      if (q.detail.find("orbit traversed twice: the FLIP_GRAZING") != std::string::npos) ++merged;
    }
  }
  EXPECT_GT(merged, 0);
  EXPECT_FALSE(std::is_sorted(order.begin(), order.end()));

  const std::vector<TracedCurve> whole = std::move(seen);
  seen.clear(), order.clear();
  o.vertex_states = false;
  const TraceResult released = TraceCurves(model_, prop_, start_, o, {}, keep);
  ASSERT_EQ(seen.size(), whole.size());
  ASSERT_EQ(released.curves.size(), whole.size());
  EXPECT_EQ(released.summary.notes, r.summary.notes);
  int thinned = 0;
  for (size_t k = 0; k < whole.size(); ++k) {
    ExpectSameCurve(seen[k], whole[k], static_cast<int>(k));
    const std::vector<CurvePoint>& all = whole[k].curve.points;
    const TracedCurve& kept = released.curves[k];
    const CurveOutline& line = kept.outline;
    ASSERT_EQ(line.size(), all.size()) << k;
    for (size_t v = 0; v < all.size(); ++v) {
      EXPECT_TRUE(SameBits(line.values1[v], all[v].value1) &&
                  SameBits(line.values2[v], all[v].value2))
          << k << " " << v;
      EXPECT_EQ(line.SignatureAt(v), all[v].orbit.signature) << k << " " << v;
    }
    if (kept.curve.points.size() == all.size()) continue;  // kept whole (a PD curve seeding)
    ++thinned;
    ASSERT_EQ(kept.curve.points.size(), 2u) << k;
    EXPECT_TRUE(SameBits(kept.curve.points.back().value1, all.back().value1)) << k;
    EXPECT_EQ(kept.curve.points.back().orbit.starts.size(), all.back().orbit.starts.size()) << k;
  }
  EXPECT_GT(thinned, 0);
}

// The curve tasks on 2 and 3 threads (on this 2-core machine, 3 also exercises more workers than
// cores): the same curves, to the bit, in the same order, the same notes and the same streamed
// order as on one thread. The small box has branch points, switching at a flip-grazing and edge
// branches; period 2 adds the period-2 branches and the last pass over their ends. On 2 threads
// without vertex_states (the trace job's setting): the curves as handed over, while the switching
// tasks read the outlines of curves whose vertices are released meanwhile.
TEST_F(TraceStream, TheSameCurvesWhateverTheThreads) {
  for (const int max_period : {1, 2}) {
    TraceOptions o = SmallBox();
    o.max_period = max_period;
    if (max_period == 2) o.max1 = 0.45;
    std::vector<int> streamed_one;
    const TraceResult one =
        TraceCurves(model_, prop_, start_, o, {}, [&](int index, const TracedCurve&) {
          streamed_one.push_back(index);
          return true;
        });
    ASSERT_TRUE(one.summary.status.ok());
    ASSERT_FALSE(one.summary.cancelled());
    ASSERT_GE(one.curves.size(), 3u);
    // Branches along the box's edges ran: with more threads, computed ahead of their round.
    EXPECT_TRUE(std::any_of(one.summary.notes.begin(), one.summary.notes.end(),
                            [](const std::string& n) {
                              return n.find("branches run along the box's edges") !=
                                     std::string::npos;
                            }))
        << "max_period " << max_period;
    for (const int threads : {2, 3}) {
      o.threads = threads;
      o.vertex_states = threads != 2;
      std::vector<int> streamed;
      std::vector<TracedCurve> seen(one.curves.size());
      const TraceResult many =
          TraceCurves(model_, prop_, start_, o, {}, [&](int index, const TracedCurve& c) {
            streamed.push_back(index);
            if (index < static_cast<int>(seen.size())) seen[index] = c;
            return true;
          });
      SCOPED_TRACE("max_period " + std::to_string(max_period) + ", " + std::to_string(threads) +
                   " threads");
      ASSERT_FALSE(many.summary.cancelled());
      ASSERT_EQ(many.curves.size(), one.curves.size());
      for (size_t k = 0; k < one.curves.size(); ++k) {
        ExpectSameCurve(seen[k], one.curves[k], static_cast<int>(k));
        if (o.vertex_states) ExpectSameCurve(many.curves[k], one.curves[k], static_cast<int>(k));
      }
      EXPECT_EQ(many.summary.notes, one.summary.notes);
      EXPECT_EQ(many.summary.branch_points, one.summary.branch_points);
      EXPECT_EQ(streamed, streamed_one);
      ExpectHeldBackLast(streamed, many);
    }
  }
}

// On two threads, a stop while curves are traced (at the first report past 0.3: the branches take
// the first tenth) ends the curve tasks running on the workers too.
TEST_F(TraceStream, StopsPromptlyOnTwoThreads) {
  TraceOptions o = testing::ReferenceBox();
  o.threads = 2;
  CancelProbe probe([](double fraction) { return fraction >= 0.3; });
  const TraceResult r = TraceCurves(model_, prop_, start_, o, probe.Callback());
  probe.Returned();
  EXPECT_TRUE(r.summary.cancelled());
  for (const TracedCurve& c : r.curves) {
    for (const CurvePoint& p : c.curve.points) ASSERT_TRUE(p.stability.monodromy.allFinite());
  }
  probe.ExpectPrompt("trace on two threads: curves");
}

// On two threads, a stop at the trace's first report (its first 5 ms: ProgressThrottle's
// interval), while the start's two branches run as tasks on the workers: the trace ends
// cancelled, promptly, with no branch applied and no curve.
TEST_F(TraceStream, StopsPromptlyWhileBranchingOnTwoThreads) {
  TraceOptions o = testing::ReferenceBox();
  o.threads = 2;
  CancelProbe probe([](double) { return true; });
  const TraceResult r = TraceCurves(model_, prop_, start_, o, probe.Callback());
  probe.Returned();
  EXPECT_TRUE(r.summary.cancelled());
  EXPECT_EQ(r.summary.branch_points, 0);
  EXPECT_TRUE(r.curves.empty());
  probe.ExpectPrompt("trace on two threads: branches");
}

// Seeds on 2 and 3 threads: the seeds' attractors and their branches are tasks too; the same
// notes (the seed without a periodic attractor's among them, in the same place), branch point
// counts and curves as on one thread. The seeds add branches: more branch points than without.
TEST_F(TraceStream, SeedsGiveTheSameResultWhateverTheThreads) {
  TraceOptions o = SmallBox();
  o.switch_at_codim2 = false;
  const TraceResult unseeded = TraceCurves(model_, prop_, start_, o);
  // 0.055: no periodic attractor (trace_test.cc's seeds); 0.07 and 0.15 inside the box.
  o.seeds1 = {0.07, 0.055, 0.15};
  const TraceResult one = TraceCurves(model_, prop_, start_, o);
  ASSERT_TRUE(one.summary.status.ok()) << one.summary.status.ToString();
  ASSERT_FALSE(one.summary.cancelled());
  EXPECT_GT(one.summary.branch_points, unseeded.summary.branch_points);
  EXPECT_TRUE(std::any_of(one.summary.notes.begin(), one.summary.notes.end(),
                          [](const std::string& n) { return n.find("seed omega = 0.055") == 0; }));
  for (const int threads : {2, 3}) {
    o.threads = threads;
    const TraceResult many = TraceCurves(model_, prop_, start_, o);
    SCOPED_TRACE(std::to_string(threads) + " threads");
    ASSERT_FALSE(many.summary.cancelled());
    EXPECT_EQ(many.summary.notes, one.summary.notes);
    EXPECT_EQ(many.summary.branch_points, one.summary.branch_points);
    ASSERT_EQ(many.curves.size(), one.curves.size());
    for (size_t k = 0; k < one.curves.size(); ++k) {
      ExpectSameCurve(many.curves[k], one.curves[k], static_cast<int>(k));
    }
  }
}

// Stopped on two threads at the first report of the switching rounds.
TEST_F(TraceStream, StopsPromptlyWhileSwitchingOnTwoThreads) {
  TraceOptions o = SmallBox();
  o.threads = 2;
  CancelProbe probe([](double fraction) { return fraction >= 0.99; });
  const TraceResult r = TraceCurves(model_, prop_, start_, o, probe.Callback());
  probe.Returned();
  EXPECT_TRUE(r.summary.cancelled());
  EXPECT_FALSE(r.curves.empty());
  probe.ExpectPrompt("trace on two threads: switching at codimension-2 points");
}

// threads out of range are refused naming the field.
TEST_F(TraceStream, ThreadsOutOfRangeAreRefused) {
  for (const int threads : {-1, kMaxTraceThreads + 1}) {
    TraceOptions o = SmallBox();
    o.threads = threads;
    const TraceResult r = TraceCurves(model_, prop_, start_, o);
    EXPECT_EQ(r.summary.status.code(), StatusCode::kInvalidArgument) << threads;
    EXPECT_NE(r.summary.status.message().find("threads"), std::string::npos);
  }
}

// Without vertex states (TraceOptions::vertex_states false, as the trace job asks): the same
// curves, codimension-2 points and notes; the interior vertices hold no section states and no
// monodromy, but their parameters, signature, durations and measures, except on the period-1 PD
// curves (switching starts period-2 grazing curves from their vertices); every curve's first and
// last vertex is whole.
TEST_F(TraceStream, CurvesWithoutVertexStatesAreTheSameCurves) {
  TraceOptions o = SmallBox();
  o.max1 = 0.45;
  o.max_period = 2;
  const TraceResult whole = TraceCurves(model_, prop_, start_, o);
  o.vertex_states = false;
  const TraceResult lean = TraceCurves(model_, prop_, start_, o);
  ASSERT_FALSE(whole.summary.cancelled());
  ASSERT_EQ(lean.curves.size(), whole.curves.size());
  EXPECT_EQ(lean.summary.notes, whole.summary.notes);
  int lean_curves = 0;
  for (size_t k = 0; k < whole.curves.size(); ++k) {
    ExpectSameCurve(lean.curves[k], whole.curves[k], static_cast<int>(k));
    const std::vector<CurvePoint>& points = lean.curves[k].curve.points;
    if (points.empty()) continue;
    EXPECT_FALSE(points.front().orbit.starts.empty()) << k;
    EXPECT_FALSE(points.back().orbit.starts.empty()) << k;
    const bool kept = lean.curves[k].curve.kind == CurveKind::kPeriodDoubling &&
                      points.front().orbit.signature.periods == 1;
    for (size_t i = 1; i + 1 < points.size(); ++i) {
      const CurvePoint& full = whole.curves[k].curve.points[i];
      EXPECT_EQ(points[i].orbit.starts.empty(), !kept) << k << " " << i;
      EXPECT_EQ(points[i].stability.monodromy.size() == 0, !kept) << k << " " << i;
      EXPECT_EQ(points[i].orbit.signature, full.orbit.signature) << k << " " << i;
      EXPECT_EQ(points[i].orbit.durations, full.orbit.durations) << k << " " << i;
      EXPECT_EQ(points[i].measures, full.measures) << k << " " << i;
      EXPECT_EQ(points[i].stability.stable, full.stability.stable) << k << " " << i;
    }
    if (!kept && points.size() > 2) ++lean_curves;
  }
  EXPECT_GT(lean_curves, 0);
}

}  // namespace
}  // namespace drillbif
