// Unary calls through gRPC's generic stub, for services whose protos the tests do not compile
// (health, reflection), and the health status read that way.
#ifndef DRILLBIF_TESTS_SUPPORT_GENERIC_CALL_H_
#define DRILLBIF_TESTS_SUPPORT_GENERIC_CALL_H_

#include <grpcpp/generic/generic_stub.h>
#include <grpcpp/grpcpp.h>

#include <chrono>
#include <future>
#include <memory>
#include <string>
#include <vector>

namespace drillbif::testing {

// The bytes of one unary call of `method` with `request` bytes.
inline grpc::Status GenericUnary(const std::shared_ptr<grpc::Channel>& channel,
                                 const std::string& method, const std::string& request,
                                 std::string* response) {
  grpc::GenericStub stub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  grpc::Slice slice(request);
  grpc::ByteBuffer in(&slice, 1);
  grpc::ByteBuffer out;
  std::promise<grpc::Status> done;
  stub.UnaryCall(&context, method, grpc::StubOptions(), &in, &out,
                 [&done](grpc::Status s) { done.set_value(std::move(s)); });
  grpc::Status status = done.get_future().get();
  std::vector<grpc::Slice> slices;
  if (status.ok() && out.Dump(&slices).ok()) {
    for (const grpc::Slice& s : slices) response->append(s.begin(), s.end());
  }
  return status;
}

// grpc.health.v1 Check of the whole server: 1 SERVING, 2 NOT_SERVING, -1 when the call fails.
// (HealthCheckRequest{service: ""} is empty; the response's status is field 1, a varint.)
inline int HealthStatus(const std::shared_ptr<grpc::Channel>& channel) {
  std::string response;
  if (!GenericUnary(channel, "/grpc.health.v1.Health/Check", "", &response).ok()) return -1;
  if (response.size() == 2 && response[0] == '\x08') return response[1];
  return response.empty() ? 0 : -1;  // UNKNOWN (0) is the empty message
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_GENERIC_CALL_H_
