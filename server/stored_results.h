// Results in the store, as pages. A run's result is written while it runs: its items (the kind's
// paged fields, jobs/registry.h) go into the store in chunks as they are produced
// (ResultWriter), and its summary (the result message without those items) at completion.
// GetResult reads one page: the summary and a window of the items, in the order the run
// produced them, bounded in items and in bytes (ReadResultPage). Nothing here holds a whole
// large result.
//
// Each paged field is a stream of the store (its index in the kind's paged_fields), so that a
// field's items stay together and in order whatever order the run produced them in: a page is a
// window on the items of the fields in their order (all of a simulation's samples, then all of
// its events, ...), as a client prints them. A chunk holds items of one field only, serialized as
// the kind's result message with just them; concatenating a result's summary and its chunks
// gives the whole message (protobuf's wire format).
#ifndef DRILLBIF_SERVER_STORED_RESULTS_H_
#define DRILLBIF_SERVER_STORED_RESULTS_H_

#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>

#include <cstdint>
#include <string>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/v1/service.pb.h"
#include "jobs/registry.h"
#include "jobs/run_context.h"
#include "server/store/job_store.h"

namespace drillbif::server {

// Writes one run's result items to the store as chunks of about `chunk_bytes` per field (it holds
// at most that much per paged field), refusing to go beyond `max_result_bytes` (0: no limit).
// Not thread-safe: the run's thread uses it.
class ResultWriter final : public jobs::ResultSink {
 public:
  ResultWriter(JobStore* store, const JobRecord& job, const jobs::JobKindSpec& kind,
               int64_t max_result_bytes, int64_t chunk_bytes);

  // `items` holds items of exactly one paged field (INVALID_ARGUMENT otherwise). Errors: the
  // result-size limit (RESOURCE_EXHAUSTED naming it), the store's (e.g. disk full).
  Status Append(const google::protobuf::Message& items, int64_t count) override;

  // Moves the paged items of a whole result (a run that did not stream) into chunks, field by
  // field, leaving its summary in `result`. Errors as Append.
  Status MoveItemsOf(google::protobuf::Message* result);

  // Writes what is buffered. Errors as Append.
  Status Flush();

  // Items and bytes accepted so far (written or buffered).
  int64_t items() const { return items_; }
  int64_t bytes() const { return bytes_; }
  // The first error Append or Flush returned (the run stops on it), else OK.
  const Status& error() const { return error_; }

 private:
  // A paged field's buffer and how much of it went to the store.
  struct Stream {
    std::string buffer;
    int64_t buffered_items = 0;
    int64_t written_items = 0;  // the next chunk's first item
  };

  Status Add(int stream, std::string bytes, int64_t count);
  Status FlushStream(int stream);
  Status Fail(Status status);

  JobStore* const store_;
  const std::string id_;
  const int64_t run_;
  const jobs::JobKindSpec& kind_;
  const int64_t max_result_bytes_;
  const int64_t chunk_bytes_;
  std::vector<Stream> streams_;  // by index in kind_.paged_fields
  int64_t items_ = 0, bytes_ = 0;
  Status error_;
};

// How GetResult pages.
struct PageOptions {
  // Largest page in bytes (items beyond it go to the next page; a page has at least one item).
  // 4 MiB: gRPC's default receive limit for clients.
  int64_t max_page_bytes = 4 << 20;
  // page_size 0 returns the whole result when it is at most this large, else a first page of
  // max_page_bytes with a next_page_token.
  int64_t max_whole_bytes = 4 << 20;
};

// Fills `response` with a page of the stored result of job `id` (SUCCEEDED, of `kind`):
// GetResultRequest's semantics (page_size items from page_token, 0: see PageOptions). Errors:
// INVALID_ARGUMENT for page_size or page_token, the store's.
Status ReadResultPage(JobStore& store, const jobs::JobKindSpec& kind, const std::string& id,
                      int page_size, const std::string& page_token, const PageOptions& options,
                      v1::GetResultResponse* response);

// The bytes an Operation's `response` carries for a SUCCEEDED job: the whole result when it is
// at most `max_whole_bytes`, else its summary (*summary_only set). Errors: the store's.
StatusOr<std::string> ResultForOperation(JobStore& store, const std::string& id,
                                         int64_t max_whole_bytes, bool* summary_only);

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_STORED_RESULTS_H_
