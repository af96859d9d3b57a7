#include "server/grpc_calls.h"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/wire_format_lite.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "server/http_text.h"

namespace drillbif::server {
namespace {

using google::protobuf::Descriptor;
using google::protobuf::FieldDescriptor;
using google::protobuf::internal::WireFormatLite;
using google::protobuf::io::CodedInputStream;

// Deeper messages are refused (protobuf's own recursion limit is 100).
constexpr int kMaxDepth = 100;

std::string Malformed(int64_t at, const char* what) {
  return "malformed protobuf bytes at byte " + std::to_string(at) + " (" + what + ")";
}

// The first problem of `bytes` as a `type` message, with the field's path below `prefix`; empty
// when the walk finds none. Checks what a protobuf parser checks that a client can get wrong:
// the wire format, and UTF-8 in string fields.
std::string FirstProblem(const Descriptor* type, std::string_view bytes, const std::string& prefix,
                         int64_t base, int depth) {
  if (depth > kMaxDepth)
    return prefix + ": nested more than " + std::to_string(kMaxDepth) + " deep";
  CodedInputStream in(reinterpret_cast<const uint8_t*>(bytes.data()),
                      static_cast<int>(bytes.size()));
  for (;;) {
    if (static_cast<size_t>(in.CurrentPosition()) == bytes.size()) return {};
    const int64_t at = base + in.CurrentPosition();
    const uint32_t tag = in.ReadTag();
    if (tag == 0) return Malformed(at, "a field number of 0, or a truncated tag");
    const FieldDescriptor* field = type->FindFieldByNumber(WireFormatLite::GetTagFieldNumber(tag));
    const std::string path = prefix + (field != nullptr ? field->name() : "(unknown field)");
    if (WireFormatLite::GetTagWireType(tag) != WireFormatLite::WIRETYPE_LENGTH_DELIMITED) {
      if (!WireFormatLite::SkipField(&in, tag)) return Malformed(at, "a truncated value");
      continue;
    }
    uint32_t length = 0;
    if (!in.ReadVarint32(&length)) return Malformed(at, "a truncated length");
    const int64_t start = base + in.CurrentPosition();
    std::string value;
    if (!in.ReadString(&value, static_cast<int>(length))) {
      return Malformed(at, "a length beyond the message");
    }
    if (field == nullptr) continue;
    if (field->type() == FieldDescriptor::TYPE_STRING &&
        FindInvalidUtf8(value) != std::string_view::npos) {
      return path + ": not valid UTF-8";
    }
    if (field->type() == FieldDescriptor::TYPE_MESSAGE) {
      std::string problem =
          FirstProblem(field->message_type(), value, path + ".", start, depth + 1);
      if (!problem.empty()) return problem;
    }
  }
}

}  // namespace

std::string DescribeParseFailure(const Descriptor* type, std::string_view bytes) {
  std::string problem = FirstProblem(type, bytes, "", 0, 0);
  if (problem.empty()) problem = "the bytes do not parse";
  return "not a valid " + type->full_name() + ": " + problem;
}

grpc::Status BoundedStatus(grpc::Status status) {
  const std::string& message = status.error_message();
  if (message.size() <= kMaxStatusMessageBytes) return status;
  size_t cut = kMaxStatusMessageBytes;
  // Back to the first byte of a character (continuation bytes are 10xxxxxx).
  while (cut > 0 && (static_cast<unsigned char>(message[cut]) & 0xC0) == 0x80) --cut;
  return grpc::Status(status.error_code(), message.substr(0, cut) + "...", status.error_details());
}

grpc::Status ParseRequest(const grpc::ByteBuffer& raw, google::protobuf::Message* message) {
  std::vector<grpc::Slice> slices;
  std::string bytes;
  if (!raw.Dump(&slices).ok()) {
    return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "the request could not be read");
  }
  for (const grpc::Slice& slice : slices) bytes.append(slice.begin(), slice.end());
  if (message->ParseFromString(bytes)) return grpc::Status::OK;
  return grpc::Status(grpc::StatusCode::INVALID_ARGUMENT,
                      DescribeParseFailure(message->GetDescriptor(), bytes));
}

int MethodIndex(std::string_view service_full_name, std::string_view name) {
  const google::protobuf::ServiceDescriptor* service =
      google::protobuf::DescriptorPool::generated_pool()->FindServiceByName(
          std::string(service_full_name));
  for (int i = 0; service != nullptr && i < service->method_count(); ++i) {
    if (service->method(i)->name() == name) return i;
  }
  std::fprintf(stderr, "drillbif: no method %s in service %s\n", std::string(name).c_str(),
               std::string(service_full_name).c_str());
  std::abort();
}

}  // namespace drillbif::server
