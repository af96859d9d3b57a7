// The trace job: request validation naming the field, and a small box whose one period-doubling
// curve ends at a flip-grazing inside it and leaves it after a Poincare-section crossing.
#include "jobs/trace_job.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

namespace drillbif::jobs {
namespace {

using ::testing::HasSubstr;

// omega in [0.05, 0.2], a in [0.27, 0.32] around the reference start (omega = 0.1, a = 0.3).
v1::TraceRequest SmallBox() {
  v1::TraceRequest r;
  r.add_trace_params(std::string("omega"));  // not ("omega"): GCC 12 -Wrestrict false positive
  r.add_trace_params(std::string("a"));
  r.add_min(0.05);
  r.add_min(0.27);
  r.add_max(0.2);
  r.add_max(0.32);
  return r;
}

void ExpectInvalid(const v1::TraceRequest& request, const std::string& names) {
  const StatusOr<v1::TraceResult> r = RunTrace(request);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr(names));
}

TEST(RunTrace, InvalidRequestsNameTheField) {
  v1::TraceRequest one = SmallBox();
  one.mutable_trace_params()->RemoveLast();
  ExpectInvalid(one, "trace_params");
  v1::TraceRequest unknown = SmallBox();
  unknown.set_trace_params(1, "zeta");
  ExpectInvalid(unknown, "zeta");
  v1::TraceRequest same = SmallBox();
  same.set_trace_params(1, "omega");
  ExpectInvalid(same, "trace_params");
  v1::TraceRequest bounds = SmallBox();
  bounds.mutable_max()->RemoveLast();
  ExpectInvalid(bounds, "min, max");
  v1::TraceRequest empty = SmallBox();
  empty.set_max(1, 0.27);
  ExpectInvalid(empty, "min, max of a");
  v1::TraceRequest outside = SmallBox();
  outside.set_min(1, 0.31);
  ExpectInvalid(outside, "params.a = 0.3");
  v1::TraceRequest invalid_value = SmallBox();
  invalid_value.set_min(0, -1.0);  // omega must be > 0
  ExpectInvalid(invalid_value, "min, max of omega");
  v1::TraceRequest transient = SmallBox();
  transient.set_transient_periods(-1);
  ExpectInvalid(transient, "transient_periods");
  v1::TraceRequest period = SmallBox();
  period.set_max_period(3);
  ExpectInvalid(period, "max_period");
  v1::TraceRequest contradiction = SmallBox();
  contradiction.set_period2(true);
  contradiction.set_max_period(1);
  ExpectInvalid(contradiction, "max_period: 1 contradicts period2");
  v1::TraceRequest steps = SmallBox();
  steps.set_curve_steps(static_cast<v1::CurveSteps>(7));
  ExpectInvalid(steps, "curve_steps");
  v1::TraceRequest seed = SmallBox();
  seed.add_seeds(0.3);  // omega outside [0.05, 0.2]
  ExpectInvalid(seed, "seeds");
  v1::TraceRequest nan_seed = SmallBox();
  nan_seed.add_seeds(std::nan(""));
  ExpectInvalid(nan_seed, "seeds");
  for (const int threads : {-1, kMaxTraceThreads + 1}) {
    v1::TraceRequest bad_threads = SmallBox();
    bad_threads.set_threads(threads);
    ExpectInvalid(bad_threads, "threads");
  }
}

// The threads asked for change nothing in the result but its wall time: one thread against the
// default (every core) and more threads than cores.
TEST(RunTrace, TheResultIsTheSameWhateverTheThreads) {
  v1::TraceRequest one = SmallBox();
  one.set_threads(1);
  StatusOr<v1::TraceResult> reference = RunTrace(one);
  ASSERT_TRUE(reference.ok()) << reference.status().ToString();
  ASSERT_EQ(reference->status(), "COMPLETED");
  reference->clear_wall_seconds();
  for (const int threads : {0, 8}) {
    v1::TraceRequest request = SmallBox();
    request.set_threads(threads);
    StatusOr<v1::TraceResult> r = RunTrace(request);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    r->clear_wall_seconds();
    EXPECT_EQ(r->SerializeAsString(), reference->SerializeAsString()) << threads << " threads";
  }
}

// The default curve steps (COARSE, unset) against FINE: fewer vertices, the same
// codimension-2 points (kind and position, to 1e-7 of the box: each is solved to the same
// tolerance whatever the steps).
TEST(RunTrace, DefaultCoarseCurveStepsGiveFewerVerticesThanFineAndTheSameCodim2Points) {
  v1::TraceRequest fine_request = SmallBox();
  fine_request.set_curve_steps(v1::CURVE_STEPS_FINE);
  const StatusOr<v1::TraceResult> fine = RunTrace(fine_request);
  const StatusOr<v1::TraceResult> coarse = RunTrace(SmallBox());
  ASSERT_TRUE(fine.ok() && coarse.ok());
  EXPECT_EQ(coarse->status(), "COMPLETED") << coarse->message();
  int fine_vertices = 0, coarse_vertices = 0;
  for (const v1::Curve& c : fine->curves()) fine_vertices += c.points_size();
  for (const v1::Curve& c : coarse->curves()) coarse_vertices += c.points_size();
  EXPECT_LT(2 * coarse_vertices, fine_vertices);
  ASSERT_EQ(coarse->codim2_points_size(), fine->codim2_points_size());
  for (const v1::Codim2Point& q : fine->codim2_points()) {
    bool found = false;
    for (const v1::Codim2Point& e : coarse->codim2_points()) {
      found = found || (e.kind() == q.kind() &&
                        std::hypot((e.params().omega() - q.params().omega()) / 0.15,
                                   (e.params().a() - q.params().a()) / 0.05) <= 1e-7);
    }
    EXPECT_TRUE(found) << q.kind() << " at omega = " << q.params().omega();
  }
}

// With period 2, omega in [0.099, 0.101], a in [0.25, 0.75] holds period-2 curves next to slow
// lift-offs (a = 0.689), whose corrector fails next to ends that only a prediction brackets
// (engine/src/continuation/curve.cc, EndAtBoundary): each is an unverified end of its curve, named
// in the curve's message, counted in a note, and not among the codimension-2 points.
TEST(RunTrace, UnverifiedCurveEndsAreListedNamedAndNotClaimed) {
  v1::TraceRequest request;
  request.add_trace_params(std::string("omega"));
  request.add_trace_params(std::string("a"));
  request.add_min(0.099);
  request.add_min(0.25);
  request.add_max(0.101);
  request.add_max(0.75);
  request.set_period2(true);
  const StatusOr<v1::TraceResult> r = RunTrace(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  int ends = 0;
  for (const v1::Curve& c : r->curves()) {
    ends += c.unverified_ends_size();
    int named = 0;
    for (size_t at = c.message().find("point claimed"); at != std::string::npos;
         at = c.message().find("point claimed", at + 1)) {
      ++named;
    }
    EXPECT_EQ(named, c.unverified_ends_size()) << c.message();
    for (const v1::CurveVertex& e : c.unverified_ends()) {
      for (const v1::Codim2Point& q : r->codim2_points()) {
        EXPECT_FALSE(q.params().omega() == e.params().omega() && q.params().a() == e.params().a())
            << q.kind() << " claimed at an unverified end";
      }
    }
  }
  ASSERT_GT(ends, 0);
  const std::string count = std::to_string(ends) + " period-2 curve ends not located";
  EXPECT_TRUE(std::any_of(r->notes().begin(), r->notes().end(), [&](const std::string& n) {
    return n.rfind(count, 0) == 0;
  })) << count;
  // Switching tries them, but they are not counted among the located points not switched at.
  int wide = 0;
  for (const v1::Codim2Point& q : r->codim2_points()) wide += q.bracket() > 1e-6 ? 1 : 0;
  for (const std::string& n : r->notes()) {
    // "M codimension-2 points at curve ends not switched at: N located only to a bracket > 1e-6,"
    if (n.find(" located only to a bracket > 1e-6") == std::string::npos) continue;
    EXPECT_LE(std::stoi(n.substr(n.find(": ") + 2)), wide) << n;
  }
}

// In omega in [0.05, 0.2], a in [0.27, 0.32] the PD curve from the omega-branch ends at a
// flip-grazing at one end; at the other its orbit's first event reaches the Poincare section (an
// impact at s = 0, not a grazing: the curve goes on in the rotated signature) and it leaves the
// box. Its flip-grazing is a corner (the contact phase between impact and progression vanishes),
// past which the PD curve goes on without that phase: a second PD curve, switched from the
// first, from the same point to the box. (Without edge branches: with them two more PD curves
// start on the branch along omega = 0.05, see the next test.) The flip-grazing is met from both
// curves and listed once, with the first; the second's message names it.
TEST(RunTrace, SmallBoxHasAPeriodDoublingCurveEndingAtAFlipGrazingAndItsContinuation) {
  v1::TraceRequest request = SmallBox();
  request.set_no_edge_branches(true);
  const StatusOr<v1::TraceResult> r = RunTrace(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status(), "COMPLETED") << r->message();
  std::vector<int> pd_curves, flips_listed;
  std::vector<const v1::Codim2Point*> flips;
  for (int i = 0; i < r->curves_size(); ++i) {
    const v1::Curve& c = r->curves(i);
    ASSERT_GT(c.points_size(), 0);
    for (const v1::CurveVertex& v : c.points()) {
      EXPECT_GE(v.params().omega(), 0.05);
      EXPECT_LE(v.params().omega(), 0.2);
      EXPECT_GE(v.params().a(), 0.27);
      EXPECT_LE(v.params().a(), 0.32);
      EXPECT_DOUBLE_EQ(v.params().b(), 0.15);
    }
    if (c.kind() != "PERIOD_DOUBLING") continue;
    pd_curves.push_back(i);
    EXPECT_EQ(c.period(), 1);
    int flip_grazings = 0;
    for (const v1::Codim2Point& q : r->codim2_points()) {
      if (q.curve() != i || q.kind() != "FLIP_GRAZING") continue;
      ++flip_grazings;
      flips.push_back(&q);
    }
    flips_listed.push_back(flip_grazings);
    EXPECT_THAT(c.message(), HasSubstr("ended at a FLIP_GRAZING point"));
    EXPECT_THAT(c.message(), HasSubstr("left the box"));
  }
  ASSERT_EQ(pd_curves.size(), 2u);
  const v1::Curve& first = r->curves(pd_curves[0]);
  const v1::Curve& past = r->curves(pd_curves[1]);
  EXPECT_THAT(first.message(), HasSubstr("through 1 section crossings, left the box"));
  EXPECT_EQ(past.from_curve(), pd_curves[0]);
  // The continuation's end at the corner is bisected (bracket <= 1e-8 in arclength), the first
  // curve's solved there with the phase at zero length: the same point (within 1e-9 of the box),
  // listed with the first curve only.
  EXPECT_EQ(flips_listed, (std::vector<int>{1, 0}));
  ASSERT_EQ(flips.size(), 1u);
  EXPECT_EQ(flips[0]->curve(), pd_curves[0]);
}

// Edge branches (the default): in the small box the branches along omega = 0.05 and 0.2 through
// the fold and PD curves' ends there locate points that no curve through the start's branches
// crosses; their curves are added, each with an end on the edge its branch ran along.
// no_edge_branches gives the curves without them, each also in the default result (same kind
// and start).
TEST(RunTrace, EdgeBranchesAddCurvesStartedOnTheBoxEdge) {
  const StatusOr<v1::TraceResult> with = RunTrace(SmallBox());
  v1::TraceRequest request = SmallBox();
  request.set_no_edge_branches(true);
  const StatusOr<v1::TraceResult> without = RunTrace(request);
  ASSERT_TRUE(with.ok() && without.ok());
  EXPECT_EQ(with->status(), "COMPLETED") << with->message();
  auto edge_note = [](const v1::TraceResult& r) {
    return std::any_of(r.notes().begin(), r.notes().end(), [](const std::string& n) {
      return n.find("along the box's edges") != std::string::npos;
    });
  };
  EXPECT_TRUE(edge_note(*with));
  EXPECT_FALSE(edge_note(*without));
  auto same = [](const v1::Curve& x, const v1::Curve& y) {
    return x.kind() == y.kind() && x.start_kind() == y.start_kind() &&
           x.points(0).params().omega() == y.points(0).params().omega() &&
           x.points(0).params().a() == y.points(0).params().a();
  };
  for (const v1::Curve& c : without->curves()) {
    EXPECT_TRUE(std::any_of(with->curves().begin(), with->curves().end(),
                            [&](const v1::Curve& d) { return same(c, d); }))
        << c.kind() << " from omega = " << c.points(0).params().omega();
  }
  int added = 0;
  for (const v1::Curve& c : with->curves()) {
    if (std::any_of(without->curves().begin(), without->curves().end(),
                    [&](const v1::Curve& d) { return same(c, d); })) {
      continue;
    }
    ++added;
    // Started on an edge branch: one end on the box's edge (points run from end to end).
    auto on_edge = [](const v1::CurveVertex& v) {
      return v.params().omega() == 0.05 || v.params().omega() == 0.2 || v.params().a() == 0.27 ||
             v.params().a() == 0.32;
    };
    EXPECT_TRUE(on_edge(c.points(0)) || on_edge(c.points(c.points_size() - 1)))
        << c.kind() << " " << c.message();
  }
  EXPECT_GT(added, 0);
}

// The progress of a trace whose start search simulates a long transient (long enough for the
// search to report) rises monotonically: the search is the first 2% of the bar, the curves the
// rest.
TEST(RunTrace, ProgressIsMonotoneThroughALongStartSearch) {
  v1::TraceRequest request = SmallBox();
  request.set_transient_periods(200000);
  std::vector<double> fractions;
  const StatusOr<v1::TraceResult> r = RunTrace(request, {.progress = [&](double f) {
                                                 fractions.push_back(f);
                                                 return true;
                                               }});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status(), "COMPLETED") << r->message();
  ASSERT_FALSE(fractions.empty());
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()))
      << ::testing::PrintToString(fractions);
  EXPECT_LE(fractions.back(), 1.0);
  EXPECT_GE(fractions.front(), 0.0);
}

// A stop seen while a curve is being traced (not between curves) ends the trace CANCELLED too,
// with the part of that curve traced so far. The curves stage reports its fraction before each
// curve (the job's bar: 0.02 + 0.98 * 0.1 at the first curve); within a curve the flows poll the
// same callback with that fraction. The second call at or past the first curve's fraction comes
// from within the first curve (the first may be the report itself).
TEST(RunTrace, AStopWhileACurveIsTracedEndsTheTraceCancelled) {
  constexpr double kFirstCurve = 0.02 + 0.98 * 0.1;
  int calls_in_curves = 0;
  const StatusOr<v1::TraceResult> r = RunTrace(SmallBox(), {.progress = [&](double f) {
                                                 if (f >= kFirstCurve - 1e-12) ++calls_in_curves;
                                                 return calls_in_curves < 2;
                                               }});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status(), "CANCELLED") << r->message();
  EXPECT_GE(calls_in_curves, 2);
}

TEST(RunTrace, CancelStopsBeforeTheNextCurveAndKeepsWhatWasTraced) {
  int calls = 0;
  double last = -1.0;
  bool monotone = true;
  // Cancel at the first report after the branches (fraction > 0.1: before the second curve).
  const StatusOr<v1::TraceResult> r = RunTrace(SmallBox(), {.progress = [&](double f) {
                                                 ++calls;
                                                 monotone = monotone && f >= last && f <= 1.0;
                                                 last = f;
                                                 return f <= 0.1;
                                               }});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status(), "CANCELLED");
  EXPECT_TRUE(monotone);
  EXPECT_GT(calls, 1);
  const StatusOr<v1::TraceResult> full = RunTrace(SmallBox());
  ASSERT_TRUE(full.ok());
  EXPECT_LT(r->curves_size(), full->curves_size());
}

}  // namespace
}  // namespace drillbif::jobs
