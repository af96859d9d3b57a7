// GetResult's pages of a result held whole: the items of the kind's paged fields (registry.h)
// form one sequence, fields in their order; a page is a window on it, with the summary fields.
#ifndef DRILLBIF_JOBS_RESULT_PAGES_H_
#define DRILLBIF_JOBS_RESULT_PAGES_H_

#include <google/protobuf/message.h>

#include <cstdint>
#include <string>
#include <string_view>

#include "drillbif/common/status.h"
#include "drillbif/v1/service.pb.h"
#include "jobs/registry.h"

namespace drillbif::jobs {

// Largest GetResultRequest.page_size.
inline constexpr int kMaxResultPageSize = 100000;

// Page tokens are "o" + the decimal offset of the page's first item: opaque to clients.
std::string PageToken(int64_t offset);
// The offset of a token ("" is 0); INVALID_ARGUMENT naming page_token for a malformed one or an
// offset beyond INT64_MAX.
StatusOr<int64_t> ParsePageToken(std::string_view token);

// Keeps the items [lo, hi) of the repeated message field `field` of `message`, in order (the
// range clamped to the items there are).
void KeepRepeatedRange(const google::protobuf::FieldDescriptor* field, int64_t lo, int64_t hi,
                       google::protobuf::Message* message);

// Keeps the items [begin, end) of `result` (a message of kind.result_type) and clears its
// first-page-only fields unless begin is 0.
void KeepItems(const JobKindSpec& kind, int64_t begin, int64_t end,
               google::protobuf::Message* result);

// The kind's member of GetResultResponse's `result` oneof (the one of its result type), cleared
// and set.
google::protobuf::Message* MutableResultOf(const JobKindSpec& kind,
                                           v1::GetResultResponse* response);

// Fills `response` with `result_bytes` of `kind`, whole (page_size 0) or the page at
// `page_token`. INVALID_ARGUMENT for page_size outside [0, kMaxResultPageSize] or a malformed
// token; INTERNAL for unparsable bytes.
Status PageResult(const JobKindSpec& kind, std::string_view result_bytes, int page_size,
                  std::string_view page_token, v1::GetResultResponse* response);

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_RESULT_PAGES_H_
