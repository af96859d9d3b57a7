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

// The bytes of one unary call of `method` with `request` bytes (and `authorization` metadata
// when not empty).
inline grpc::Status GenericUnary(const std::shared_ptr<grpc::Channel>& channel,
                                 const std::string& method, const std::string& request,
                                 std::string* response, const std::string& authorization = "") {
  grpc::GenericStub stub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  if (!authorization.empty()) context.AddMetadata("authorization", authorization);
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

// A server-streaming call of `method` with `request` bytes: its first message's bytes in
// *response (when one comes) and its final status (the call is cancelled after the first
// message).
inline grpc::Status GenericServerStreamFirst(const std::shared_ptr<grpc::Channel>& channel,
                                             const std::string& method, const std::string& request,
                                             std::string* response,
                                             const std::string& authorization = "") {
  grpc::GenericStub stub(channel);
  grpc::ClientContext context;
  context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
  if (!authorization.empty()) context.AddMetadata("authorization", authorization);
  grpc::CompletionQueue cq;
  std::unique_ptr<grpc::GenericClientAsyncReaderWriter> call =
      stub.PrepareCall(&context, method, &cq);
  void* tag = nullptr;
  bool ok = false;
  call->StartCall(reinterpret_cast<void*>(1));
  cq.Next(&tag, &ok);
  grpc::Slice slice(request);
  grpc::ByteBuffer in(&slice, 1);
  call->WriteLast(in, grpc::WriteOptions(), reinterpret_cast<void*>(2));
  cq.Next(&tag, &ok);
  grpc::ByteBuffer out;
  call->Read(&out, reinterpret_cast<void*>(3));
  cq.Next(&tag, &ok);
  if (ok) {
    std::vector<grpc::Slice> slices;
    if (out.Dump(&slices).ok()) {
      for (const grpc::Slice& s : slices) response->append(s.begin(), s.end());
    }
    context.TryCancel();
  }
  grpc::Status status;
  call->Finish(&status, reinterpret_cast<void*>(4));
  while (cq.Next(&tag, &ok) && tag != reinterpret_cast<void*>(4)) {
  }
  cq.Shutdown();
  while (cq.Next(&tag, &ok)) {
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
