#include "server/stored_results.h"

#include <google/protobuf/reflection.h>

#include <algorithm>
#include <limits>
#include <memory>
#include <utility>
#include <vector>

#include "drillbif/common/checked.h"
#include "jobs/job_cost.h"
#include "jobs/result_pages.h"

namespace drillbif::server {
namespace {

using google::protobuf::FieldDescriptor;
using google::protobuf::Message;

// The one paged field of `kind` that `items` holds items of; null when it holds none, or items
// of several, or other fields.
const FieldDescriptor* OnlyPagedField(const jobs::JobKindSpec& kind, const Message& items) {
  std::vector<const FieldDescriptor*> set;
  items.GetReflection()->ListFields(items, &set);
  if (set.size() != 1) return nullptr;
  const FieldDescriptor* field = set.front();
  for (const std::string& name : kind.paged_fields) {
    if (field->name() == name) return field;
  }
  return nullptr;
}

// Keeps the items [lo, hi) of the one repeated field `field` of `part`.
void KeepRange(const FieldDescriptor* field, int64_t lo, int64_t hi, Message* part) {
  auto* items = part->GetReflection()->MutableRepeatedPtrField<Message>(part, field);
  const int64_t n = items->size();
  if (hi < n) items->DeleteSubrange(static_cast<int>(hi), static_cast<int>(n - hi));
  if (lo > 0) items->DeleteSubrange(0, static_cast<int>(lo));
}

}  // namespace

ResultWriter::ResultWriter(JobStore* store, const JobRecord& job, const jobs::JobKindSpec& kind,
                           int64_t max_result_bytes, int64_t chunk_bytes)
    : store_(store),
      id_(job.id),
      run_(job.run),
      kind_(kind),
      max_result_bytes_(max_result_bytes),
      chunk_bytes_(chunk_bytes) {}

Status ResultWriter::Fail(Status status) {
  if (error_.ok()) error_ = status;
  return status;
}

Status ResultWriter::Append(const Message& items, int64_t count) {
  if (!error_.ok()) return error_;
  const FieldDescriptor* field = OnlyPagedField(kind_, items);
  if (field == nullptr || count < 1 || items.GetReflection()->FieldSize(items, field) != count) {
    return Fail(Internal("a " + kind_.name + " run streamed items that are not " +
                         std::to_string(count) + " items of one paged field"));
  }
  return Add(field, items.SerializeAsString(), count);
}

Status ResultWriter::Add(const FieldDescriptor* field, std::string bytes, int64_t count) {
  if (!error_.ok()) return error_;
  const int64_t size = static_cast<int64_t>(bytes.size());
  if (max_result_bytes_ > 0 && bytes_ + size > max_result_bytes_) {
    return Fail(ResourceExhausted(
        "the result reached the limit of " +
        jobs::HumanBytes(static_cast<double>(max_result_bytes_)) + " (max_result_bytes of " +
        kind_.name + " jobs) after " + std::to_string(items_) +
        " items; ask for less (fewer periods, values, steps or outputs, or a smaller box)"));
  }
  if (buffered_field_ != field && !buffer_.empty()) DRILLBIF_RETURN_IF_ERROR(Flush());
  buffered_field_ = field;
  buffer_ += bytes;
  buffered_items_ += count;
  items_ += count;
  bytes_ += size;
  if (static_cast<int64_t>(buffer_.size()) >= chunk_bytes_) return Flush();
  return Status::Ok();
}

Status ResultWriter::Flush() {
  if (!error_.ok()) return error_;
  if (buffered_items_ == 0) return Status::Ok();
  if (Status s = store_->AppendResultChunk(id_, run_, written_items_, buffered_items_, buffer_);
      !s.ok()) {
    return Fail(s);
  }
  written_items_ += buffered_items_;
  buffered_items_ = 0;
  buffer_.clear();
  return Status::Ok();
}

Status ResultWriter::MoveItemsOf(Message* result) {
  const auto* reflection = result->GetReflection();
  for (const std::string& name : kind_.paged_fields) {
    const FieldDescriptor* field = result->GetDescriptor()->FindFieldByName(name);
    const int n = reflection->FieldSize(*result, field);
    std::unique_ptr<Message> part = kind_.NewResult();
    int64_t batch_items = 0, batch_bytes = 0;
    for (int i = 0; i < n; ++i) {
      const Message& item = reflection->GetRepeatedMessage(*result, field, i);
      part->GetReflection()->AddMessage(part.get(), field)->CopyFrom(item);
      ++batch_items;
      batch_bytes += static_cast<int64_t>(item.ByteSizeLong()) + 8;  // + tag and length
      if (batch_bytes >= chunk_bytes_ || i + 1 == n) {
        DRILLBIF_RETURN_IF_ERROR(Add(field, part->SerializeAsString(), batch_items));
        part->Clear();
        batch_items = batch_bytes = 0;
      }
    }
    reflection->ClearField(result, field);
  }
  return Status::Ok();
}

Status ReadResultPage(JobStore& store, const jobs::JobKindSpec& kind, const std::string& id,
                      int page_size, const std::string& page_token, const PageOptions& options,
                      v1::GetResultResponse* response) {
  if (page_size < 0 || page_size > jobs::kMaxResultPageSize) {
    return InvalidArgument("page_size: must be in [0, " + std::to_string(jobs::kMaxResultPageSize) +
                           "], got " + std::to_string(page_size));
  }
  DRILLBIF_ASSIGN_OR_RETURN(const int64_t begin, jobs::ParsePageToken(page_token));
  DRILLBIF_ASSIGN_OR_RETURN(const ResultInfo info, store.GetResultInfo(id));
  Message* result = jobs::MutableResultOf(kind, response);
  if (!result->ParseFromString(info.summary)) {
    return Internal("the stored result is not a valid " + result->GetTypeName());
  }
  // A result stored whole (nothing streamed) holds its items in the summary.
  const int64_t held = kind.ItemsOf(*result);
  const int64_t total = held + info.total_items;
  response->set_total_points(total);
  if (begin > total) {
    return InvalidArgument("page_token: beyond the end of the result (" + std::to_string(total) +
                           " items)");
  }
  if (page_size == 0 && info.total_bytes <= options.max_whole_bytes) {
    if (info.total_items == 0) return Status::Ok();
    DRILLBIF_ASSIGN_OR_RETURN(const std::string whole, store.GetResult(id));
    if (!result->ParseFromString(whole)) {
      return Internal("the stored result is not a valid " + result->GetTypeName());
    }
    return Status::Ok();
  }
  const int64_t size = page_size == 0 ? std::numeric_limits<int64_t>::max() : page_size;
  int64_t end = std::min(total, CheckedAdd(begin, size).value_or(total));
  if (info.total_items == 0) {
    jobs::KeepItems(kind, begin, end, result);
  } else {
    DRILLBIF_ASSIGN_OR_RETURN(const std::vector<ResultChunk> chunks,
                              store.ReadResultChunks(id, begin, options.max_page_bytes));
    int64_t reached = begin;
    for (const ResultChunk& chunk : chunks) {
      if (reached >= end) break;
      std::unique_ptr<Message> part = kind.NewResult();
      if (!part->ParseFromString(chunk.bytes)) {
        return Internal("a stored result chunk is not a valid " + part->GetTypeName());
      }
      const FieldDescriptor* field = OnlyPagedField(kind, *part);
      if (field == nullptr) return Internal("a stored result chunk holds no single paged field");
      const int64_t lo = std::max(begin, chunk.first_item) - chunk.first_item;
      const int64_t hi = std::min(end, chunk.first_item + chunk.item_count) - chunk.first_item;
      KeepRange(field, lo, hi, part.get());
      result->MergeFrom(*part);
      reached = chunk.first_item + hi;
    }
    end = reached;
    if (begin > 0) {
      for (const std::string& name : kind.first_page_fields) {
        result->GetReflection()->ClearField(result, result->GetDescriptor()->FindFieldByName(name));
      }
    }
  }
  if (end < total) response->set_next_page_token(jobs::PageToken(end));
  return Status::Ok();
}

StatusOr<std::string> ResultForOperation(JobStore& store, const std::string& id,
                                         int64_t max_whole_bytes, bool* summary_only) {
  DRILLBIF_ASSIGN_OR_RETURN(ResultInfo info, store.GetResultInfo(id));
  *summary_only = info.total_bytes > max_whole_bytes;
  if (*summary_only || info.total_items == 0) return std::move(info.summary);
  return store.GetResult(id);
}

}  // namespace drillbif::server
