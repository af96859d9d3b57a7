// A sweep's independent pieces (both directions; each chunk of a direction) run as child jobs of
// kind "sweep_part" over every worker: the fanned-out sweep's result equals the local run's value
// by value, bit for bit; cancelling the sweep ends its parts; clients can neither submit a part
// nor name a piece. A real server on 127.0.0.1 (port 0) over a SQLite file, with two workers.
#include <gtest/gtest.h>

#include <chrono>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "jobs/sweep_job.h"
#include "server/server.h"
#include "support/operations.h"
#include "support/small_requests.h"
#include "support/test_server.h"

// Last: httplib.h includes <resolv.h>, whose macro _res breaks Eigen's headers (a parameter name)
// when they come after it.
#include <httplib.h>

namespace drillbif::server {
namespace {

using drillbif::testing::MetadataOf;
using drillbif::testing::TestServer;
using google::longrunning::Operation;

ServerOptions TwoWorkers() {
  ServerOptions options;
  options.workers = 2;
  return options;
}

// A BOTH sweep of b over [0.08, 0.2], across the period doubling at b = 0.110 so that the values
// differ in more than roundoff: 8 values a direction of 40 + 3 periods, a fraction of a second.
v1::SweepRequest BothSweep(int chunks) {
  v1::SweepRequest sweep = testing::SmallSweep(0.08, 8);
  sweep.set_direction(v1::SweepRequest::BOTH);
  sweep.set_transient_periods(40);
  sweep.set_sample_periods(3);
  sweep.set_chunks(chunks);
  return sweep;
}

std::string Submit(TestServer& s, const v1::SweepRequest& sweep) {
  v1::SubmitSweepRequest submit;
  *submit.mutable_request() = sweep;
  Operation op;
  const grpc::Status status = s.jobs().SubmitSweep(TestServer::Context().get(), submit, &op);
  EXPECT_TRUE(status.ok()) << status.error_message();
  return op.name();
}

std::string IdOf(const std::string& operation) {
  return operation.substr(std::string("operations/").size());
}

// The job's children of kind "sweep_part", in every state.
std::vector<JobRecord> PartsOf(TestServer& s, const std::string& id) {
  ListRequest list;
  list.parent = id;
  list.kind = jobs::kSweepPartKind;
  list.page_size = 1000;
  StatusOr<ListResult> page = s.server().store().List(list);
  EXPECT_TRUE(page.ok()) << page.status().ToString();
  return page.ok() ? page->jobs : std::vector<JobRecord>{};
}

// The sweep through the server equals RunSweep of the same request in this process (on its own
// threads), value by value: every field, doubles by their bits (serialized bytes). Only the
// wall time differs. Its pieces ran as `pieces` SUCCEEDED children.
void ExpectFannedOutEqualsLocal(int chunks, int pieces) {
  TestServer s(TwoWorkers(), "drillbif_sweep_fan_out");
  ASSERT_TRUE(s.ok());
  const v1::SweepRequest sweep = BothSweep(chunks);
  const std::string name = Submit(s, sweep);
  const Operation op = s.WaitDone(name);
  ASSERT_TRUE(op.done());
  ASSERT_EQ(MetadataOf(op).state(), v1::SUCCEEDED) << op.error().message();
  v1::GetResultRequest get;
  get.set_name(name);
  v1::GetResultResponse response;
  const grpc::Status got = s.jobs().GetResult(TestServer::Context().get(), get, &response);
  ASSERT_TRUE(got.ok()) << got.error_message();
  ASSERT_TRUE(response.next_page_token().empty()) << "a small result comes whole";
  const v1::SweepResult& remote = response.sweep();

  const StatusOr<v1::SweepResult> local = jobs::RunSweep(sweep);
  ASSERT_TRUE(local.ok()) << local.status().ToString();
  EXPECT_EQ(remote.status(), local->status());
  EXPECT_EQ(remote.message(), local->message());
  EXPECT_EQ(remote.periods_total(), local->periods_total());
  EXPECT_EQ(remote.events_total(), local->events_total());
  EXPECT_EQ(remote.engine_version(), local->engine_version());
  ASSERT_EQ(remote.up_size(), 8);
  ASSERT_EQ(remote.up_size(), local->up_size());
  ASSERT_EQ(remote.down_size(), local->down_size());
  for (int i = 0; i < remote.up_size(); ++i) {
    EXPECT_EQ(remote.up(i).SerializeAsString(), local->up(i).SerializeAsString()) << "up " << i;
    EXPECT_EQ(remote.down(i).SerializeAsString(), local->down(i).SerializeAsString())
        << "down " << i;
  }
  // Everything but the wall time, at once (the checks above say where a difference is).
  v1::SweepResult a = remote, b = *local;
  a.clear_wall_seconds();
  b.clear_wall_seconds();
  EXPECT_EQ(a.SerializeAsString(), b.SerializeAsString());

  const std::vector<JobRecord> parts = PartsOf(s, IdOf(name));
  EXPECT_EQ(parts.size(), static_cast<size_t>(pieces));
  for (const JobRecord& part : parts) EXPECT_EQ(part.state, JobState::kSucceeded) << part.id;
}

TEST(SweepFanOut, BothDirectionsRunAsTwoChildrenAndEqualTheLocalRunBitwise) {
  ExpectFannedOutEqualsLocal(/*chunks=*/1, /*pieces=*/2);
}

TEST(SweepFanOut, TwoChunksADirectionRunAsFourChildrenAndEqualTheLocalRunBitwise) {
  ExpectFannedOutEqualsLocal(/*chunks=*/2, /*pieces=*/4);
}

// A sweep of one piece (one direction, one chunk) runs on its own job: no child.
TEST(SweepFanOut, ASweepOfOnePieceRunsWithoutChildren) {
  TestServer s(TwoWorkers(), "drillbif_sweep_one_piece");
  ASSERT_TRUE(s.ok());
  const std::string name = Submit(s, testing::SmallSweep(0.1, 4));
  const Operation op = s.WaitDone(name);
  ASSERT_EQ(MetadataOf(op).state(), v1::SUCCEEDED) << op.error().message();
  EXPECT_TRUE(PartsOf(s, IdOf(name)).empty());
}

// One worker over a store no other process shares (no leases) has no one to hand a piece to:
// the sweep runs on its own threads, both directions at once, without children.
TEST(SweepFanOut, OneWorkerOfAPrivateStoreSweepsOnItsOwnThreads) {
  ServerOptions options;
  options.workers = 1;
  TestServer s(options, "drillbif_sweep_one_worker");
  ASSERT_TRUE(s.ok());
  const std::string name = Submit(s, BothSweep(1));
  const Operation op = s.WaitDone(name);
  ASSERT_EQ(MetadataOf(op).state(), v1::SUCCEEDED) << op.error().message();
  EXPECT_TRUE(PartsOf(s, IdOf(name)).empty());
}

// Cancelling a fanned-out sweep while its parts run ends it CANCELLED, and no part is left
// running or queued: the parts running on the other worker stop (the store cancels a parent's
// unfinished children when it leaves RUNNING), the queued ones never start.
TEST(SweepFanOut, CancellingTheSweepEndsItCancelledWithNoPartLeft) {
  TestServer s(TwoWorkers(), "drillbif_sweep_cancel");
  ASSERT_TRUE(s.ok());
  // Four parts of minutes each (LongSweep's 100000 values of 501 periods, split in two per
  // direction): two run, two wait.
  v1::SweepRequest sweep = testing::LongSweep();
  sweep.set_direction(v1::SweepRequest::BOTH);
  sweep.set_chunks(2);
  const std::string name = Submit(s, sweep);
  const std::string id = IdOf(name);
  const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds(30);
  auto running = [&] {
    int n = 0;
    for (const JobRecord& part : PartsOf(s, id)) n += part.state == JobState::kRunning ? 1 : 0;
    return n;
  };
  while (running() < 2 && std::chrono::steady_clock::now() < deadline) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_EQ(running(), 2) << "both workers run a part (the parent runs one itself)";
  ASSERT_EQ(PartsOf(s, id).size(), 4u);

  google::longrunning::CancelOperationRequest cancel;
  cancel.set_name(name);
  google::protobuf::Empty empty;
  const grpc::Status cancelled =
      s.operations().CancelOperation(TestServer::Context().get(), cancel, &empty);
  ASSERT_TRUE(cancelled.ok()) << cancelled.error_message();
  const Operation op = s.WaitDone(name, "", 30);
  ASSERT_TRUE(op.done());
  EXPECT_EQ(MetadataOf(op).state(), v1::CANCELLED) << op.ShortDebugString().substr(0, 500);
  EXPECT_EQ(op.error().code(), static_cast<int>(grpc::StatusCode::CANCELLED));

  // A part running elsewhere records its end within its simulation's poll (~5 ms) and the
  // store's write; 10 s is a loaded machine's margin.
  const auto settle = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  std::vector<JobRecord> parts;
  auto open = [&] {
    parts = PartsOf(s, id);
    int n = 0;
    for (const JobRecord& part : parts) n += IsFinished(part.state) ? 0 : 1;
    return n;
  };
  while (open() > 0 && std::chrono::steady_clock::now() < settle) {
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  ASSERT_EQ(parts.size(), 4u);
  for (const JobRecord& part : parts) {
    EXPECT_EQ(part.state, JobState::kCancelled) << part.id;
  }
}

// Clients have no way to a part: "sweep_part" is no kind of theirs (a list filtered by it is
// refused naming it; there is no route to submit one), and a sweep request naming a piece is
// refused naming the field (the piece lives in the server's SweepPartRequest only).
TEST(SweepFanOut, ClientsCanNeitherSubmitAPartNorNameAPiece) {
  TestServer s(TwoWorkers(), "drillbif_sweep_part_refused");
  ASSERT_TRUE(s.ok());
  google::longrunning::ListOperationsRequest list;
  list.set_name("operations");
  list.set_filter("kind=sweep_part");
  google::longrunning::ListOperationsResponse listed;
  const grpc::Status by_kind =
      s.operations().ListOperations(TestServer::Context().get(), list, &listed);
  EXPECT_EQ(by_kind.error_code(), grpc::StatusCode::INVALID_ARGUMENT);
  EXPECT_NE(by_kind.error_message().find("sweep_part"), std::string::npos)
      << by_kind.error_message();

  httplib::Client http("127.0.0.1", s.server().http_port());
  http.set_read_timeout(std::chrono::seconds(30));
  const httplib::Result submit_part = http.Post(
      "/v1/jobs:sweep_part", R"({"request": {"sweep": {"param": "b", "min": 0.1, "max": 0.2}}})",
      "application/json");
  ASSERT_TRUE(submit_part) << httplib::to_string(submit_part.error());
  EXPECT_EQ(submit_part->status, 404) << submit_part->body;

  const httplib::Result with_piece = http.Post(
      "/v1/jobs:sweep",
      R"({"request": {"param": "b", "min": 0.1, "max": 0.2, "direction": "BOTH", "piece": 1}})",
      "application/json");
  ASSERT_TRUE(with_piece) << httplib::to_string(with_piece.error());
  EXPECT_EQ(with_piece->status, 400) << with_piece->body;
  EXPECT_NE(with_piece->body.find("INVALID_ARGUMENT"), std::string::npos) << with_piece->body;
  EXPECT_NE(with_piece->body.find("piece"), std::string::npos) << with_piece->body;
}

}  // namespace
}  // namespace drillbif::server
