// The continue job (ContinueRequest -> start orbit -> continuation -> ContinueResult): the
// published fold and ROP maximum of MODEL.md's continuation in b, the branch points' contents,
// invalid requests as INVALID_ARGUMENT naming the field, a chaotic start
// as FAILED_PRECONDITION, direction, step budget, signature switching off, and cancellation.
#include "jobs/continue_job.h"

#include <gmock/gmock.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

#include "jobs/simulate_job.h"
#include "jobs/sweep_job.h"

namespace drillbif::jobs {
namespace {

using ::testing::HasSubstr;

// Continuation of the reference orbit in b (a = 0.3, omega = 0.1), MODEL.md's table, published to
// 8 digits by an independent computation.
constexpr double kFoldB = 0.16715050;
constexpr double kRopMaxB = 0.16381677;
constexpr double kRopMaxRop = 0.53873914;
constexpr double kGrazingL1B = 0.02772417;
// The published values are rounded to 8 decimals (error <= 5e-9); the engine locates special
// points to locate_tolerance = 1e-10 in b. 1e-8 covers both with a margin.
constexpr double kPublishedTolerance = 1e-8;

// The reference orbit's signature: NC -impact-> CwoP -progression-> CwP -stick-> CwoP
// -separation-> NC -section.
constexpr const char* kReferenceSignature = "NC>Pi CwoP>l1 CwP>l1 CwoP>l2 NC|";

// b in [0.16, 0.17] from the stable period-1 orbit at b = 0.165, found by simulation from the
// default initial state (p = y = q = s = 0): the decreasing direction passes the ROP maximum and
// stops at 0.16; the increasing one turns at the fold onto the unstable branch and goes back down
// to 0.16. About 60 ms.
v1::ContinueRequest FoldRequest() {
  v1::ContinueRequest request;
  request.mutable_params()->set_b(0.165);
  request.set_param("b");
  request.set_min(0.16);
  request.set_max(0.17);
  return request;
}

// The fold run is shared by the tests that only read it.
const v1::ContinueResult& FoldResult() {
  static const v1::ContinueResult result = [] {
    StatusOr<v1::ContinueResult> r = RunContinue(FoldRequest());
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    return r.ok() ? *r : v1::ContinueResult();
  }();
  return result;
}

// The special points of a kind.
std::vector<v1::SpecialPoint> OfKind(const v1::ContinueResult& r, v1::SpecialPoint::Kind kind) {
  std::vector<v1::SpecialPoint> out;
  for (const v1::SpecialPoint& sp : r.special_points()) {
    if (sp.kind() == kind) out.push_back(sp);
  }
  return out;
}

TEST(RunContinue, FindsThePublishedFoldAndRopMaximumInB) {
  const v1::ContinueResult& r = FoldResult();
  EXPECT_EQ(r.status(), "COMPLETED") << r.message();
  const std::vector<v1::SpecialPoint> folds = OfKind(r, v1::SpecialPoint::FOLD);
  ASSERT_EQ(folds.size(), 1u);
  EXPECT_NEAR(folds[0].value(), kFoldB, kPublishedTolerance);
  EXPECT_EQ(folds[0].params().b(), folds[0].value());
  const std::vector<v1::SpecialPoint> maxima = OfKind(r, v1::SpecialPoint::ROP_MAX);
  ASSERT_EQ(maxima.size(), 1u);
  EXPECT_NEAR(maxima[0].value(), kRopMaxB, kPublishedTolerance);
  EXPECT_NEAR(maxima[0].rop(), kRopMaxRop, kPublishedTolerance);
  EXPECT_TRUE(maxima[0].stable());
  // Nothing else happens on this stretch of the period-1 branch.
  EXPECT_EQ(r.special_points_size(), 2);
  for (const v1::SpecialPoint& sp : r.special_points()) {
    EXPECT_EQ(sp.signature_text(), kReferenceSignature);
    EXPECT_EQ(sp.signature_size(), 5);
  }
}

// Each located point says how narrowly: the fold and the ROP maximum, located by bracketing,
// carry a bracket of at most the request's locate_tolerance (1e-10, the default; the fold's, in
// the parameter that is stationary there, is the parameter's spread over an arclength bracket of
// 1e-9, ~1e-18); the published values lie within it plus their 8 digits' rounding.
TEST(RunContinue, LocatedPointsCarryTheirBracket) {
  constexpr double kLocateTolerance = 1e-10;
  const v1::ContinueResult& r = FoldResult();
  ASSERT_EQ(r.special_points_size(), 2);
  for (const v1::SpecialPoint& sp : r.special_points()) {
    EXPECT_GE(sp.bracket(), 0.0) << v1::SpecialPoint::Kind_Name(sp.kind());
    EXPECT_LE(sp.bracket(), kLocateTolerance) << v1::SpecialPoint::Kind_Name(sp.kind());
    const double published = sp.kind() == v1::SpecialPoint::FOLD ? kFoldB : kRopMaxB;
    EXPECT_LE(std::abs(sp.value() - published), 5e-9 + sp.bracket());
  }
}

TEST(RunContinue, FoldHasAMultiplierAtOne) {
  // The period-1 orbit has one nontrivial multiplier (two structural zeros, MODEL.md); at a fold
  // it is +1. It moves like sqrt(b_fold - b) along the branch, so a fold located to 1e-10 in b
  // leaves it within about 1e-5 of 1 (the engine gets ~1e-14: it locates the zero of the
  // tangent's b component, where the multiplier is exactly 1).
  const std::vector<v1::SpecialPoint> folds = OfKind(FoldResult(), v1::SpecialPoint::FOLD);
  ASSERT_EQ(folds.size(), 1u);
  ASSERT_EQ(folds[0].multipliers_size(), 1);
  EXPECT_NEAR(folds[0].multipliers(0).re(), 1.0, 1e-4);
  EXPECT_EQ(folds[0].multipliers(0).im(), 0.0);
}

TEST(RunContinue, BranchPointsCarryTheOrbitAndItsStability) {
  const v1::ContinueResult& r = FoldResult();
  ASSERT_GT(r.points_size(), 10);
  int stable = 0;
  for (const v1::BranchPoint& pt : r.points()) {
    // The branch stays in [min, max]; its ends are located on the bounds.
    EXPECT_GE(pt.value(), 0.16 - 1e-12);
    EXPECT_LE(pt.value(), 0.17 + 1e-12);
    EXPECT_EQ(pt.params().b(), pt.value());
    EXPECT_EQ(pt.params().a(), 0.3);
    EXPECT_EQ(pt.params().omega(), 0.1);
    EXPECT_TRUE(pt.params().has_xi() && pt.params().has_g() && pt.params().has_phi0());
    EXPECT_NEAR(pt.period(), 2.0 * M_PI / 0.1, 1e-9);
    EXPECT_EQ(pt.signature_text(), kReferenceSignature);
    ASSERT_EQ(pt.signature_size(), 5);
    EXPECT_EQ(pt.signature(0), v1::NO_CONTACT);
    EXPECT_EQ(pt.signature(1), v1::CONTACT);
    EXPECT_EQ(pt.signature(2), v1::PROGRESSION);
    EXPECT_EQ(pt.signature(3), v1::CONTACT);
    EXPECT_EQ(pt.signature(4), v1::NO_CONTACT);
    ASSERT_EQ(pt.durations_size(), 5);
    EXPECT_NEAR(std::accumulate(pt.durations().begin(), pt.durations().end(), 0.0), pt.period(),
                1e-9);
    EXPECT_EQ(pt.structural_zeros(), 2);
    ASSERT_EQ(pt.multipliers_size(), 1);
    const v1::Multiplier& mu = pt.multipliers(0);
    EXPECT_DOUBLE_EQ(mu.abs(), std::hypot(mu.re(), mu.im()));
    EXPECT_EQ(pt.stable(), mu.abs() < 1.0);
    stable += pt.stable();
    // The section state: free flight (p < q + g), slider relaxed.
    EXPECT_LT(pt.p(), pt.q() + 0.02);
    EXPECT_GT(pt.rop(), 0.4);
    EXPECT_GT(pt.power(), 0.0);
  }
  // Both sides of the fold: the stable branch and the unstable one.
  EXPECT_GT(stable, 0);
  EXPECT_LT(stable, r.points_size());
  EXPECT_GT(r.steps(), 0);
  EXPECT_GT(r.newton_iterations(), 0);
  EXPECT_GT(r.wall_seconds(), 0.0);
  EXPECT_FALSE(r.engine_version().empty());
}

TEST(RunContinue, UnknownParameterIsInvalidArgumentNamingIt) {
  v1::ContinueRequest request = FoldRequest();
  request.set_param("zeta");
  const StatusOr<v1::ContinueResult> r = RunContinue(request);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr("zeta"));
  EXPECT_THAT(r.status().message(), HasSubstr("param"));
}

TEST(RunContinue, EmptyRangeIsInvalidArgument) {
  for (double max : {0.16, 0.15}) {
    v1::ContinueRequest request = FoldRequest();
    request.set_max(max);
    const StatusOr<v1::ContinueResult> r = RunContinue(request);
    ASSERT_FALSE(r.ok());
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
    EXPECT_THAT(r.status().message(), HasSubstr("max must be > min"));
  }
}

TEST(RunContinue, StartValueOutsideTheRangeIsInvalidArgument) {
  v1::ContinueRequest request = FoldRequest();
  request.mutable_params()->clear_b();  // the reference b = 0.15, below min = 0.16
  const StatusOr<v1::ContinueResult> r = RunContinue(request);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr("params.b = 0.15"));
}

TEST(RunContinue, InvalidModelParametersAndOptionsAreInvalidArgument) {
  struct Case {
    const char* name;
    void (*edit)(v1::ContinueRequest*);
    const char* names;  // what the message must name
  };
  const Case cases[] = {
      {"xi", [](v1::ContinueRequest* r) { r->mutable_params()->set_xi(-1.0); }, "xi"},
      {"min below the domain", [](v1::ContinueRequest* r) { r->set_min(-0.1); }, "min"},
      {"infinite max", [](v1::ContinueRequest* r) { r->set_max(INFINITY); }, "max"},
      {"min_step", [](v1::ContinueRequest* r) { r->set_min_step(0.0); }, "min_step"},
      {"max_step", [](v1::ContinueRequest* r) { r->set_max_step(1e-9); }, "max_step"},
      {"max_steps", [](v1::ContinueRequest* r) { r->set_max_steps(0); }, "max_steps"},
      {"target_iterations", [](v1::ContinueRequest* r) { r->set_target_iterations(99); },
       "target_iterations"},
      {"locate_tolerance", [](v1::ContinueRequest* r) { r->set_locate_tolerance(-1.0); },
       "locate_tolerance"},
      {"transient_periods", [](v1::ContinueRequest* r) { r->set_transient_periods(-1); },
       "transient_periods"},
      {"initial_state", [](v1::ContinueRequest* r) { r->mutable_initial_state()->set_q(2.0); },
       "q"},
      {"empty param", [](v1::ContinueRequest* r) { r->clear_param(); }, "param"},
  };
  for (const Case& c : cases) {
    v1::ContinueRequest request = FoldRequest();
    c.edit(&request);
    const StatusOr<v1::ContinueResult> r = RunContinue(request);
    ASSERT_FALSE(r.ok()) << c.name;
    EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument) << c.name;
    EXPECT_THAT(r.status().message(), HasSubstr(c.names)) << c.name;
  }
}

TEST(RunContinue, ChaoticStartIsFailedPrecondition) {
  // b = 0.05 lies in a chaotic band of MODEL.md's brute-force diagram (checked with
  // `drillctl --local simulate --b 0.05 --transient 2000 --samples 30`: the Poincare samples never
  // repeat, with impacts in some periods only), so no Poincare return closes within 16 periods.
  v1::ContinueRequest request;
  request.mutable_params()->set_b(0.05);
  request.set_param("b");
  request.set_min(0.04);
  request.set_max(0.06);
  request.set_transient_periods(50);
  const StatusOr<v1::ContinueResult> r = RunContinue(request);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kFailedPrecondition);
  EXPECT_THAT(r.status().message(), HasSubstr("the start state is not near a periodic orbit"));
}

TEST(RunContinue, IncreasingDirectionStopsAfterMaxSteps) {
  v1::ContinueRequest request;  // reference point, b = 0.15
  request.set_param("b");
  request.set_min(0.0);
  request.set_max(0.2);
  request.set_direction(v1::ContinueRequest::INCREASING);
  request.set_max_steps(5);
  const StatusOr<v1::ContinueResult> r = RunContinue(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status(), "COMPLETED");
  EXPECT_THAT(r->message(), HasSubstr("max_steps"));
  EXPECT_EQ(r->steps(), 5);
  ASSERT_EQ(r->points_size(), 6);  // the start orbit and 5 steps
  EXPECT_EQ(r->points(0).value(), 0.15);
  for (int i = 1; i < r->points_size(); ++i) {
    EXPECT_GT(r->points(i).value(), r->points(i - 1).value());
  }
}

TEST(RunContinue, WithoutSwitchingStopsAtTheL1Grazing) {
  // Down from b = 0.12 (above the period doubling at 0.11001, so the period-1 orbit is the
  // attractor the simulation finds) past the period doubling to the grazing where the progression
  // phase vanishes.
  v1::ContinueRequest request;
  request.mutable_params()->set_b(0.12);
  request.set_param("b");
  request.set_min(0.0);
  request.set_max(0.2);
  request.set_direction(v1::ContinueRequest::DECREASING);
  request.set_switch_signatures(false);
  const StatusOr<v1::ContinueResult> r = RunContinue(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status(), "COMPLETED") << r->message();
  EXPECT_THAT(r->message(), HasSubstr("switching is off"));
  const std::vector<v1::SpecialPoint> grazings = OfKind(*r, v1::SpecialPoint::GRAZING_L1);
  ASSERT_EQ(grazings.size(), 1u);
  EXPECT_NEAR(grazings[0].value(), kGrazingL1B, kPublishedTolerance);
  // Branch order: the decreasing direction from its far end (the grazing) to the start orbit.
  EXPECT_NEAR(r->points(0).value(), kGrazingL1B, kPublishedTolerance);
  EXPECT_EQ(r->points(r->points_size() - 1).value(), 0.12);
  EXPECT_EQ(OfKind(*r, v1::SpecialPoint::PERIOD_DOUBLING).size(), 1u);
  // The branch ends at the grazing: only the side before is known, so the point is not called
  // stable whatever that side is.
  EXPECT_TRUE(grazings[0].has_stability_before());
  EXPECT_FALSE(grazings[0].has_stability_after());
  EXPECT_FALSE(grazings[0].stable());
  EXPECT_FALSE(grazings[0].stability_changes());
}

// The period-2 a-branch at omega = 0.4644 (the attractor at a = 0.19) loses its CwP phases at a
// GRAZING_L1 near a = 0.2048239, unstable on both sides (|mu| 1.99 at the grazing from either
// side): the result names both sides unstable and the point not stable.
TEST(RunContinue, GrazingCarriesTheStabilityOfBothSides) {
  v1::ContinueRequest request;
  request.mutable_params()->set_omega(0.4644);
  request.mutable_params()->set_a(0.19);
  request.set_param("a");
  request.set_min(0.19);
  request.set_max(0.21);
  request.set_direction(v1::ContinueRequest::INCREASING);
  const StatusOr<v1::ContinueResult> r = RunContinue(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const std::vector<v1::SpecialPoint> grazings = OfKind(*r, v1::SpecialPoint::GRAZING_L1);
  ASSERT_EQ(grazings.size(), 1u) << r->message();
  const v1::SpecialPoint& g = grazings[0];
  EXPECT_NEAR(g.value(), 0.2048239, 1e-7);
  ASSERT_TRUE(g.has_stability_before());
  ASSERT_TRUE(g.has_stability_after());
  EXPECT_FALSE(g.stability_before().stable());
  EXPECT_FALSE(g.stability_after().stable());
  EXPECT_GT(g.stability_before().max_abs(), 1.0);
  EXPECT_GT(g.stability_after().max_abs(), 1.0);
  EXPECT_FALSE(g.stable());
  EXPECT_FALSE(g.stability_changes());
  // The point's multipliers are the side before's.
  ASSERT_GT(g.multipliers_size(), 0);
  EXPECT_DOUBLE_EQ(g.multipliers(0).abs(), g.stability_before().max_abs());
}

// Stopped once three points of the branch were accepted (on_value hears each): the result is
// CANCELLED with the points found until then, and the progress reported was monotone in [0, 1]
// across the start orbit's search and the continuation.
// The reference b-branch over [0, 0.2] (from b = 0.15): a period doubling and a fold located
// 4.8e-7 and 3e-9 from Pi grazings, where the multipliers jump (|mu| 2.94 -> 0.73 and
// 3.47 -> 1.36), are reported as part of those grazings' unfolding, with the grazing and the
// distance; the fold at kFoldB, an isolated smooth fold, is not. The 8-digit values below are
// located to 1e-10 and rounded (error <= 5e-9), so 1e-8 picks each point out; the two points'
// distances to their grazings are computed here from the reported values.
TEST(RunContinue, BifurcationsNextToAPiGrazingNameTheGrazingAndTheDistance) {
  v1::ContinueRequest request;  // reference point, b = 0.15
  request.set_param("b");
  request.set_min(0.0);
  request.set_max(0.2);
  const StatusOr<v1::ContinueResult> r = RunContinue(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const std::vector<v1::SpecialPoint> grazings = OfKind(*r, v1::SpecialPoint::GRAZING_PI);
  ASSERT_FALSE(grazings.empty());
  // The nearest Pi grazing to b.
  auto nearest = [&](double b) {
    return *std::min_element(grazings.begin(), grazings.end(), [&](const auto& x, const auto& y) {
      return std::abs(x.value() - b) < std::abs(y.value() - b);
    });
  };
  auto find = [&](v1::SpecialPoint::Kind kind, double b) -> const v1::SpecialPoint* {
    for (const v1::SpecialPoint& sp : r->special_points()) {
      if (sp.kind() == kind && std::abs(sp.value() - b) < kPublishedTolerance) return &sp;
    }
    return nullptr;
  };
  // The engine's distance: 1e-6 x max(1, span of b) = 1e-6 on this branch (b in [0, 0.2]).
  constexpr double kUnfoldingDistance = 1e-6;
  for (const auto& [kind, b] : {std::pair{v1::SpecialPoint::PERIOD_DOUBLING, 0.15097798},
                                std::pair{v1::SpecialPoint::FOLD, 0.17681741}}) {
    SCOPED_TRACE(v1::SpecialPoint::Kind_Name(kind) + " at b = " + std::to_string(b));
    const v1::SpecialPoint* sp = find(kind, b);
    ASSERT_NE(sp, nullptr);
    const v1::SpecialPoint g = nearest(sp->value());
    const double distance = std::abs(sp->value() - g.value());
    EXPECT_LT(distance, kUnfoldingDistance);
    ASSERT_TRUE(sp->has_near_grazing());
    EXPECT_EQ(sp->near_grazing().kind(), v1::SpecialPoint::GRAZING_PI);
    EXPECT_EQ(sp->near_grazing().value(), g.value());
    EXPECT_DOUBLE_EQ(sp->near_grazing().distance(), distance);
    // The multipliers on each side are on the grazing's own point, which has both sides.
    EXPECT_TRUE(g.has_stability_before());
    EXPECT_TRUE(g.has_stability_after());
  }
  const v1::SpecialPoint* fold = find(v1::SpecialPoint::FOLD, kFoldB);
  ASSERT_NE(fold, nullptr);
  EXPECT_GT(std::abs(fold->value() - nearest(fold->value()).value()), kUnfoldingDistance);
  EXPECT_FALSE(fold->has_near_grazing());
}

TEST(RunContinue, CancelledFromTheProgressCallback) {
  int points = 0;
  std::vector<double> fractions;
  const StatusOr<v1::ContinueResult> r =
      RunContinue(FoldRequest(), {.progress =
                                      [&](double fraction) {
                                        fractions.push_back(fraction);
                                        return points < 3;
                                      },
                                  .on_value = [&](double) { ++points; }});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status(), "CANCELLED");
  EXPECT_GE(points, 3);
  EXPECT_GT(r->points_size(), 0);
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()));
  for (double f : fractions) {
    EXPECT_GE(f, 0.0);
    EXPECT_LE(f, 1.0);
  }
}

TEST(RunContinue, CancelledBeforeTheFirstStep) {
  const StatusOr<v1::ContinueResult> r =
      RunContinue(FoldRequest(), {.progress = [](double) { return false; }});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status(), "CANCELLED");
  EXPECT_EQ(r->points_size(), 0);
}

// follow_period_doubling: from the reference orbit over b in [0.09, 0.12] the branch doubles at
// b = 0.11001173 (MODEL.md); the period-2 branch born there is continued and returned.
TEST(RunContinue, FollowsThePeriodDoubledBranch) {
  v1::ContinueRequest request;
  request.set_param("b");
  request.set_min(0.09);
  request.set_max(0.12);
  request.set_max_steps(200);
  request.mutable_params()->set_b(0.115);
  request.set_follow_period_doubling(true);
  const StatusOr<v1::ContinueResult> r = RunContinue(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const auto& specials = r->special_points();
  ASSERT_TRUE(std::any_of(specials.begin(), specials.end(), [](const v1::SpecialPoint& s) {
    return s.kind() == v1::SpecialPoint::PERIOD_DOUBLING && std::abs(s.value() - 0.11001173) < 1e-7;
  }));
  const v1::ContinueResult& doubled = r->period_doubled_branch();
  EXPECT_EQ(doubled.status(), "COMPLETED") << doubled.message();
  ASSERT_GT(doubled.points_size(), 10);
  for (const v1::BranchPoint& p : doubled.points()) {
    EXPECT_THAT(p.signature_text(), ::testing::EndsWith(" x2"));
  }
  // The period-2 branch meets the period-1 branch at the doubling: a branch point of the doubled
  // system there.
  EXPECT_TRUE(std::any_of(
      doubled.special_points().begin(), doubled.special_points().end(),
      [](const v1::SpecialPoint& s) { return std::abs(s.value() - 0.11001173) < 1e-6; }));
}

// The period-n windows of the b-sweep at a = 0.3, omega = 0.1 (MODEL.md: a reverse period-adding
// cascade accumulating at b = 0): the attractor found by simulation at b inside a window, of
// period n, is continued over b in [0, 0.2]. Each end of the branch reaches b = 0, where the orbit
// degenerates (its free flight touches Pi at every maximum), or, `doubling` > 0, the period-1
// orbit's doubling there: a branch point where the period-2 branch meets the period-1 orbit
// traversed twice (beyond it the same orbits shifted by one period, the branch's other half
// again). The run completes; every fold has a multiplier at +1 and every period doubling one at
// -1. The folds are located to 1e-10 in b and the multiplier moves like sqrt(b_fold - b), so
// about 1e-5 from +1 at worst; 1e-4 as in FoldHasAMultiplierAtOne (a period doubling is a
// regular zero of mu + 1: ~1e-10). About 1 s each.
void ExpectWindowBranchCompletes(double b, const std::string& period, double doubling = 0.0) {
  SCOPED_TRACE("start at b = " + std::to_string(b));
  v1::ContinueRequest request;
  request.mutable_params()->set_b(b);
  request.set_param("b");
  request.set_min(0.0);
  request.set_max(0.2);
  const StatusOr<v1::ContinueResult> r = RunContinue(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status(), "COMPLETED") << r->message();
  EXPECT_THAT(r->message(), ::testing::Not(HasSubstr("could not")));
  ASSERT_GT(r->points_size(), 2);
  const auto start = std::find_if(r->points().begin(), r->points().end(),
                                  [&](const v1::BranchPoint& p) { return p.value() == b; });
  ASSERT_NE(start, r->points().end());
  EXPECT_THAT(start->signature_text(), ::testing::EndsWith(period));
  // Each end of the branch at an end of the range, to the tracer's "next to the bound" (1e-6 of
  // the range), or at the branch's turn at the doubling: the period-1 orbit traversed twice,
  // solved there (far below 1e-10 in b), so the doubling to MODEL.md's 8 digits (5e-9).
  constexpr double kNear = 1e-6 * 0.2;
  constexpr double kPublished = 5.1e-9;
  int at_doubling = 0;
  for (const double end : {r->points(0).value(), r->points(r->points_size() - 1).value()}) {
    if (doubling > 0.0 && std::abs(end - doubling) <= kPublished) {
      ++at_doubling;
      continue;
    }
    EXPECT_TRUE(end <= kNear || end >= 0.2 - kNear) << "branch ends at b = " << end;
  }
  if (doubling > 0.0) {
    EXPECT_EQ(at_doubling, 1) << r->message();
    EXPECT_THAT(r->message(), HasSubstr("stopped at BRANCH_POINT")) << r->message();
    // The turn (the tip of the doubling's pitchfork) is the branch's fold and its branch point.
    // No ROP or Pc maximum there: both are even about the turn, beyond which run the same
    // orbits, shifted.
    auto near = [&](v1::SpecialPoint::Kind kind, double within) {
      return std::any_of(r->special_points().begin(), r->special_points().end(),
                         [&](const v1::SpecialPoint& s) {
                           return s.kind() == kind && std::abs(s.value() - doubling) <= within;
                         });
    };
    EXPECT_TRUE(near(v1::SpecialPoint::FOLD, kPublished)) << "no fold at b = " << doubling;
    EXPECT_TRUE(near(v1::SpecialPoint::BRANCH_POINT, kPublished))
        << "no branch point at b = " << doubling;
    EXPECT_FALSE(near(v1::SpecialPoint::ROP_MAX, 1e-6)) << "a ROP maximum at the turn";
    EXPECT_FALSE(near(v1::SpecialPoint::POWER_MAX, 1e-6)) << "a Pc maximum at the turn";
  }
  int folds = 0, doublings = 0;
  for (const v1::SpecialPoint& sp : r->special_points()) {
    const bool fold = sp.kind() == v1::SpecialPoint::FOLD;
    if (!fold && sp.kind() != v1::SpecialPoint::PERIOD_DOUBLING) continue;
    (fold ? folds : doublings)++;
    const double target = fold ? 1.0 : -1.0;
    double distance = std::numeric_limits<double>::infinity();
    for (const v1::Multiplier& mu : sp.multipliers()) {
      distance = std::min(distance, std::hypot(mu.re() - target, mu.im()));
    }
    EXPECT_LT(distance, 1e-4) << v1::SpecialPoint::Kind_Name(sp.kind()) << " at b = " << sp.value();
  }
  EXPECT_GT(folds, 0);
  EXPECT_GT(doublings, 0);
}

// The request of `drillctl continue --param <param> --min <min> --max <max> --omega <omega>
// --a <a> --follow-pd`.
StatusOr<v1::ContinueResult> FollowPdFrom(const char* param, double min, double max, double omega,
                                          double a) {
  v1::ContinueRequest request;
  request.set_param(param);
  request.set_min(min);
  request.set_max(max);
  request.mutable_params()->set_omega(omega);
  request.mutable_params()->set_a(a);
  request.set_follow_period_doubling(true);
  return RunContinue(request);
}

// The period-doubled branch's turns (its BRANCH_POINTs), each checked to be the parent orbit at
// one of its doublings (located on the parent branch independently, by the sign of
// prod(mu + 1)), traversed twice: solved, not bracketed, with one nontrivial multiplier, the
// doubling's -1 squared, at 1 to the corrector's tolerance (~1e-10 relative; 1e-6 is the
// branches' fold test of a multiplier at 1).
std::vector<v1::SpecialPoint> TurnsAtParentDoublings(const v1::ContinueResult& r) {
  constexpr double kLocateTolerance = 1e-10;  // the request's default locate_tolerance
  const std::vector<v1::SpecialPoint> doublings = OfKind(r, v1::SpecialPoint::PERIOD_DOUBLING);
  const std::vector<v1::SpecialPoint> turns =
      OfKind(r.period_doubled_branch(), v1::SpecialPoint::BRANCH_POINT);
  for (const v1::SpecialPoint& s : turns) {
    EXPECT_EQ(s.bracket(), 0.0) << "the turn is solved, not bracketed";
    EXPECT_TRUE(std::any_of(doublings.begin(), doublings.end(),
                            [&](const v1::SpecialPoint& d) {
                              return d.bracket() <= kLocateTolerance &&
                                     std::abs(d.value() - s.value()) <= 2 * kLocateTolerance;
                            }))
        << "the turn at " << s.value() << " is no doubling of the parent branch";
    EXPECT_EQ(s.multipliers_size(), 1) << "at " << s.value();
    if (s.multipliers_size() == 1) {
      EXPECT_NEAR(s.multipliers(0).re(), 1.0, 1e-6);
    }
  }
  return turns;
}

// The omega-branch over [0.05, 2] from the attractor at (omega, a), followed through its period
// doubling (FollowPdFrom) into *out; its period-doubled branch COMPLETED, its signatures ending
// in `suffix` (" x8": period 8).
void DoubledOmegaBranch(double omega, double a, const char* suffix, v1::ContinueResult* out) {
  StatusOr<v1::ContinueResult> r = FollowPdFrom("omega", 0.05, 2.0, omega, a);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const v1::ContinueResult& doubled = r->period_doubled_branch();
  ASSERT_EQ(doubled.status(), "COMPLETED") << doubled.message();
  ASSERT_FALSE(doubled.points().empty());
  EXPECT_THAT(doubled.points(0).signature_text(), ::testing::EndsWith(suffix));
  *out = *std::move(r);
}

// The period-8 omega-branch born at a doubling of the period-4 attractor at omega = 0.15, a = 0.5
// runs to the other doubling it joins, at omega = 0.4631173123, a period doubling 1.3e-8 and a
// grazing 4e-9 before it. Next to that turn its system is ill-conditioned (smallest singular
// value ~1e-6 of ~2e3 over the last 1.6e-3 of its halves' durations), the corrector's steps
// stagnate at rounding noise, and the branch crept at 1e-13 per step until it FAILED ("the
// corrector failed down to min_step at omega = 0.463117"). The turn, solved within a step that
// fails to correct, ends it: the period-4 orbit at its doubling (located on the period-4 branch
// independently, by the sign of prod(mu + 1)), traversed twice, with its multiplier at +1.
TEST(RunContinue, PeriodEightBranchEndsAtItsTurnWhereItsStepsStopCorrecting) {
  v1::ContinueResult r;
  ASSERT_NO_FATAL_FAILURE(DoubledOmegaBranch(0.15, 0.5, " x8", &r));
  const v1::ContinueResult& doubled = r.period_doubled_branch();
  EXPECT_EQ(TurnsAtParentDoublings(r).size(), 2u) << doubled.message();
  EXPECT_NEAR(doubled.points(doubled.points_size() - 1).value(), 0.4631173123, 1e-10);
}

// The period-16 omega-branch born at a doubling of the period-8 attractor at omega = 1.0, a = 2.5
// stops correcting 2.3e-2 of arclength before its turn at omega = 0.27075185 (Newton's steps
// stagnate at 2e-9 against a tolerance of 4e-10, the residual at 1e-11), farther than its failed
// step (1.1e-2) reaches: it crept at 1e-7 .. 1e-5 per step and FAILED ("the corrector failed down
// to min_step at omega = 0.270755"). The turn solved ahead, with nothing but the turn between
// (the parameter's change that of a quadratic turn, no multiplier crossing -1), ends it; its
// detail says that the stretch before it was not traced.
TEST(RunContinue, PeriodSixteenBranchEndsAtItsTurnSolvedBeyondItsFailedStep) {
  v1::ContinueResult r;
  ASSERT_NO_FATAL_FAILURE(DoubledOmegaBranch(1.0, 2.5, " x16", &r));
  const v1::ContinueResult& doubled = r.period_doubled_branch();
  const std::vector<v1::SpecialPoint> turns = TurnsAtParentDoublings(r);
  ASSERT_EQ(turns.size(), 2u) << doubled.message();
  const auto ahead = std::find_if(turns.begin(), turns.end(), [](const v1::SpecialPoint& s) {
    return std::abs(s.value() - 0.27075185) < 1e-8;
  });
  ASSERT_NE(ahead, turns.end());
  EXPECT_THAT(ahead->detail(), ::testing::HasSubstr("past the last corrected point"));
  // The branch's decreasing end: no point beyond the turn.
  const auto lowest = std::min_element(
      doubled.points().begin(), doubled.points().end(),
      [](const v1::BranchPoint& p, const v1::BranchPoint& q) { return p.value() < q.value(); });
  EXPECT_EQ(lowest->value(), ahead->value());
}

// On the period-4 a-branch at omega = 0.07 (from the period-2 attractor at a = 0.5) the ROP is
// largest at the GRAZING_L2 at a = 0.63006770600: the slope of ROP along the old signature turns
// negative 1e-4 of arclength before it, where a is nearly stationary. Trial points predicted
// along the step's tangent there did not correct (8 iterations, converging linearly next to the
// vanishing segment), and the ROP_MAX was reported at the last trial that did, a = 0.6300676692,
// bracketed to 6.2e-6, with an ROP 3.9e-9 below the grazing's, 3.7e-8 away. At the GRAZING_L1 at
// a = 0.6365169699, where a contact phase vanishes, the location of the vanishing closed on the
// degenerate family of zero-length solutions 3.5e-8 before the grazing (solved in tangent form),
// and the search for special points before it ended there, with the ROP's slope read off that
// family: a ROP_MAX at a = 0.6365169689, bracketed to 3.4e-8, with an ROP 8.3e-9 below the
// grazing's. A maximum is not exceeded next to it: within the bracket's width the ROP differs by
// O(|ROP''| 1e-20), so 1e-12 is rounding's margin on an ROP of 0.70.
TEST(RunContinue, RopMaximumNextToAGrazingIsNotExceededThere) {
  const StatusOr<v1::ContinueResult> r = FollowPdFrom("a", 0.01, 8.0, 0.07, 0.5);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const v1::ContinueResult& doubled = r->period_doubled_branch();
  ASSERT_EQ(doubled.status(), "COMPLETED") << doubled.message();
  std::vector<v1::SpecialPoint> grazings;
  for (const v1::SpecialPoint& s : doubled.special_points()) {
    if (s.has_stability_before()) grazings.push_back(s);
  }
  ASSERT_TRUE(std::any_of(grazings.begin(), grazings.end(), [](const v1::SpecialPoint& g) {
    return g.kind() == v1::SpecialPoint::GRAZING_L2 && std::abs(g.value() - 0.630067706) < 1e-8;
  }));
  int next_to_grazing = 0;
  for (const v1::SpecialPoint& m : OfKind(doubled, v1::SpecialPoint::ROP_MAX)) {
    EXPECT_LE(m.bracket(), 1e-10) << "ROP_MAX at a = " << m.value();  // the default tolerance
    for (const v1::SpecialPoint& g : grazings) {
      if (std::abs(m.value() - g.value()) > 1e-6) continue;
      ++next_to_grazing;
      EXPECT_GE(m.rop(), g.rop() - 1e-12)
          << "ROP_MAX at a = " << m.value() << " below the ROP of the "
          << v1::SpecialPoint::Kind_Name(g.kind()) << " at a = " << g.value();
    }
  }
  EXPECT_GE(next_to_grazing, 1);
}

// On the a-branch at omega = 0.15 (from the attractor at a = 0.5) the ROP rises into the
// GRAZING_PI at a = 0.6213554427, where an impact appears, and falls beyond it: the branch's ROP
// has a corner maximum there (slopes 2.5e-3 before and -1.3e-7 after along the branch), which the
// smooth maxima's test (a sign change of the slope between two points of one signature) does not
// see. Checked on the branch's own points, independently of the slopes: the points next to the
// grazing on either side have a lower ROP (by 6.3e-5 and 2.2e-7).
TEST(RunContinue, RopMaximumAtAGrazingIsReportedThere) {
  v1::ContinueRequest request;
  request.set_param("a");
  request.set_min(0.01);
  request.set_max(8.0);
  request.mutable_params()->set_omega(0.15);
  request.mutable_params()->set_a(0.5);
  const StatusOr<v1::ContinueResult> r = RunContinue(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->status(), "COMPLETED") << r->message();
  const std::vector<v1::SpecialPoint> grazings = OfKind(*r, v1::SpecialPoint::GRAZING_PI);
  const auto grazing = std::find_if(
      grazings.begin(), grazings.end(),
      [](const v1::SpecialPoint& g) { return std::abs(g.value() - 0.6213554427) < 1e-9; });
  ASSERT_NE(grazing, grazings.end());
  const std::vector<v1::SpecialPoint> maxima = OfKind(*r, v1::SpecialPoint::ROP_MAX);
  const auto corner = std::find_if(maxima.begin(), maxima.end(), [&](const v1::SpecialPoint& m) {
    return m.value() == grazing->value();
  });
  ASSERT_NE(corner, maxima.end()) << "no ROP_MAX at the GRAZING_PI at a = " << grazing->value();
  EXPECT_EQ(corner->rop(), grazing->rop());
  EXPECT_EQ(corner->bracket(), grazing->bracket());
  EXPECT_THAT(corner->detail(), ::testing::HasSubstr("at the GRAZING_PI"));
  const auto& points = r->points();
  const auto at = std::find_if(points.begin(), points.end(), [&](const v1::BranchPoint& p) {
    return p.value() == grazing->value();
  });
  ASSERT_TRUE(at != points.end() && at != points.begin() && at + 1 != points.end());
  EXPECT_LT((at - 1)->rop(), at->rop());
  EXPECT_LT((at + 1)->rop(), at->rop());
}

// Each grazing carries the stability of the branch just before it. Next to a vanishing segment
// the rows of its two events nearly coincide, and the point 1e-6 of the arclength before the
// grazing may not correct: four of the grazings of these two branches (GRAZING_L2 at
// a = 0.68134, 0.68405, 0.68958 of the period-2 branch, 0.68214 of the period-4 one) had no side
// before, so no stability there and no search for special points over the step before them.
TEST(RunContinue, EveryGrazingCarriesTheStabilityOfItsSideBefore) {
  const StatusOr<v1::ContinueResult> r = FollowPdFrom("a", 0.01, 8.0, 0.07, 0.5);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  int grazings = 0;
  for (const v1::ContinueResult* branch : {&*r, &r->period_doubled_branch()}) {
    for (const v1::SpecialPoint& s : branch->special_points()) {
      const bool grazing = s.kind() == v1::SpecialPoint::GRAZING_L1 ||
                           s.kind() == v1::SpecialPoint::GRAZING_L2 ||
                           s.kind() == v1::SpecialPoint::GRAZING_PI ||
                           s.kind() == v1::SpecialPoint::SIGNATURE_CHANGE;
      if (!grazing) continue;
      ++grazings;
      EXPECT_TRUE(s.has_stability_before())
          << v1::SpecialPoint::Kind_Name(s.kind()) << " at a = " << s.value();
      EXPECT_GT(s.multipliers_size(), 0) << "at a = " << s.value();
    }
  }
  EXPECT_GT(grazings, 0);
}

// The period-4 a-branch at omega = 0.6 (from the period-2 attractor at a = 0.2) locates a
// GRAZING_L2 at a = 0.3241 where a CwoP phase vanishes. A trial point of that location 4e-9 of
// arclength from the root, predicted on the bracket's chord, corrected onto the degenerate family
// of zero-length solutions at a = 2.7e9: the grazing was reported there, and the branch FAILED
// after it. A point between two of the branch's points lies within their distance of their chord.
TEST(RunContinue, GrazingLocationStaysOnItsBranch) {
  const StatusOr<v1::ContinueResult> r = FollowPdFrom("a", 0.01, 8.0, 0.6, 0.2);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const v1::ContinueResult& doubled = r->period_doubled_branch();
  EXPECT_EQ(doubled.status(), "COMPLETED") << doubled.message();
  for (const v1::BranchPoint& p : doubled.points()) {
    EXPECT_TRUE(p.value() >= 0.01 && p.value() <= 8.0) << "a point at a = " << p.value();
  }
  for (const v1::SpecialPoint& s : doubled.special_points()) {
    EXPECT_TRUE(s.value() >= 0.01 && s.value() <= 8.0)
        << v1::SpecialPoint::Kind_Name(s.kind()) << " at a = " << s.value();
  }
  EXPECT_NE(std::find_if(doubled.special_points().begin(), doubled.special_points().end(),
                         [](const v1::SpecialPoint& s) {
                           return s.kind() == v1::SpecialPoint::GRAZING_L2 &&
                                  std::abs(s.value() - 0.3241) < 1e-4;
                         }),
            doubled.special_points().end());
}

TEST(RunContinue, PeriodTwoWindowBranchCompletesOverTheRange) {
  ExpectWindowBranchCompletes(0.068, " x2", 0.11001173);
}

TEST(RunContinue, PeriodThreeWindowBranchCompletesOverTheRange) {
  ExpectWindowBranchCompletes(0.0443, " x3");
}

}  // namespace
}  // namespace drillbif::jobs
