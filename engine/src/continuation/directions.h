// Continue (continuation/continuation.h) by direction: a branch both ways is two independent
// runs from its start, increasing then decreasing, that Continue makes one after the other and
// joins. A caller with threads may run them side by side (each on a propagator of its own) and
// join them to the same result, bit for bit: ContinueDirection for d = 0 .. DirectionCount - 1,
// then JoinDirections of the runs in that order, which reads them as Continue would have made
// them (a direction that ends the branch, e.g. a closed one, makes the later ones unread).
#ifndef DRILLBIF_CONTINUATION_DIRECTIONS_H_
#define DRILLBIF_CONTINUATION_DIRECTIONS_H_

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/continuation/continuation.h"

namespace drillbif::internal {

// One direction's run.
struct BranchDirection {
  // The start refused (options, signature, admissibility) or stopped before the first step:
  // Continue's whole result.
  std::optional<ContinuationResult> refused;
  int sign = 1;               // +1: increasing, -1: decreasing
  Status init;                // the tracer's start in this direction
  bool init_stopped = false;  // a stop was seen when the start failed
  bool cancelled = false;
  bool failed = false;  // could not go on
  bool closed = false;  // came back to its start
  int64_t steps = 0, rejected = 0, newton_iterations = 0;
  std::string message;      // how it ended ("reached max", "cancelled", ...)
  ContinuationResult part;  // its points (with the start for d = 0) and special points
};

// How many directions `options.direction` runs (1 or 2).
size_t DirectionCount(const ContinuationOptions& options);

// Direction d (0: the first Continue runs) of the branch through `start`, as Continue's
// arguments say (the start's checks included).
BranchDirection ContinueDirection(const HybridModel& model, Propagator& propagator,
                                  const PeriodicOrbit& start, const ContinuationOptions& options,
                                  size_t d, const ContinuationCallback& callback = {},
                                  const ProgressCallback& progress = {});

// Continue's result from its directions' runs, in order.
ContinuationResult JoinDirections(std::vector<BranchDirection> runs);

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_DIRECTIONS_H_
