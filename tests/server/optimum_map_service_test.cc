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

// A server of its own over `db`, and stubs.
class MapServer {
 public:
  explicit MapServer(const std::string& db) {
    ServerOptions options;
    options.grpc_port = 0;
    options.http_port = 0;
    options.db_path = db;
    options.workers = 2;
    StatusOr<std::unique_ptr<Server>> server = Server::Start(options);
    EXPECT_TRUE(server.ok()) << server.status().ToString();
    if (!server.ok()) return;
    server_ = std::move(server).value();
    auto channel = grpc::CreateChannel(server_->grpc_address(), grpc::InsecureChannelCredentials());
    jobs_ = v1::Jobs::NewStub(channel);
    operations_ = google::longrunning::Operations::NewStub(channel);
  }
  bool ok() const { return server_ != nullptr; }
  Server& server() { return *server_; }

  static std::unique_ptr<grpc::ClientContext> Context(double seconds = 60) {
    auto context = std::make_unique<grpc::ClientContext>();
    context->set_deadline(std::chrono::system_clock::now() +
                          std::chrono::milliseconds(static_cast<int>(seconds * 1000)));
    return context;
  }

  // Submits the map and waits until it is done.
  Operation RunMap() {
    v1::SubmitOptimumMapRequest submit;
    *submit.mutable_request() = MapRequest();
    Operation op;
    EXPECT_TRUE(jobs_->SubmitOptimumMap(Context().get(), submit, &op).ok());
    google::longrunning::WaitOperationRequest wait;
    wait.set_name(op.name());
    wait.mutable_timeout()->set_seconds(60);
    EXPECT_TRUE(operations_->WaitOperation(Context(90).get(), wait, &op).ok());
    return op;
  }

  grpc::Status Query(const v1::QueryOptimumRequest& q, v1::QueryOptimumResponse* response) {
    return jobs_->QueryOptimum(Context().get(), q, response);
  }

  std::unique_ptr<v1::Jobs::Stub> jobs_;
  std::unique_ptr<google::longrunning::Operations::Stub> operations_;

 private:
  std::unique_ptr<Server> server_;
};

TEST(OptimumMapService, QueriesBetweenCellsAreAnsweredFromTheMapVerified) {
  testing::TempDir dir("drillbif_map");
  MapServer s(dir.path() + "/jobs.db");
  ASSERT_TRUE(s.ok());
  const Operation map = s.RunMap();
  ASSERT_TRUE(map.done());
  ASSERT_TRUE(map.has_response()) << map.error().message();
  const auto result = testing::ResponseOf<v1::OptimumMapResult>(map);
  EXPECT_EQ(result.cells_found(), 3) << result.message();

  const int64_t runs = s.server().engine_runs();
  v1::QueryOptimumResponse answer;
  ASSERT_TRUE(s.Query(QueryAt(0.1475), &answer).ok());
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
  ASSERT_TRUE(s.Query(QueryAt(0.1475), &again).ok());
  EXPECT_EQ(again.SerializeAsString(), answer.SerializeAsString());
}

TEST(OptimumMapService, OutsideEveryMapIsNotFoundNamingTheNearestAndADeletedMapStopsAnswering) {
  testing::TempDir dir("drillbif_map");
  MapServer s(dir.path() + "/jobs.db");
  ASSERT_TRUE(s.ok());
  const Operation map = s.RunMap();
  ASSERT_TRUE(map.has_response());
  v1::QueryOptimumResponse answer;
  grpc::Status outside = s.Query(QueryAt(0.17), &answer);
  EXPECT_EQ(outside.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_THAT(outside.error_message(), HasSubstr(map.name()));
  EXPECT_THAT(outside.error_message(), HasSubstr("1 cells outside"));

  v1::QueryOptimumRequest unknown = QueryAt(0.1475);
  unknown.set_on_map_failure(static_cast<v1::QueryOptimumRequest::OnMapFailure>(7));
  grpc::Status refused = s.Query(unknown, &answer);
  EXPECT_EQ(refused.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_THAT(refused.error_message(), HasSubstr("on_map_failure"));

  v1::QueryOptimumRequest no_maps = QueryAt(0.1475);
  no_maps.set_no_maps(true);
  EXPECT_EQ(s.Query(no_maps, &answer).error_code(), grpc::StatusCode::NOT_FOUND);

  v1::QueryOptimumRequest other_margin = QueryAt(0.1475);
  other_margin.mutable_request()->set_margin(0, 0.02);
  grpc::Status other = s.Query(other_margin, &answer);
  EXPECT_EQ(other.error_code(), grpc::StatusCode::NOT_FOUND);
  EXPECT_THAT(other.error_message(), ::testing::Not(HasSubstr(map.name())));

  ASSERT_TRUE(s.Query(QueryAt(0.1475), &answer).ok());  // an answer kept in memory ...
  google::longrunning::DeleteOperationRequest del;
  del.set_name(map.name());
  google::protobuf::Empty empty;
  ASSERT_TRUE(s.operations_->DeleteOperation(MapServer::Context().get(), del, &empty).ok());
  EXPECT_EQ(s.Query(QueryAt(0.1475), &answer).error_code(), grpc::StatusCode::NOT_FOUND)
      << "... is dropped with its map";
}

TEST(OptimumMapService, ARestartedServerAnswersFromTheMapsOfItsStore) {
  testing::TempDir dir("drillbif_map");
  std::string name;
  {
    MapServer first(dir.path() + "/jobs.db");
    ASSERT_TRUE(first.ok());
    name = first.RunMap().name();
  }
  MapServer second(dir.path() + "/jobs.db");
  ASSERT_TRUE(second.ok());
  v1::QueryOptimumResponse answer;
  ASSERT_TRUE(second.Query(QueryAt(0.1525), &answer).ok());
  EXPECT_EQ(answer.operation(), name);
  EXPECT_TRUE(answer.from_map().verified()) << answer.from_map().verification();
}

// Between a cell without an optimum (b = 0.11: no stable period-1 start orbit from rest) and one
// with (b = 0.12), the nearest cell's point fails its check at b = 0.1145 (one margin from it the
// orbit is no longer stable): NEAREST_CELL answers it unverified, and COMPUTE does not get that
// answer back but runs an optimum job at b = 0.1145 instead, whose optimum lies lower in a.
TEST(OptimumMapService, AnUnverifiedAnswerIsNotKeptForACallerWhoAsksToCompute) {
  testing::TempDir dir("drillbif_map");
  MapServer s(dir.path() + "/jobs.db");
  ASSERT_TRUE(s.ok());
  v1::SubmitOptimumMapRequest submit;
  *submit.mutable_request() = testing::SmallBoxMap(0.11, 0.12, 2);
  Operation map;
  ASSERT_TRUE(s.jobs_->SubmitOptimumMap(MapServer::Context().get(), submit, &map).ok());
  google::longrunning::WaitOperationRequest wait;
  wait.set_name(map.name());
  wait.mutable_timeout()->set_seconds(60);
  ASSERT_TRUE(s.operations_->WaitOperation(MapServer::Context(90).get(), wait, &map).ok());
  ASSERT_TRUE(map.has_response()) << map.error().message();

  v1::QueryOptimumRequest query;
  *query.mutable_request() = submit.request().optimum();
  query.mutable_request()->mutable_trace()->mutable_params()->set_b(0.1145);
  v1::QueryOptimumResponse nearest;
  ASSERT_TRUE(s.Query(query, &nearest).ok());
  ASSERT_EQ(nearest.operation(), map.name());
  EXPECT_FALSE(nearest.from_map().interpolated());
  ASSERT_FALSE(nearest.from_map().verified()) << nearest.from_map().verification();
  EXPECT_EQ(nearest.optimum().status(), "FAILED");

  query.set_on_map_failure(v1::QueryOptimumRequest::COMPUTE);
  v1::QueryOptimumResponse computed;
  const grpc::Status status = s.Query(query, &computed);
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
