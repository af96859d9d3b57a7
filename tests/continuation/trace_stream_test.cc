// TraceCurves: cancellation within the bound (support/cancel_probe.h) in its branches and curves
// and while it switches at codimension-2 points, on one thread and on several; the curves handed
// to on_curve (in order, as the result holds them at the end, each once it is final); and the same
// result whatever the number of threads the curve tasks run on.
#include <gtest/gtest.h>

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

namespace drillbif {
namespace {

using DO = DriftingOscillator;
using std::chrono::milliseconds;
using testing::CancelProbe;

constexpr milliseconds kDelay(200);  // as in simulation_cancel_test.cc

class TraceStream : public ::testing::Test {
 protected:
  void SetUp() override {
    const StatusOr<PeriodicOrbit> orbit =
        testing::SolvedOrbitFromRest(model_, prop_, testing::ReferenceParams());
    ASSERT_TRUE(orbit.ok()) << orbit.status().ToString();
    start_ = *orbit;
  }
  // The small box of the trace runner's tests (omega in [0.05, 0.2], a in [0.27, 0.32]: ~1 s,
  // with a flip-grazing to switch at).
  static TraceOptions SmallBox() {
    TraceOptions o = testing::ReferenceBox();
    o.max1 = 0.2;
    o.min2 = 0.27, o.max2 = 0.32;
    return o;
  }
  DO model_;
  ExactPropagator prop_{model_};
  PeriodicOrbit start_;
};

bool SameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// The same curve: kind, start, message, and every point's and codimension-2 point's parameters
// to the bit.
void ExpectSameCurve(const TracedCurve& a, const TracedCurve& b, int index) {
  EXPECT_EQ(a.curve.kind, b.curve.kind) << index;
  EXPECT_EQ(a.start.kind, b.start.kind) << index;
  EXPECT_EQ(a.from_curve, b.from_curve) << index;
  EXPECT_EQ(a.curve.summary.message, b.curve.summary.message) << index;
  ASSERT_EQ(a.curve.points.size(), b.curve.points.size()) << index;
  for (size_t k = 0; k < a.curve.points.size(); ++k) {
    EXPECT_TRUE(SameBits(a.curve.points[k].value1, b.curve.points[k].value1) &&
                SameBits(a.curve.points[k].value2, b.curve.points[k].value2))
        << index << " " << k;
  }
  ASSERT_EQ(a.curve.codim2.size(), b.curve.codim2.size()) << index;
  for (size_t k = 0; k < a.curve.codim2.size(); ++k) {
    EXPECT_EQ(a.curve.codim2[k].kind, b.curve.codim2[k].kind) << index << " " << k;
    EXPECT_EQ(a.curve.codim2[k].detail, b.curve.codim2[k].detail) << index << " " << k;
    EXPECT_TRUE(SameBits(a.curve.codim2[k].point.value1, b.curve.codim2[k].point.value1))
        << index << " " << k;
  }
}

// The whole box of problems/reference_box.h (seconds of branches, hundreds of curves), stopped
// 200 ms in.
TEST_F(TraceStream, StopsPromptly) {
  CancelProbe probe(kDelay);
  const TraceResult r =
      TraceCurves(model_, prop_, start_, testing::ReferenceBox(), probe.Callback());
  probe.Returned();
  EXPECT_TRUE(r.summary.status.ok()) << r.summary.status.ToString();
  EXPECT_TRUE(r.summary.cancelled);
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
  EXPECT_TRUE(r.summary.cancelled);
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
  ASSERT_FALSE(full.summary.cancelled);
  ASSERT_GE(full.curves.size(), 3u);
  ASSERT_EQ(seen.size(), full.curves.size());
  for (size_t k = 0; k < seen.size(); ++k) {
    ExpectSameCurve(seen[k], full.curves[k], static_cast<int>(k));
  }

  int calls = 0;
  const TraceResult stopped = TraceCurves(model_, prop_, start_, SmallBox(), {},
                                          [&](int, const TracedCurve&) { return ++calls < 2; });
  EXPECT_TRUE(stopped.summary.cancelled);
  EXPECT_EQ(calls, 2);
  EXPECT_LT(stopped.curves.size(), full.curves.size());
}

// Period 2 (a box where period-2 curves end next to period-1 flip-grazings, which the trace's
// last pass reports as those points): curves handed over in index order, each equal to what the
// result holds at the end, so after that pass.
TEST_F(TraceStream, PeriodTwoCurvesAreHandedOverFinal) {
  TraceOptions o = testing::ReferenceBox();
  o.max1 = 0.45;
  o.min2 = 0.27, o.max2 = 0.32;
  o.max_period = 2;
  std::vector<TracedCurve> seen;
  const TraceResult r =
      TraceCurves(model_, prop_, start_, o, {}, [&](int index, const TracedCurve& c) {
        EXPECT_EQ(index, static_cast<int>(seen.size()));
        seen.push_back(c);
        return true;
      });
  ASSERT_FALSE(r.summary.cancelled);
  ASSERT_EQ(seen.size(), r.curves.size());
  for (size_t k = 0; k < seen.size(); ++k)
    ExpectSameCurve(seen[k], r.curves[k], static_cast<int>(k));
  // The last pass did change curves here (else the check above would not see a curve handed
  // over too early).
  int merged = 0;
  for (const TracedCurve& c : r.curves) {
    for (const Codim2Point& q : c.curve.codim2) {
      if (q.detail.find("orbit traversed twice: the FLIP_GRAZING") != std::string::npos) ++merged;
    }
  }
  EXPECT_GT(merged, 0);
}

// The curve tasks on 2 and 3 threads (on this 2-core machine, 3 also exercises more workers than
// cores): the same curves, to the bit, in the same order, the same notes and the same streamed
// order as on one thread. The small box has branch points, switching at a flip-grazing and edge
// branches; period 2 adds the period-2 branches and the last pass over their ends.
TEST_F(TraceStream, TheSameCurvesWhateverTheThreads) {
  for (const int max_period : {1, 2}) {
    TraceOptions o = SmallBox();
    o.max_period = max_period;
    if (max_period == 2) o.max1 = 0.45;
    const TraceResult one = TraceCurves(model_, prop_, start_, o);
    ASSERT_TRUE(one.summary.status.ok());
    ASSERT_FALSE(one.summary.cancelled);
    ASSERT_GE(one.curves.size(), 3u);
    for (const int threads : {2, 3}) {
      o.threads = threads;
      std::vector<int> streamed;
      const TraceResult many =
          TraceCurves(model_, prop_, start_, o, {}, [&](int index, const TracedCurve&) {
            streamed.push_back(index);
            return true;
          });
      SCOPED_TRACE("max_period " + std::to_string(max_period) + ", " + std::to_string(threads) +
                   " threads");
      ASSERT_FALSE(many.summary.cancelled);
      ASSERT_EQ(many.curves.size(), one.curves.size());
      for (size_t k = 0; k < one.curves.size(); ++k) {
        ExpectSameCurve(many.curves[k], one.curves[k], static_cast<int>(k));
      }
      EXPECT_EQ(many.summary.notes, one.summary.notes);
      EXPECT_EQ(many.summary.branch_points, one.summary.branch_points);
      ASSERT_EQ(streamed.size(), one.curves.size());
      for (size_t k = 0; k < streamed.size(); ++k) EXPECT_EQ(streamed[k], static_cast<int>(k));
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
  EXPECT_TRUE(r.summary.cancelled);
  for (const TracedCurve& c : r.curves) {
    for (const CurvePoint& p : c.curve.points) ASSERT_TRUE(p.stability.monodromy.allFinite());
  }
  probe.ExpectPrompt("trace on two threads: curves");
}

// Stopped on two threads at the first report of the switching rounds.
TEST_F(TraceStream, StopsPromptlyWhileSwitchingOnTwoThreads) {
  TraceOptions o = SmallBox();
  o.threads = 2;
  CancelProbe probe([](double fraction) { return fraction >= 0.99; });
  const TraceResult r = TraceCurves(model_, prop_, start_, o, probe.Callback());
  probe.Returned();
  EXPECT_TRUE(r.summary.cancelled);
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
  ASSERT_FALSE(whole.summary.cancelled);
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
