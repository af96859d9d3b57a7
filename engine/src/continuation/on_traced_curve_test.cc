// internal::OnTracedCurve (trace_internal.h): a point between a curve's end vertex and the
// codimension-2 end located beyond it lies on the curve, though off its polyline, and the end is
// joined to the end vertex whose durations are its own (tangent segments merged), not to the one
// nearer in the box. A synthetic curve in a unit box: the straight polyline F = (0, 0),
// M = (0.005, 0), L = (0.01, 0) (no turn, so no chord allowance on it), and one end E.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <utility>
#include <vector>

#include "trace_internal.h"

namespace drillbif::internal {
namespace {

constexpr double kTol = 1e-5;  // TraceOptions::duplicate_distance's default

CurvePoint Vertex(double u, double v, std::vector<double> durations) {
  CurvePoint p;
  p.value1 = u, p.value2 = v;
  p.orbit.signature.segments = {{0, 0, false}, {1, -1, false}};
  p.orbit.durations = std::move(durations);
  return p;
}

// The curve with its end at (u, 0), in tangent form (segment 0's mode touches its guard and goes
// on): merged, its durations are `merged`. `root`: a root between vertices instead (its
// violation admissible), no end.
TracedCurve Line(double u, std::pair<double, double> merged, bool root = false) {
  TracedCurve t;
  t.curve.kind = CurveKind::kFold;
  t.curve.points = {Vertex(0.0, 0.0, {1.0, 2.0}), Vertex(0.005, 0.0, {2.0, 1.0}),
                    Vertex(0.01, 0.0, {3.0, 0.5})};
  Codim2Point end;
  end.kind = Codim2Kind::kFoldGrazing;
  end.point.value1 = u;
  end.point.orbit.signature.segments = {{0, 0, true}, {0, 0, false}, {1, -1, false}};
  end.point.orbit.durations = {0.4 * merged.first, 0.6 * merged.first, merged.second};
  end.violation.admissible = root;
  t.curve.codim2 = {end};
  t.outline = OutlineOf(t.curve);
  return t;
}

TEST(OnTracedCurve, APointBetweenTheLastVertexAndTheEndBeyondItIsOnTheCurve) {
  const TracedCurve t = Line(0.012, {3.1, 0.45});                // L's durations to a step's change
  EXPECT_FALSE(OnCurve(t.outline, 0.011, 0.0, 1.0, 1.0, kTol));  // 1e-3 beyond L
  EXPECT_TRUE(OnTracedCurve(t, 0.011, 0.0, 1.0, 1.0, kTol));
  EXPECT_TRUE(OnTracedCurve(t, 0.012, 0.0, 1.0, 1.0, kTol));  // the end itself
  // The stretch goes on straight (no turn, no allowance): 1e-4 off it is off the curve.
  EXPECT_FALSE(OnTracedCurve(t, 0.011, 1e-4, 1.0, 1.0, kTol));
  EXPECT_FALSE(OnTracedCurve(t, 0.013, 0.0, 1.0, 1.0, kTol));  // beyond the end
}

// A stretch next to a turning vertex is allowed a bow of |stretch| * min(turn, 0.5) / 4 off its
// chord (OnCurve): (0, 0) -> (1, 0) -> (1 + cos t, sin t) turns by t at (1, 0). Points below the
// first stretch's middle, whose distance to the second stretch is ~0.5 or more, lie on the curve
// just inside the bow and off it just outside; a turn above 0.5 rad gets the cap's bow, 1/8.
TEST(OnCurve, AStretchNextToATurnIsAllowedItsBowAndNoMore) {
  for (const double turn : {0.3, 1.0}) {
    CurveResult c;
    c.points = {Vertex(0.0, 0.0, {1.0, 2.0}), Vertex(1.0, 0.0, {1.0, 2.0}),
                Vertex(1.0 + std::cos(turn), std::sin(turn), {1.0, 2.0})};
    const CurveOutline line = OutlineOf(c);
    const double bow = std::min(turn, 0.5) / 4.0;
    EXPECT_TRUE(OnCurve(line, 0.5, -(bow - 1e-3), 1.0, 1.0, kTol)) << turn;
    EXPECT_FALSE(OnCurve(line, 0.5, -(bow + kTol + 1e-3), 1.0, 1.0, kTol)) << turn;
  }
}

TEST(OnTracedCurve, TheEndIsJoinedToTheVertexWithItsDurationsNotTheNearerOne) {
  // The end at (-0.002, 0), 2e-3 from F and 1.2e-2 from L. Joined to L (its durations), the
  // stretch L-E turns back along the polyline, its chord allowance (turn capped at 0.5 rad)
  // 1.2e-2 * 0.5 / 4 = 1.5e-3: (0.005, 1e-3) is on it. Joined to F, the stretch F-E is 5.1e-3
  // from that point.
  EXPECT_TRUE(OnTracedCurve(Line(-0.002, {3.1, 0.45}), 0.005, 1e-3, 1.0, 1.0, kTol));
  EXPECT_FALSE(OnTracedCurve(Line(-0.002, {1.1, 1.95}), 0.005, 1e-3, 1.0, 1.0, kTol));
}

TEST(OnTracedCurve, ARootBetweenVerticesIsNoEnd) {
  EXPECT_FALSE(OnTracedCurve(Line(0.012, {3.1, 0.45}, true), 0.011, 0.0, 1.0, 1.0, kTol));
}

}  // namespace
}  // namespace drillbif::internal
