#include "jobs/result_pages.h"

#include <google/protobuf/reflection.h>

#include <algorithm>
#include <charconv>

#include "drillbif/common/checked.h"

namespace drillbif::jobs {

using google::protobuf::FieldDescriptor;
using google::protobuf::Message;

std::string PageToken(int64_t offset) {
  // Appended rather than "o" + ...: GCC 12 warns (-Wrestrict) of an overlap that cannot happen
  // in the inlined operator+.
  std::string token = "o";
  token += std::to_string(offset);
  return token;
}

StatusOr<int64_t> ParsePageToken(std::string_view token) {
  if (token.empty()) return int64_t{0};
  int64_t offset = -1;
  if (token[0] == 'o') {
    const char* begin = token.data() + 1;
    const char* end = token.data() + token.size();
    auto [ptr, ec] = std::from_chars(begin, end, offset);
    if (ec != std::errc() || ptr != end || offset < 0) offset = -1;
  }
  if (offset < 0) {
    return InvalidArgument("page_token: malformed token '" + std::string(token.substr(0, 64)) +
                           "'");
  }
  return offset;
}

void KeepRepeatedRange(const FieldDescriptor* field, int64_t lo, int64_t hi, Message* message) {
  // Reflection's element swaps and RemoveLast: each kept item moved to its place, the rest
  // removed from the end.
  const auto* reflection = message->GetReflection();
  const int64_t n = reflection->FieldSize(*message, field);
  hi = std::clamp<int64_t>(hi, 0, n);
  lo = std::clamp<int64_t>(lo, 0, hi);
  if (lo > 0) {
    for (int64_t i = lo; i < hi; ++i) {
      reflection->SwapElements(message, field, static_cast<int>(i - lo), static_cast<int>(i));
    }
  }
  for (int64_t i = hi - lo; i < n; ++i) reflection->RemoveLast(message, field);
}

void KeepItems(const JobKindSpec& kind, int64_t begin, int64_t end, Message* result) {
  const auto* reflection = result->GetReflection();
  int64_t first = 0;  // index of the current field's first item in the sequence
  for (const std::string& name : kind.paged_fields) {
    const FieldDescriptor* field = result->GetDescriptor()->FindFieldByName(name);
    const int64_t n = reflection->FieldSize(*result, field);
    // This field's items kept: [begin, end) in its own indices, clamped to its items.
    KeepRepeatedRange(field, begin - first, end - first, result);
    first += n;
  }
  if (begin > 0) {
    for (const std::string& name : kind.first_page_fields) {
      reflection->ClearField(result, result->GetDescriptor()->FindFieldByName(name));
    }
  }
}

Message* MutableResultOf(const JobKindSpec& kind, v1::GetResultResponse* response) {
  // The member of the `result` oneof of the kind's result type.
  const google::protobuf::OneofDescriptor* oneof =
      response->GetDescriptor()->FindOneofByName("result");
  for (int i = 0; i < oneof->field_count(); ++i) {
    const FieldDescriptor* field = oneof->field(i);
    if (field->message_type() == kind.result_type) {
      return response->GetReflection()->MutableMessage(response, field);
    }
  }
  return nullptr;
}

Status PageResult(const JobKindSpec& kind, std::string_view result_bytes, int page_size,
                  std::string_view page_token, v1::GetResultResponse* response) {
  if (page_size < 0 || page_size > kMaxResultPageSize) {
    return InvalidArgument("page_size: must be in [0, " + std::to_string(kMaxResultPageSize) +
                           "], got " + std::to_string(page_size));
  }
  DRILLBIF_ASSIGN_OR_RETURN(const int64_t begin, ParsePageToken(page_token));
  Message* result = MutableResultOf(kind, response);
  if (!result->ParseFromArray(result_bytes.data(), static_cast<int>(result_bytes.size()))) {
    return Internal("the stored result is not a valid " + result->GetTypeName());
  }
  const int64_t total = kind.ItemsOf(*result);
  response->set_total_points(total);
  if (page_size == 0 || kind.paged_fields.empty()) return Status::Ok();
  const int64_t end = CheckedAdd(begin, int64_t{page_size}).value_or(total);
  KeepItems(kind, begin, end, result);
  if (end < total) response->set_next_page_token(PageToken(end));
  return Status::Ok();
}

}  // namespace drillbif::jobs
