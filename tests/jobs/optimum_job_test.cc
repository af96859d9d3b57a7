// The optimum job and the trace job's region: validation naming the field, and a small box
// (omega in [0.05, 0.15], a in [0.25, 0.6]) where the margin decides the optimum
// (tests/region/stability_region_test.cc checks the engine against brute force there).
#include "jobs/optimum_job.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <string>
#include <vector>

#include "jobs/optimum_cache.h"
#include "jobs/trace_job.h"
#include "support/same_result.h"
#include "support/small_requests.h"

namespace drillbif::jobs {
namespace {

using ::testing::HasSubstr;

v1::OptimumRequest Request() {
  v1::OptimumRequest r;
  *r.mutable_trace() = testing::SmallBoxTrace();
  r.add_margin(0.01);
  r.add_margin(0.02);
  return r;
}

void ExpectInvalid(const v1::OptimumRequest& request, const std::string& names) {
  const StatusOr<v1::OptimumResult> r = RunOptimum(request);
  ASSERT_FALSE(r.ok());
  EXPECT_EQ(r.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(r.status().message(), HasSubstr(names));
}

TEST(RunOptimum, InvalidRequestsNameTheField) {
  v1::OptimumRequest negative = Request();
  negative.set_margin(0, -0.01);
  ExpectInvalid(negative, "margin");
  v1::OptimumRequest three = Request();
  three.add_margin(0.1);
  ExpectInvalid(three, "margin");
  v1::OptimumRequest nan = Request();
  nan.set_margin(1, std::nan(""));
  ExpectInvalid(nan, "margin");
  v1::OptimumRequest scaled_two = Request();
  scaled_two.set_scaled(true);
  ExpectInvalid(scaled_two, "margin");
  v1::OptimumRequest grid = Request();
  grid.add_grid(2);
  grid.add_grid(50);
  ExpectInvalid(grid, "grid");
  v1::OptimumRequest region = Request();
  region.mutable_trace()->mutable_region();
  ExpectInvalid(region, "trace.region");
  v1::OptimumRequest period2 = Request();
  period2.mutable_trace()->set_period2(true);
  ExpectInvalid(period2, "trace.period2");
  v1::OptimumRequest period4 = Request();
  period4.mutable_trace()->set_max_period(4);
  ExpectInvalid(period4, "trace.max_period");
  v1::OptimumRequest unknown = Request();
  unknown.mutable_trace()->set_trace_params(1, "zeta");
  ExpectInvalid(unknown, "trace.trace_params");
  v1::OptimumRequest xi = Request();
  xi.mutable_trace()->mutable_params()->set_xi(-1.0);
  ExpectInvalid(xi, "xi");
}

TEST(RunOptimum, FindsAStableOperatingPointWithTheMargin) {
  v1::OptimumRequest request = Request();
  request.add_grid(41);
  request.add_grid(41);
  const StatusOr<v1::OptimumResult> r = RunOptimum(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status(), "COMPLETED") << r->message();
  ASSERT_EQ(r->margin_size(), 2);
  EXPECT_GE(r->margin(0), 0.01 * (1 - 1e-12));
  EXPECT_GE(r->margin(1), 0.02 * (1 - 1e-12));
  EXPECT_GE(r->params().omega(), 0.05);
  EXPECT_LE(r->params().omega(), 0.15);
  EXPECT_GE(r->params().a(), 0.25);
  EXPECT_LE(r->params().a(), 0.6);
  EXPECT_DOUBLE_EQ(r->params().b(), 0.15);  // the other parameters are the request's
  EXPECT_GT(r->rop(), 0.0);
  EXPECT_FALSE(r->signature().empty());
  EXPECT_EQ(r->grid(0), 41);
  EXPECT_NEAR(r->spacing(1), 0.35 / 40, 1e-15);
  EXPECT_GT(r->curves(), 0);
  // The coexistence check: every spread start accounted for, and the optimum's orbit among the
  // attractors, its ROP from simulation equal to the region's (a Newton solve on the grid) to
  // 1e-8 (both orbits solved to ~1e-11).
  int starts = r->not_periodic();
  bool optimum_found = false;
  for (const v1::Attractor& a : r->attractors()) {
    starts += a.reached_from();
    optimum_found = optimum_found || (a.stable() && std::abs(a.rop() - r->rop()) <= 1e-8);
  }
  EXPECT_EQ(starts, 8);
  EXPECT_TRUE(optimum_found) << r->message();
  EXPECT_THAT(r->message(), HasSubstr("spread initial states"));
}

TEST(RunOptimum, DefaultGridFollowsTheMargin) {
  v1::OptimumRequest request = Request();
  request.set_margin(0, 0.02);  // spacing 0.01: 11 nodes in omega
  request.set_margin(1, 0.07);  // spacing 0.035: 11 nodes in a
  const StatusOr<v1::OptimumResult> r = RunOptimum(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->grid_size(), 2);
  EXPECT_EQ(r->grid(0), 11);
  EXPECT_EQ(r->grid(1), 11);
}

// Runs `request` with `cache`, expects the reuse flags given, and the answer of a run from
// scratch (every field but the times and the reuse flags, bitwise).
void ExpectReuse(const v1::OptimumRequest& request, OptimumCache* cache, bool curves, bool region) {
  const StatusOr<v1::OptimumResult> r = RunOptimum(request, {.optimum_cache = cache});
  const StatusOr<v1::OptimumResult> fresh = RunOptimum(request);
  ASSERT_TRUE(r.ok() && fresh.ok());
  EXPECT_EQ(r->curves_reused(), curves);
  EXPECT_EQ(r->region_reused(), region);
  EXPECT_FALSE(fresh->curves_reused() || fresh->region_reused());
  testing::ExpectSameResult(*r, *fresh);
}

// With a cache (the server's worker pool has one), a second request over the same curves reuses
// them, and over the same grid the region too; each answer is the one computed from scratch.
TEST(RunOptimum, AnotherMarginOverKnownCurvesReusesThemAndGivesTheSameAnswer) {
  OptimumCache cache;
  v1::OptimumRequest first = Request();
  first.add_grid(41);
  first.add_grid(41);
  ExpectReuse(first, &cache, false, false);
  // Another margin, the same grid: curves and region reused.
  v1::OptimumRequest second = first;
  second.set_margin(0, 0.02);
  second.set_margin(1, 0.04);
  ExpectReuse(second, &cache, true, true);
  // Another grid: the curves reused, the region computed.
  v1::OptimumRequest third = second;
  third.set_grid(0, 31);
  ExpectReuse(third, &cache, true, false);
  // Another box: nothing reused.
  v1::OptimumRequest other = first;
  other.mutable_trace()->set_max(1, 0.55);
  ExpectReuse(other, &cache, false, false);
}

// A trace of the same box (the map drawn first, with its region) leaves its curves and region for
// an optimum asked next; a trace of period-2 curves leaves nothing (the optimum's are period 1).
TEST(RunOptimum, ATraceOfTheSameBoxLeavesItsCurvesAndRegion) {
  OptimumCache cache;
  v1::TraceRequest period2 = testing::SmallBoxTrace();
  period2.set_period2(true);
  period2.set_max(0, 0.12);  // keeps the run short
  ASSERT_TRUE(RunTrace(period2, {.optimum_cache = &cache}).ok());
  EXPECT_EQ(cache.FindCurves(OptimumCache::KeyOf(period2)), nullptr);

  v1::TraceRequest map = testing::SmallBoxTrace();
  map.mutable_region()->add_grid(41);
  map.mutable_region()->add_grid(41);
  const StatusOr<v1::TraceResult> traced = RunTrace(map, {.optimum_cache = &cache});
  ASSERT_TRUE(traced.ok()) << traced.status().ToString();
  v1::OptimumRequest request = Request();
  request.add_grid(41);
  request.add_grid(41);
  ExpectReuse(request, &cache, true, true);
  EXPECT_EQ(OptimumCache::KeyOf(map), OptimumCache::KeyOf(request.trace()));  // region left out
}

// The progress rises monotonically through every stage (curves, region, the optimum's query, the
// coexistence check) and ends at 1, so that a client can tell the stages apart by the fraction.
TEST(RunOptimum, ProgressIsMonotoneThroughEveryStage) {
  v1::OptimumRequest request = Request();
  request.add_grid(101);
  request.add_grid(101);
  std::vector<double> fractions;
  const StatusOr<v1::OptimumResult> r = RunOptimum(request, {.progress = [&](double f) {
                                                     fractions.push_back(f);
                                                     return true;
                                                   }});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status(), "COMPLETED") << r->message();
  ASSERT_FALSE(fractions.empty());
  EXPECT_TRUE(std::is_sorted(fractions.begin(), fractions.end()))
      << ::testing::PrintToString(fractions);
  EXPECT_EQ(fractions.back(), 1.0);
}

// A cancelled optimum leaves nothing in the cache: the next request computes its curves.
TEST(RunOptimum, ACancelledRunIsNotReused) {
  OptimumCache cache;
  v1::OptimumRequest request = Request();
  request.add_grid(41);
  request.add_grid(41);
  const StatusOr<v1::OptimumResult> cancelled =
      RunOptimum(request, {.progress = [](double) { return false; }, .optimum_cache = &cache});
  ASSERT_TRUE(cancelled.ok()) << cancelled.status().ToString();
  EXPECT_EQ(cancelled->status(), "CANCELLED");
  EXPECT_EQ(cache.FindCurves(OptimumCache::KeyOf(request.trace())), nullptr);
  const StatusOr<v1::OptimumResult> r = RunOptimum(request, {.optimum_cache = &cache});
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_FALSE(r->curves_reused());
  EXPECT_EQ(r->status(), "COMPLETED") << r->message();
}

// Least recently used curves go first; a region goes with its curves.
TEST(OptimumCache, KeepsTheMostRecentlyUsed) {
  OptimumCache cache(2, 1);
  auto curves = std::make_shared<OptimumCurves>();
  auto region = std::make_shared<StabilityRegion>();
  cache.PutCurves("a", curves);
  cache.PutRegion("a", 3, 3, region);
  cache.PutCurves("b", curves);
  EXPECT_NE(cache.FindCurves("a"), nullptr);  // a is now the most recent
  cache.PutCurves("c", curves);               // drops b
  EXPECT_EQ(cache.FindCurves("b"), nullptr);
  EXPECT_EQ(cache.FindRegion("a", 3, 3), region);
  cache.PutRegion("a", 4, 4, region);  // one region per curves: drops (3, 3)
  EXPECT_EQ(cache.FindRegion("a", 3, 3), nullptr);
  EXPECT_EQ(cache.FindRegion("a", 4, 4), region);
  cache.PutRegion("b", 3, 3, region);  // b's curves are gone: not kept
  EXPECT_EQ(cache.FindRegion("b", 3, 3), nullptr);
  cache.PutCurves("a", curves);  // new curves: their old regions go
  EXPECT_EQ(cache.FindRegion("a", 4, 4), nullptr);
  // The key is the request's content.
  v1::OptimumRequest r1 = Request(), r2 = Request();
  EXPECT_EQ(OptimumCache::KeyOf(r1.trace()), OptimumCache::KeyOf(r2.trace()));
  r2.mutable_trace()->mutable_params()->set_b(0.16);
  EXPECT_NE(OptimumCache::KeyOf(r1.trace()), OptimumCache::KeyOf(r2.trace()));
}

// A region of n x n nodes (its grid's vectors filled) and its approximate size computed from the
// element sizes independently of ApproximateBytes' code: two value axes of doubles, a label (int)
// and a ROP (double) per node.
std::shared_ptr<StabilityRegion> RegionOfNodes(int n) {
  auto region = std::make_shared<StabilityRegion>();
  region->grid.n1 = region->grid.n2 = n;
  region->grid.values1.assign(n, 0.0);
  region->grid.values2.assign(n, 0.0);
  region->grid.label.assign(static_cast<size_t>(n) * n, RegionGrid::kOutside);
  region->grid.rop.assign(static_cast<size_t>(n) * n, 0.0);
  return region;
}

int64_t NodeBytes(int n) {
  return 2 * n * int64_t{sizeof(double)} + int64_t{n} * n * int64_t{sizeof(int) + sizeof(double)};
}

// The cache holds at most its byte bound: the least recently used regions, then curves, go first,
// and a region larger than the bound alone is not kept, so that the memory a server holds between
// jobs does not grow with the largest regions it computed.
TEST(OptimumCache, HoldsAtMostItsByteBound) {
  auto curves = std::make_shared<OptimumCurves>();
  const int64_t curves_bytes = OptimumCache::ApproximateBytes(*curves);
  const auto small = RegionOfNodes(100), large = RegionOfNodes(400);
  EXPECT_GE(OptimumCache::ApproximateBytes(*small), NodeBytes(100));
  EXPECT_LT(OptimumCache::ApproximateBytes(*small), NodeBytes(100) + 4096);
  // Room for the curves of two keys and two small regions, not for a large one.
  const int64_t bound = 2 * curves_bytes + 2 * OptimumCache::ApproximateBytes(*small) + 1024;
  ASSERT_LT(bound, NodeBytes(400));
  OptimumCache cache(4, 2, bound);
  cache.PutCurves("a", curves);
  cache.PutRegion("a", 100, 100, small);
  cache.PutCurves("b", curves);
  cache.PutRegion("b", 100, 100, small);
  EXPECT_LE(cache.bytes(), bound);
  EXPECT_EQ(cache.FindRegion("a", 100, 100), small);   // a is now the most recent
  cache.PutRegion("a", 101, 101, RegionOfNodes(101));  // over the bound: b goes, the oldest
  EXPECT_LE(cache.bytes(), bound);
  EXPECT_EQ(cache.FindCurves("b"), nullptr);
  EXPECT_NE(cache.FindRegion("a", 101, 101), nullptr);
  cache.PutRegion("a", 400, 400, large);  // larger than the bound alone: not kept
  EXPECT_EQ(cache.FindRegion("a", 400, 400), nullptr);
  EXPECT_LE(cache.bytes(), bound);
  cache.PutCurves("a", curves);  // replaced curves drop their regions and their bytes
  EXPECT_EQ(cache.bytes(), curves_bytes);
}

TEST(RunTrace, RegionOnRequestOnly) {
  v1::TraceRequest request = testing::SmallBoxTrace();
  const StatusOr<v1::TraceResult> plain = RunTrace(request);
  ASSERT_TRUE(plain.ok()) << plain.status().ToString();
  EXPECT_FALSE(plain->has_region());  // compute only what is asked
  request.mutable_region()->add_grid(21);
  request.mutable_region()->add_grid(31);
  const StatusOr<v1::TraceResult> r = RunTrace(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_TRUE(r->has_region());
  const v1::StabilityRegion& region = r->region();
  EXPECT_EQ(region.values1_size(), 21);
  EXPECT_EQ(region.values2_size(), 31);
  EXPECT_EQ(region.label_size(), 21 * 31);
  EXPECT_EQ(region.rop_size(), 21 * 31);
  EXPECT_GE(region.signatures_size(), 1);
  EXPECT_GT(region.polygons_size(), 0);
  for (const v1::RegionPolygon& p : region.polygons()) {
    EXPECT_GE(p.vertices_size(), 3);
    for (const v1::RegionVertex& v : p.vertices()) EXPECT_LT(v.curve(), r->curves_size());
  }
  v1::TraceRequest bad = testing::SmallBoxTrace();
  bad.mutable_region()->add_grid(21);
  const StatusOr<v1::TraceResult> e = RunTrace(bad);
  EXPECT_EQ(e.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(e.status().message(), HasSubstr("region.grid"));
}

}  // namespace
}  // namespace drillbif::jobs
