// The optimum map job and queries answered from it, on the small (omega, a) box of the optimum
// tests (omega in [0.05, 0.15], a in [0.25, 0.6]) over the weight on bit b in [0.14, 0.16].
#include "jobs/optimum_map_job.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <cmath>
#include <map>
#include <set>
#include <string>
#include <vector>

#include "jobs/optimum_map_query.h"
#include "support/small_requests.h"

namespace drillbif::jobs {
namespace {

using ::testing::HasSubstr;

v1::OptimumMapRequest MapRequest(int steps) { return testing::SmallBoxMap(0.14, 0.16, steps); }

void ExpectInvalid(const v1::OptimumMapRequest& request, const std::string& names) {
  const StatusOr<OptimumMapPlan> plan = PlanOptimumMap(request);
  ASSERT_FALSE(plan.ok()) << names;
  EXPECT_EQ(plan.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(plan.status().message(), HasSubstr(names));
}

TEST(PlanOptimumMap, InvalidRequestsNameTheField) {
  v1::OptimumMapRequest none = MapRequest(3);
  none.clear_over();
  ExpectInvalid(none, "over");
  v1::OptimumMapRequest unknown = MapRequest(3);
  unknown.set_over(0, "zeta");
  ExpectInvalid(unknown, "over[0]");
  v1::OptimumMapRequest traced = MapRequest(3);
  traced.set_over(0, "omega");
  ExpectInvalid(traced, "trace parameter");
  v1::OptimumMapRequest twice = MapRequest(3);
  twice.add_over("b");
  twice.add_from(0.1);
  twice.add_to(0.2);
  twice.add_steps(2);
  ExpectInvalid(twice, "over[1]");
  v1::OptimumMapRequest sizes = MapRequest(3);
  sizes.add_from(0.1);
  ExpectInvalid(sizes, "from, to, steps");
  v1::OptimumMapRequest reversed = MapRequest(3);
  reversed.set_from(0, 0.2);
  ExpectInvalid(reversed, "from[0], to[0]");
  v1::OptimumMapRequest one = MapRequest(1);
  ExpectInvalid(one, "steps[0]");
  v1::OptimumMapRequest many = MapRequest(3);
  many.add_over("xi");
  many.add_from(0.04);
  many.add_to(0.06);
  many.add_steps(5000);
  ExpectInvalid(many, "steps: 15000 cells");
  v1::OptimumMapRequest threads = MapRequest(3);
  threads.set_threads(-1);
  ExpectInvalid(threads, "threads");
  v1::OptimumMapRequest negative = MapRequest(3);
  negative.set_from(0, -0.1);
  ExpectInvalid(negative, "the cell at b = -0.1");
  v1::OptimumMapRequest margin = MapRequest(3);
  margin.mutable_optimum()->set_margin(0, -1.0);
  ExpectInvalid(margin, "optimum.margin");
}

TEST(PlanOptimumMap, CellsSpanTheConditionsFirstFastest) {
  v1::OptimumMapRequest r = MapRequest(3);
  r.add_over("xi");
  r.add_from(0.04);
  r.add_to(0.06);
  r.add_steps(2);
  const StatusOr<OptimumMapPlan> plan = PlanOptimumMap(r);
  ASSERT_TRUE(plan.ok()) << plan.status().ToString();
  EXPECT_EQ(plan->cells, 6);
  EXPECT_EQ(CellIndex(*plan, 4), (std::vector<int>{1, 1}));
  EXPECT_EQ(CellCondition(*plan, 0), (std::vector<double>{0.14, 0.04}));
  EXPECT_EQ(CellCondition(*plan, 5), (std::vector<double>{0.16, 0.06}));  // ends exactly
  const v1::OptimumRequest cell = CellRequest(r, *plan, 4);
  EXPECT_EQ(cell.trace().params().xi(), 0.06);
  EXPECT_DOUBLE_EQ(cell.trace().params().b(), 0.15);
}

// Cells by their flat index.
std::map<int, v1::OptimumMapCell> ByIndex(const v1::OptimumMapResult& result) {
  std::map<int, v1::OptimumMapCell> cells;
  for (const v1::OptimumMapCell& c : result.cells()) cells[c.index(0)] = c;
  return cells;
}

TEST(RunOptimumMap, EachCellIsTheOptimumAtItsConditionOnAnyNumberOfThreads) {
  v1::OptimumMapRequest request = MapRequest(3);
  request.set_threads(2);
  const StatusOr<v1::OptimumMapResult> two = RunOptimumMap(request);
  ASSERT_TRUE(two.ok()) << two.status().ToString();
  EXPECT_EQ(two->status(), "COMPLETED") << two->message();
  EXPECT_EQ(two->cells_found(), 3);
  request.set_threads(1);
  const StatusOr<v1::OptimumMapResult> one = RunOptimumMap(request);
  ASSERT_TRUE(one.ok()) << one.status().ToString();
  const auto cells_two = ByIndex(*two), cells_one = ByIndex(*one);
  ASSERT_EQ(cells_two.size(), 3u);
  const OptimumMapPlan plan = PlanOptimumMap(request).value();
  for (const auto& [k, cell] : cells_two) {
    // The optimum job at the cell's condition, run on its own: the same answer to the bit.
    const StatusOr<v1::OptimumResult> alone = RunOptimum(CellRequest(request, plan, k));
    ASSERT_TRUE(alone.ok());
    EXPECT_EQ(cell.condition(0), CellCondition(plan, k)[0]);
    EXPECT_EQ(cell.optimum().params().a(), alone->params().a()) << k;
    EXPECT_EQ(cell.optimum().params().omega(), alone->params().omega()) << k;
    EXPECT_EQ(cell.optimum().rop(), alone->rop()) << k;
    EXPECT_EQ(cell.optimum().params().SerializeAsString(),
              cells_one.at(k).optimum().params().SerializeAsString());
    EXPECT_TRUE(cell.has_orbit()) << "the coexistence check found the optimum's orbit";
    EXPECT_GT(cell.boundary_size(), 0);
    // The region without its grid, and every curve its polygons lie on, with its polyline.
    EXPECT_GT(cell.region().polygons_size(), 0);
    EXPECT_EQ(cell.region().label_size(), 0);
    EXPECT_EQ(cell.region().values1_size(), 0);
    std::set<int> on, given;
    for (const v1::RegionPolygon& p : cell.region().polygons()) {
      for (const v1::RegionVertex& v : p.vertices()) {
        if (v.curve() >= 0) on.insert(v.curve());
      }
    }
    for (const v1::BoundingCurve& c : cell.curves()) {
      given.insert(c.curve());
      EXPECT_EQ(c.values1_size(), c.values2_size());
      EXPECT_GT(c.values1_size(), 1);
    }
    EXPECT_EQ(on, given);
  }
}

TEST(RunOptimumMap, AStopCancelsWithTheCellsDoneUntilThen) {
  RunContext context;
  std::atomic<int> calls{0};
  context.progress = [&](double) { return ++calls < 3; };
  const auto start = std::chrono::steady_clock::now();
  const StatusOr<v1::OptimumMapResult> r = RunOptimumMap(MapRequest(5), context);
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_EQ(r->status(), "CANCELLED");
  EXPECT_LT(r->cells_size(), 5);
  // Five cells take ~2 s on two threads; the stop comes after ~40 ms of polling.
  EXPECT_LT(seconds, 1.5);
}

// A map of five cells, as queries use it.
class MapQuery : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    request_ = new v1::OptimumMapRequest(MapRequest(5));
    const StatusOr<v1::OptimumMapResult> r = RunOptimumMap(*request_);
    ASSERT_TRUE(r.ok()) << r.status().ToString();
    ASSERT_EQ(r->cells_found(), 5) << r->message();
    std::vector<v1::OptimumMapCell> cells(r->cells().begin(), r->cells().end());
    StatusOr<LoadedMap> map = LoadMap("operations/map", *request_, std::move(cells));
    ASSERT_TRUE(map.ok()) << map.status().ToString();
    map_ = new LoadedMap(*std::move(map));
  }
  static void TearDownTestSuite() {
    delete map_;
    delete request_;
  }
  // The optimum request of the map at b.
  static v1::OptimumRequest QueryAt(double b) {
    v1::OptimumRequest q = request_->optimum();
    q.mutable_trace()->mutable_params()->set_b(b);
    return q;
  }
  static v1::OptimumMapRequest* request_;
  static LoadedMap* map_;
};
v1::OptimumMapRequest* MapQuery::request_ = nullptr;
LoadedMap* MapQuery::map_ = nullptr;

// A map's answer to `q` against an optimum computed afresh there: the same orbit, the parameters
// within one grid spacing, the ROP within 1% (derived below), the margin at least the one asked.
void ExpectAgreesWithAFreshOptimum(const MapQueryAnswer& a, const v1::OptimumRequest& q) {
  const StatusOr<v1::OptimumResult> fresh = RunOptimum(q);
  ASSERT_TRUE(fresh.ok());
  ASSERT_EQ(fresh->status(), "COMPLETED");
  EXPECT_LE(std::abs(a.optimum.params().omega() - fresh->params().omega()), fresh->spacing(0));
  EXPECT_LE(std::abs(a.optimum.params().a() - fresh->params().a()), fresh->spacing(1));
  EXPECT_LE(std::abs(a.optimum.rop() - fresh->rop()), 0.01 * fresh->rop());
  EXPECT_EQ(a.optimum.signature(), fresh->signature());
  EXPECT_GE(a.optimum.margin(0), q.margin(0));  // in omega's units
}

// The acceptance of a map: between cells, the answer agrees with an optimum computed afresh at
// that condition to the grid's resolution in the parameters (one spacing: the fresh optimum is a
// grid node, the answer interpolates two) and to 1% in ROP (here one spacing of a changes the
// ROP by ~1.1%, and the answers measured lie within half a spacing).
TEST_F(MapQuery, BetweenCellsAgreesWithAFreshOptimum) {
  for (double b : {0.1425, 0.1431, 0.1525, 0.1575}) {
    SCOPED_TRACE(b);
    const v1::OptimumRequest q = QueryAt(b);
    const MapQueryAnswer a = AnswerFromMap(*map_, q, /*nearest_on_failure=*/false);
    ASSERT_TRUE(a.from_map.verified()) << a.from_map.verification();
    EXPECT_TRUE(a.from_map.interpolated());
    EXPECT_EQ(a.optimum.status(), "COMPLETED");
    EXPECT_EQ(a.from_map.cells_size(), 2);
    EXPECT_EQ(a.optimum.params().b(), b);
    ExpectAgreesWithAFreshOptimum(a, q);
  }
}

// At a cell's own condition the answer is that cell's optimum, its ROP solved again to Newton's
// tolerance (1e-11 on the orbit; the ROP, a mean over the orbit, agrees to ~1e-10 relative).
TEST_F(MapQuery, AtACellItIsThatCellsOptimum) {
  const MapQueryAnswer a = AnswerFromMap(*map_, QueryAt(0.145), false);
  ASSERT_TRUE(a.from_map.verified()) << a.from_map.verification();
  ASSERT_EQ(a.from_map.cells_size(), 1);
  EXPECT_EQ(a.from_map.cells(0).index(0), 1);
  const v1::OptimumResult& cell = map_->cells[1]->optimum();
  EXPECT_EQ(a.optimum.params().a(), cell.params().a());
  EXPECT_EQ(a.optimum.params().omega(), cell.params().omega());
  EXPECT_NEAR(a.optimum.rop(), cell.rop(), 1e-8 * cell.rop());
}

TEST_F(MapQuery, AFailedInterpolationFallsBackToTheNearestCellOrSaysWhy) {
  LoadedMap doctored = *map_;
  // A boundary segment of cell 1 through the interpolated point at b = 0.1431.
  const MapQueryAnswer clean = AnswerFromMap(*map_, QueryAt(0.1431), false);
  ASSERT_TRUE(clean.from_map.verified());
  v1::BoundarySegment* s = doctored.cells[0]->add_boundary();
  s->set_a1(0.0), s->set_b1(1.0);
  s->set_a2(clean.optimum.params().a()), s->set_b2(clean.optimum.params().a());
  s->set_kind("FOLD");
  const MapQueryAnswer strict = AnswerFromMap(doctored, QueryAt(0.1431), false);
  EXPECT_FALSE(strict.from_map.verified());
  EXPECT_EQ(strict.optimum.status(), "FAILED");
  EXPECT_THAT(strict.from_map.verification(), HasSubstr("margins from the boundary"));
  const MapQueryAnswer nearest = AnswerFromMap(doctored, QueryAt(0.1431), true);
  EXPECT_FALSE(nearest.from_map.interpolated());
  EXPECT_THAT(nearest.from_map.verification(), HasSubstr("interpolation: "));
  // The nearest cell's point is on the doctored segment's side too: it fails, and says so.
  EXPECT_FALSE(nearest.from_map.verified());
  // Without cell 1, the nearest cell with an optimum answers: cell 0's point, checked at b.
  LoadedMap one_missing = *map_;
  one_missing.cells[1].reset();
  const MapQueryAnswer fallback = AnswerFromMap(one_missing, QueryAt(0.1431), true);
  EXPECT_TRUE(fallback.from_map.verified()) << fallback.from_map.verification();
  EXPECT_FALSE(fallback.from_map.interpolated());
  EXPECT_EQ(fallback.optimum.params().a(), map_->cells[0]->optimum().params().a());
  EXPECT_EQ(fallback.optimum.params().b(), 0.1431);
  EXPECT_FALSE(AnswerFromMap(one_missing, QueryAt(0.1431), false).from_map.verified());
  doctored.cells[1].reset();
  const MapQueryAnswer missing = AnswerFromMap(doctored, QueryAt(0.1431), true);
  EXPECT_FALSE(missing.from_map.verified());
  EXPECT_THAT(missing.from_map.verification(), HasSubstr("cell 1 has no verified optimum"));
}

TEST_F(MapQuery, KeysMatchTheSameBoxAndMarginAtAnyCondition) {
  const std::string key = MapQueryKey(request_->optimum(), {"b"});
  v1::OptimumRequest explicit_xi = QueryAt(0.151);
  explicit_xi.mutable_trace()->mutable_params()->set_xi(0.05);  // the reference value
  explicit_xi.mutable_trace()->set_threads(3);
  EXPECT_EQ(MapQueryKey(explicit_xi, {"b"}), key);
  v1::OptimumRequest other_margin = QueryAt(0.151);
  other_margin.set_margin(0, 0.02);
  EXPECT_NE(MapQueryKey(other_margin, {"b"}), key);
  v1::OptimumRequest other_xi = QueryAt(0.151);
  other_xi.mutable_trace()->mutable_params()->set_xi(0.06);
  EXPECT_NE(MapQueryKey(other_xi, {"b"}), key);
  EXPECT_EQ(CellsOutside(*map_, QueryConditions(*map_, QueryAt(0.15))), 0.0);
  EXPECT_NEAR(CellsOutside(*map_, QueryConditions(*map_, QueryAt(0.17))), 2.0, 1e-12);
}

// Two conditions (b and the rock's damping xi), four cells: a query inside is interpolated
// bilinearly from all four and agrees with an optimum computed afresh there, to one grid spacing
// and 1% in ROP as in one condition.
TEST(MapQueryTwoConditions, InsideTheCellsAgreesWithAFreshOptimum) {
  v1::OptimumMapRequest request = MapRequest(2);
  request.set_to(0, 0.145);
  request.add_over("xi");
  request.add_from(0.048);
  request.add_to(0.052);
  request.add_steps(2);
  const StatusOr<v1::OptimumMapResult> r = RunOptimumMap(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->cells_found(), 4) << r->message();
  const LoadedMap map =
      LoadMap("operations/map2", request, {r->cells().begin(), r->cells().end()}).value();
  v1::OptimumRequest q = request.optimum();
  q.mutable_trace()->mutable_params()->set_b(0.1425);
  q.mutable_trace()->mutable_params()->set_xi(0.0505);
  const MapQueryAnswer a = AnswerFromMap(map, q, false);
  ASSERT_TRUE(a.from_map.verified()) << a.from_map.verification();
  ASSERT_EQ(a.from_map.cells_size(), 4);
  double weights = 0.0;
  for (const v1::MapCellWeight& w : a.from_map.cells()) weights += w.weight();
  EXPECT_NEAR(weights, 1.0, 1e-12);
  ExpectAgreesWithAFreshOptimum(a, q);
}

}  // namespace
}  // namespace drillbif::jobs
