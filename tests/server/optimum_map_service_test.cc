// Optimum maps through the service: a map submitted as a job, then QueryOptimum at conditions
// between its cells answered from it (verified, without a job), outside it NOT_FOUND naming it, and
// the maps of a store found again by a restarted server. A real server on 127.0.0.1 (port 0) over
// a SQLite file; the small (omega, a) box of the optimum tests over b in [0.14, 0.16].
#include <gmock/gmock.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <string>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "jobs/optimum_map_query.h"
#include "server/server.h"
#include "support/operations.h"
#include "support/small_requests.h"
#include "support/temp_dir.h"
#include "support/test_server.h"

namespace drillbif::server {
namespace {

using google::longrunning::Operation;
using ::testing::HasSubstr;

v1::OptimumMapRequest MapRequest() { return testing::SmallBoxMap(0.14, 0.16, 3); }

v1::QueryOptimumRequest QueryAt(double b) {
  v1::QueryOptimumRequest q;
  *q.mutable_request() = MapRequest().optimum();
  q.mutable_request()->mutable_trace()->mutable_params()->set_b(b);
  return q;
}

using drillbif::testing::TestServer;

// Two workers, so that the map's cells run two at a time.
ServerOptions TwoWorkers() {
  ServerOptions options;
  options.workers = 2;
  return options;
}

// Submits `map` and waits until it is done.
Operation RunMap(TestServer& s, const v1::OptimumMapRequest& map = MapRequest()) {
  v1::SubmitOptimumMapRequest submit;
  *submit.mutable_request() = map;
  Operation op;
  EXPECT_TRUE(s.jobs().SubmitOptimumMap(TestServer::Context().get(), submit, &op).ok());
  return s.WaitDone(op.name());
}

grpc::Status Query(TestServer& s, const v1::QueryOptimumRequest& q,
                   v1::QueryOptimumResponse* response) {
  return s.jobs().QueryOptimum(TestServer::Context().get(), q, response);
}

TEST(OptimumMapService, QueriesBetweenCellsAreAnsweredFromTheMapVerified) {
  TestServer s(TwoWorkers(), "drillbif_map");
  ASSERT_TRUE(s.ok());
  const Operation map = RunMap(s);
  ASSERT_TRUE(map.done());
  ASSERT_TRUE(map.has_response()) << map.error().message();
  const auto result = testing::ResponseOf<v1::OptimumMapResult>(map);
  EXPECT_EQ(result.cells_found(), 3) << result.message();

  const int64_t runs = s.server().engine_runs();
  v1::QueryOptimumResponse answer;
  ASSERT_TRUE(Query(s, QueryAt(0.1475), &answer).ok());
  ASSERT_TRUE(answer.has_optimum());
  EXPECT_EQ(answer.operation(), map.name());
  EXPECT_FALSE(answer.stored());
  EXPECT_TRUE(answer.from_map().verified()) << answer.from_map().verification();
  EXPECT_TRUE(answer.from_map().interpolated());
  EXPECT_EQ(answer.from_map().cells_size(), 2);
  EXPECT_EQ(answer.optimum().params().b(), 0.1475);
  EXPECT_EQ(s.server().engine_runs(), runs) << "answered without a job";

  // The same answer as the query module gives on the map's cells, read back from the store.
  jobs::LoadedMap loaded =
      jobs::LoadMap(map.name(), MapRequest(), {result.cells().begin(), result.cells().end()})
          .value();
  const jobs::MapQueryAnswer direct = jobs::AnswerFromMap(loaded, QueryAt(0.1475).request(), true);
  EXPECT_EQ(answer.optimum().params().SerializeAsString(),
            direct.optimum.params().SerializeAsString());
  EXPECT_EQ(answer.optimum().rop(), direct.optimum.rop());

  // Asked again: the kept answer.
  v1::QueryOptimumResponse again;
  ASSERT_TRUE(Query(s, QueryAt(0.1475), &again).ok());
  EXPECT_EQ(again.SerializeAsString(), answer.SerializeAsString());
}

TEST(OptimumMapService, OutsideEveryMapIsNotFoundNamingTheNearestAndADeletedMapStopsAnswering) {
  TestServer s(TwoWorkers(), "drillbif_map");
  ASSERT_TRUE(s.ok());
  const Operation map = RunMap(s);
  ASSERT_TRUE(map.has_response());
  v1::QueryOptimumResponse answer;
  grpc::Status outside = Query(s, QueryAt(0.17), &answer);
  EXPECT_EQ(outside.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_THAT(outside.error_message(), HasSubstr(map.name()));
  EXPECT_THAT(outside.error_message(), HasSubstr("1 cells outside"));

  v1::QueryOptimumRequest unknown = QueryAt(0.1475);
  unknown.set_on_map_failure(static_cast<v1::QueryOptimumRequest::OnMapFailure>(7));
  grpc::Status refused = Query(s, unknown, &answer);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(refused.error_message(), HasSubstr("on_map_failure"));

  v1::QueryOptimumRequest no_maps = QueryAt(0.1475);
  no_maps.set_no_maps(true);
  EXPECT_EQ(Query(s, no_maps, &answer).error_code(), grpc::StatusCode::NOT_FOUND);

  v1::QueryOptimumRequest other_margin = QueryAt(0.1475);
  other_margin.mutable_request()->set_margin(0, 0.02);
  grpc::Status other = Query(s, other_margin, &answer);
  EXPECT_EQ(other.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_THAT(other.error_message(), ::testing::Not(HasSubstr(map.name())));

  ASSERT_TRUE(Query(s, QueryAt(0.1475), &answer).ok());  // an answer kept in memory ...
  google::longrunning::DeleteOperationRequest del;
  del.set_name(map.name());
  google::protobuf::Empty empty;
  ASSERT_TRUE(s.operations().DeleteOperation(TestServer::Context().get(), del, &empty).ok());
  EXPECT_EQ(Query(s, QueryAt(0.1475), &answer).error_code(), grpc::StatusCode::NOT_FOUND)
      << "... is dropped with its map";
}

TEST(OptimumMapService, ARestartedServerAnswersFromTheMapsOfItsStore) {
  testing::TempDir dir("drillbif_map");
  const std::string db = dir.path() + "/jobs.db";
  std::string name;
  {
    TestServer first(TwoWorkers(), "drillbif_map", db);
    ASSERT_TRUE(first.ok());
    name = RunMap(first).name();
  }
  TestServer second(TwoWorkers(), "drillbif_map", db);
  ASSERT_TRUE(second.ok());
  v1::QueryOptimumResponse answer;
  ASSERT_TRUE(Query(second, QueryAt(0.1525), &answer).ok());
  EXPECT_EQ(answer.operation(), name);
  EXPECT_TRUE(answer.from_map().verified()) << answer.from_map().verification();
}

// Between a cell without an optimum (b = 0.11: no stable period-1 start orbit from rest) and one
// with (b = 0.12), the nearest cell's point fails its check at b = 0.1145 (one margin from it the
// orbit is no longer stable): NEAREST_CELL answers it unverified, and COMPUTE does not get that
// answer back but runs an optimum job at b = 0.1145 instead, whose optimum lies lower in a.
TEST(OptimumMapService, AnUnverifiedAnswerIsNotKeptForACallerWhoAsksToCompute) {
  TestServer s(TwoWorkers(), "drillbif_map");
  ASSERT_TRUE(s.ok());
  const v1::OptimumMapRequest request = testing::SmallBoxMap(0.11, 0.12, 2);
  const Operation map = RunMap(s, request);
  ASSERT_TRUE(map.has_response()) << map.error().message();

  v1::QueryOptimumRequest query;
  *query.mutable_request() = request.optimum();
  query.mutable_request()->mutable_trace()->mutable_params()->set_b(0.1145);
  v1::QueryOptimumResponse nearest;
  ASSERT_TRUE(Query(s, query, &nearest).ok());
  ASSERT_EQ(nearest.operation(), map.name());
  EXPECT_FALSE(nearest.from_map().interpolated());
  ASSERT_FALSE(nearest.from_map().verified()) << nearest.from_map().verification();
  EXPECT_EQ(nearest.optimum().status(), "FAILED");

  query.set_on_map_failure(v1::QueryOptimumRequest::COMPUTE);
  v1::QueryOptimumResponse computed;
  const grpc::Status status = Query(s, query, &computed);
  // An optimum job computed there (the box has one at b = 0.1145, at a lower a than the cell's),
  // not the map's unverified answer again.
  ASSERT_TRUE(status.ok()) << status.error_message();
  EXPECT_NE(computed.operation(), map.name());
  EXPECT_FALSE(computed.has_from_map());
  EXPECT_EQ(computed.optimum().status(), "COMPLETED");
  EXPECT_EQ(computed.optimum().params().b(), 0.1145);
  EXPECT_LT(computed.optimum().params().a(), nearest.optimum().params().a());
}

}  // namespace
}  // namespace drillbif::server
