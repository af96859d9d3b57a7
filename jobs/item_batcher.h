// Batches a run's result items of one paged field for a ResultSink (run_context.h): items are
// added to a result message holding only that field, which goes to the sink every kItems items
// and at Flush. One batcher per field, since a sink takes one field's items at a time.
#ifndef DRILLBIF_JOBS_ITEM_BATCHER_H_
#define DRILLBIF_JOBS_ITEM_BATCHER_H_

#include <cstdint>
#include <utility>

#include "drillbif/common/status.h"
#include "jobs/run_context.h"

namespace drillbif::jobs {

template <typename Result>
class ItemBatcher {
 public:
  // Items per batch: enough that a sink call's overhead is small, few enough that a batch of the
  // largest items (trace curves of thousands of vertices) stays small.
  static constexpr int64_t kItems = 64;

  explicit ItemBatcher(ResultSink* sink) : sink_(sink) {}

  // Adds one item: `fill(&batch)` appends it to the batch's field. False once the sink refused
  // (status() says why): the run should stop.
  template <typename Fill>
  bool Add(Fill&& fill) {
    if (!status_.ok()) return false;
    std::forward<Fill>(fill)(&batch_);
    if (++count_ >= kItems) Flush();
    return status_.ok();
  }

  // Sends what is batched. False once the sink refused.
  bool Flush() {
    if (status_.ok() && count_ > 0) {
      status_ = sink_->Append(batch_, count_);
      batch_.Clear();
      count_ = 0;
    }
    return status_.ok();
  }

  // OK, or the sink's first error.
  const Status& status() const { return status_; }

 private:
  ResultSink* const sink_;
  Result batch_;
  int64_t count_ = 0;
  Status status_;
};

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_ITEM_BATCHER_H_
