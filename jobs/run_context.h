// What a job run gets besides its request: the progress callback that can also stop it, the
// current parameter value, the optimum cache, and the sink that streamed result items go to.
#ifndef DRILLBIF_JOBS_RUN_CONTEXT_H_
#define DRILLBIF_JOBS_RUN_CONTEXT_H_

#include <google/protobuf/message.h>

#include <cstdint>
#include <functional>

#include "drillbif/common/status.h"
#include "drillbif/simulate/simulator.h"

namespace drillbif {
class TraceTaskRunner;  // continuation/trace_tasks.h
}  // namespace drillbif

namespace drillbif::jobs {

class OptimumCache;
class MapCellRunner;    // optimum_map_job.h
class SweepPartRunner;  // sweep_job.h

// Receives the current value of the swept or continued parameter (a sweep: the grid point
// finished last; a continuation: each accepted point), for progress displays: the service
// records it as the job's current value.
using ValueCallback = std::function<void(double value)>;

// Where a run streams its result items (Poincare samples, events, sweep values, branch points,
// curves) as it produces them, instead of holding them in the result it returns. Each call
// passes a result message of the job's kind holding only items of its paged fields (see
// registry.h), in the order they were produced; concatenating the serialized calls and the
// serialized result the run returns gives the whole result (protobuf merges repeated fields by
// appending). An error stops the run (the runner returns that error).
class ResultSink {
 public:
  virtual ~ResultSink() = default;
  // `items` holds `count` >= 1 items of the paged fields and nothing else.
  virtual Status Append(const google::protobuf::Message& items, int64_t count) = 0;
};

// The context of one run. Every member is optional.
struct RunContext {
  // Called from the running thread with the fraction done in [0, 1]; returning false stops the
  // run (its result is then CANCELLED, with what was computed until then).
  ProgressCallback progress = nullptr;
  // The current parameter value (sweep, continue).
  ValueCallback on_value = nullptr;
  // Curves and regions of earlier trace and optimum runs (jobs/optimum_cache.h); runs of those
  // kinds use and fill it.
  OptimumCache* optimum_cache = nullptr;
  // Streamed result items; null: the result holds them all.
  ResultSink* sink = nullptr;
  // Where the tasks of a trace job's trace, or an optimum job's, run (continuation/trace_tasks.h:
  // e.g. the store's child jobs, for any worker to take); null: the trace's own threads. Not
  // owned.
  TraceTaskRunner* trace_tasks = nullptr;
  // Where an optimum map's cells run (e.g. the store's child jobs); null: the job's own threads.
  // Not owned.
  MapCellRunner* map_cells = nullptr;
  // Where a sweep's independent pieces run (e.g. the store's child jobs); null: the job's own
  // threads. Not owned.
  SweepPartRunner* sweep_parts = nullptr;
};

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_RUN_CONTEXT_H_
