// The gRPC services' calls served from raw bytes. gRPC's generated handlers parse a request before
// the service sees it, and answer a request that does not parse (invalid UTF-8 in a string field,
// a malformed message) with UNIMPLEMENTED and an empty message. The services therefore register
// every method as a raw callback method (grpc::Service::MarkMethodRawCallback) and parse the
// request themselves: bytes that do not parse give INVALID_ARGUMENT naming the field and the
// problem (DescribeParseFailure), and the response is serialized when the call finishes.
#ifndef DRILLBIF_SERVER_GRPC_CALLS_H_
#define DRILLBIF_SERVER_GRPC_CALLS_H_

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>
#include <grpcpp/grpcpp.h>
#include <grpcpp/impl/codegen/server_callback_handlers.h>

#include <functional>
#include <string>
#include <string_view>

namespace drillbif::server {

// Why `bytes` do not parse as a `type` message, naming the field where it can: "request.param:
// not valid UTF-8" or "malformed protobuf bytes at byte 17 (a length beyond the message)".
std::string DescribeParseFailure(const google::protobuf::Descriptor* type, std::string_view bytes);

// Parses a call's raw request into `message`; INVALID_ARGUMENT with DescribeParseFailure's reason
// when it does not parse.
grpc::Status ParseRequest(const grpc::ByteBuffer& raw, google::protobuf::Message* message);

// Longest status message sent, in bytes. gRPC sends the message percent-encoded in the trailers,
// which a client refuses beyond its metadata limit (8 KiB by default) with RESOURCE_EXHAUSTED
// "received initial metadata size exceeds limit", losing the code and the message: a message that
// echoed a 1 MB field did. 1024 bytes stay under that limit even when every byte is encoded
// (3 bytes each) and leave room for the other headers.
inline constexpr size_t kMaxStatusMessageBytes = 1024;

// `status` with its message cut after kMaxStatusMessageBytes (on a UTF-8 character boundary)
// and "..." appended when it was longer.
grpc::Status BoundedStatus(grpc::Status status);

// One unary rpc served from raw bytes: the request parsed (ParseRequest) and the response
// serialized into gRPC's buffer when the call finishes OK. Handlers end every call with Finish,
// exactly once, from any thread; it deletes the call.
template <typename Request, typename Response>
class UnaryCall {
 public:
  UnaryCall(grpc::CallbackServerContext* context, grpc::ByteBuffer* out)
      : context_(context), reactor_(context->DefaultReactor()), out_(out) {}
  UnaryCall(const UnaryCall&) = delete;
  UnaryCall& operator=(const UnaryCall&) = delete;

  grpc::CallbackServerContext* context() const { return context_; }
  grpc::ServerUnaryReactor* reactor() const { return reactor_; }
  const Request& request() const { return request_; }
  Request* mutable_request() { return &request_; }
  Response* response() { return &response_; }

  void Finish(grpc::Status status) {
    if (status.ok()) {
      const std::string bytes = response_.SerializeAsString();
      grpc::Slice slice(bytes);
      *out_ = grpc::ByteBuffer(&slice, 1);
    }
    grpc::ServerUnaryReactor* reactor = reactor_;
    delete this;
    reactor->Finish(BoundedStatus(std::move(status)));
  }

 private:
  grpc::CallbackServerContext* const context_;
  grpc::ServerUnaryReactor* const reactor_;
  grpc::ByteBuffer* const out_;
  Request request_;
  Response response_;
};

// The index of method `name` of the service `service_full_name` ("drillbif.v1.Jobs") in the
// order gRPC registers methods in, for MarkMethodRawCallback. Aborts when there is no such
// method: the names are the services' own, fixed in the code.
int MethodIndex(std::string_view service_full_name, std::string_view name);

// The raw callback handler of one unary method: each call becomes a `Call` (a UnaryCall) whose
// request is parsed from the raw bytes; one that does not parse is finished with ParseRequest's
// INVALID_ARGUMENT, any other is given to `handle`, which finishes it. For
// grpc::Service::MarkMethodRawCallback, which takes ownership of the handler.
template <typename Call>
grpc::internal::MethodHandler* RawUnaryHandler(std::function<void(Call*)> handle) {
  return new grpc::internal::CallbackUnaryHandler<grpc::ByteBuffer, grpc::ByteBuffer>(
      [handle = std::move(handle)](grpc::CallbackServerContext* context, const grpc::ByteBuffer* in,
                                   grpc::ByteBuffer* out) {
        auto* call = new Call(context, out);
        grpc::ServerUnaryReactor* reactor = call->reactor();
        if (grpc::Status s = ParseRequest(*in, call->mutable_request()); !s.ok()) {
          call->Finish(std::move(s));
        } else {
          handle(call);
        }
        return reactor;
      });
}

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_GRPC_CALLS_H_
