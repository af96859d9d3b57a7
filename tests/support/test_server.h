// A drillbif server in the test's process for service tests: started on 127.0.0.1 with free
// ports and a store in a temporary directory, with gRPC stubs, calls with a deadline and the
// token, and waiting for an operation to finish.
#ifndef DRILLBIF_TESTS_SUPPORT_TEST_SERVER_H_
#define DRILLBIF_TESTS_SUPPORT_TEST_SERVER_H_

#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <chrono>
#include <memory>
#include <string>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "server/server.h"
#include "support/operations.h"
#include "support/temp_dir.h"

namespace drillbif::testing {

class TestServer {
 public:
  // Starts a server with `options`, whose ports, host and store path are replaced (the store:
  // `db` when given, e.g. to start a server again on an earlier one's file; else a file in a
  // temporary directory); ok() tells whether it started (a test failure otherwise).
  explicit TestServer(server::ServerOptions options, const std::string& name = "drillbif_server",
                      const std::string& db = "")
      : dir_(name) {
    options.host = "127.0.0.1";
    options.grpc_port = 0;
    options.http_port = 0;
    options.db_path = db.empty() ? dir_.path() + "/jobs.db" : db;
    StatusOr<std::unique_ptr<server::Server>> started = server::Server::Start(options);
    EXPECT_TRUE(started.ok()) << started.status().ToString();
    if (!started.ok()) return;
    server_ = std::move(started).value();
    channel_ = grpc::CreateChannel(server_->grpc_address(), grpc::InsecureChannelCredentials());
    jobs_ = v1::Jobs::NewStub(channel_);
    operations_ = google::longrunning::Operations::NewStub(channel_);
  }

  bool ok() const { return server_ != nullptr; }
  server::Server& server() { return *server_; }
  const std::string& dir() const { return dir_.path(); }
  v1::Jobs::Stub& jobs() { return *jobs_; }
  google::longrunning::Operations::Stub& operations() { return *operations_; }

  // A context with a deadline and, when `token` is not empty, the bearer token.
  static std::unique_ptr<grpc::ClientContext> Context(const std::string& token = "",
                                                      double seconds = 30) {
    auto context = std::make_unique<grpc::ClientContext>();
    context->set_deadline(std::chrono::system_clock::now() +
                          std::chrono::milliseconds(static_cast<int>(seconds * 1000)));
    if (!token.empty()) context->AddMetadata("authorization", "Bearer " + token);
    return context;
  }

  // The operation once done (WaitOperation, repeated), or as it is after `seconds`.
  google::longrunning::Operation WaitDone(const std::string& name, const std::string& token = "",
                                          double seconds = 60) {
    const auto end = std::chrono::steady_clock::now() +
                     std::chrono::milliseconds(static_cast<int>(seconds * 1000));
    google::longrunning::Operation op;
    while (std::chrono::steady_clock::now() < end) {
      google::longrunning::WaitOperationRequest request;
      request.set_name(name);
      request.mutable_timeout()->set_seconds(1);
      auto context = Context(token, 5);
      const grpc::Status s = operations_->WaitOperation(context.get(), request, &op);
      EXPECT_TRUE(s.ok()) << s.error_message();
      if (!s.ok() || op.done()) return op;
    }
    return op;
  }

 private:
  TempDir dir_;
  std::unique_ptr<server::Server> server_;
  std::shared_ptr<grpc::Channel> channel_;
  std::unique_ptr<v1::Jobs::Stub> jobs_;
  std::unique_ptr<google::longrunning::Operations::Stub> operations_;
};

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_TEST_SERVER_H_
