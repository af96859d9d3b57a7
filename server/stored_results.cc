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

// The index in kind.paged_fields of the one field that `items` holds items of; -1 when it holds
// none, or items of several, or other fields.
int OnlyPagedField(const jobs::JobKindSpec& kind, const Message& items) {
  std::vector<const FieldDescriptor*> set;
  items.GetReflection()->ListFields(items, &set);
  if (set.size() != 1) return -1;
  for (size_t i = 0; i < kind.paged_fields.size(); ++i) {
    if (set.front()->name() == kind.paged_fields[i]) return static_cast<int>(i);
  }
  return -1;
}

const FieldDescriptor* PagedField(const jobs::JobKindSpec& kind, int stream) {
  return kind.result_type->FindFieldByName(kind.paged_fields[static_cast<size_t>(stream)]);
}

}  // namespace

ResultWriter::ResultWriter(JobStore* store, const JobRecord& job, const jobs::JobKindSpec& kind,
                           int64_t max_result_bytes, int64_t chunk_bytes)
    : store_(store),
      id_(job.id),
      run_(job.run),
      kind_(kind),
      max_result_bytes_(max_result_bytes),
      chunk_bytes_(chunk_bytes),
      streams_(kind.paged_fields.size()) {}

Status ResultWriter::Fail(Status status) {
  if (error_.ok()) error_ = status;
  return status;
}

Status ResultWriter::Append(const Message& items, int64_t count) {
  if (!error_.ok()) return error_;
  const int stream = OnlyPagedField(kind_, items);
  if (stream < 0 || count < 1 ||
      items.GetReflection()->FieldSize(items, PagedField(kind_, stream)) != count) {
    return Fail(Internal("a " + kind_.name + " run streamed items that are not " +
                         std::to_string(count) + " items of one paged field"));
  }
  return Add(stream, items.SerializeAsString(), count);
}

Status ResultWriter::Add(int stream, std::string bytes, int64_t count) {
  if (!error_.ok()) return error_;
  const int64_t size = static_cast<int64_t>(bytes.size());
  if (max_result_bytes_ > 0 && bytes_ + size > max_result_bytes_) {
    return Fail(ResourceExhausted(
        "the result reached the limit of " +
        jobs::HumanBytes(static_cast<double>(max_result_bytes_)) + " (max_result_bytes of " +
        kind_.name + " jobs) after " + std::to_string(items_) +
        " items; ask for less (fewer periods, values, steps or outputs, or a smaller box)"));
  }
  Stream& s = streams_[static_cast<size_t>(stream)];
  s.buffer += bytes;
  s.buffered_items += count;
  items_ += count;
  bytes_ += size;
  if (static_cast<int64_t>(s.buffer.size()) >= chunk_bytes_) return FlushStream(stream);
  return Status::Ok();
}

Status ResultWriter::FlushStream(int stream) {
  Stream& s = streams_[static_cast<size_t>(stream)];
  if (s.buffered_items == 0) return Status::Ok();
  if (Status status =
          store_->AppendResultChunk(id_, run_, stream, s.written_items, s.buffered_items, s.buffer);
      !status.ok()) {
    return Fail(status);
  }
  s.written_items += s.buffered_items;
  s.buffered_items = 0;
  s.buffer.clear();
  return Status::Ok();
}

Status ResultWriter::Flush() {
  if (!error_.ok()) return error_;
  for (size_t i = 0; i < streams_.size(); ++i) {
    DRILLBIF_RETURN_IF_ERROR(FlushStream(static_cast<int>(i)));
  }
  return Status::Ok();
}

Status ResultWriter::MoveItemsOf(Message* result) {
  const auto* reflection = result->GetReflection();
  for (size_t stream = 0; stream < kind_.paged_fields.size(); ++stream) {
    const FieldDescriptor* field = PagedField(kind_, static_cast<int>(stream));
    const int n = reflection->FieldSize(*result, field);
    std::unique_ptr<Message> part = kind_.NewResult();
    int64_t batch_items = 0, batch_bytes = 0;
    for (int i = 0; i < n; ++i) {
      const Message& item = reflection->GetRepeatedMessage(*result, field, i);
      part->GetReflection()->AddMessage(part.get(), field)->CopyFrom(item);
      ++batch_items;
      batch_bytes += static_cast<int64_t>(item.ByteSizeLong()) + 8;  // + tag and length
      if (batch_bytes >= chunk_bytes_ || i + 1 == n) {
        DRILLBIF_RETURN_IF_ERROR(
            Add(static_cast<int>(stream), part->SerializeAsString(), batch_items));
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
    // The items of the streams (paged fields) in order: stream s holds [offset, offset + n_s).
    int64_t budget = options.max_page_bytes;
    int64_t reached = begin;
    int64_t offset = 0;
    for (size_t stream = 0; stream < info.stream_items.size() && reached < end && budget > 0;
         ++stream) {
      const int64_t n = info.stream_items[stream];
      if (reached >= offset + n) {
        offset += n;
        continue;
      }
      DRILLBIF_ASSIGN_OR_RETURN(
          const std::vector<ResultChunk> chunks,
          store.ReadResultChunks(id, static_cast<int>(stream), reached - offset, budget));
      const FieldDescriptor* field = PagedField(kind, static_cast<int>(stream));
      for (const ResultChunk& chunk : chunks) {
        if (reached >= end) break;
        std::unique_ptr<Message> part = kind.NewResult();
        if (!part->ParseFromString(chunk.bytes) ||
            OnlyPagedField(kind, *part) != static_cast<int>(stream)) {
          return Internal("a stored result chunk is not a valid part of a " + part->GetTypeName());
        }
        const int64_t first = offset + chunk.first_item;  // in the page sequence
        const int64_t lo = std::max(reached, first) - first;
        const int64_t hi = std::min(end, first + chunk.item_count) - first;
        jobs::KeepRepeatedRange(field, lo, hi, part.get());
        result->MergeFrom(*part);
        reached = first + hi;
        budget -= static_cast<int64_t>(chunk.bytes.size());
      }
      offset += n;
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
