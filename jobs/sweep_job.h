// The sweep job: a brute-force bifurcation diagram, simulating at each value of a parameter grid
// and recording Poincare samples (proto/drillbif/v1/sweep.proto).
#ifndef DRILLBIF_JOBS_SWEEP_JOB_H_
#define DRILLBIF_JOBS_SWEEP_JOB_H_

#include <cstdint>
#include <functional>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/model/hybrid_model.h"
#include "drillbif/simulate/sweep.h"
#include "drillbif/v1/sweep.pb.h"
#include "jobs/job_cost.h"
#include "jobs/run_context.h"

namespace drillbif::jobs {

// The store's kind of one piece of a sweep run as a child job: its request a
// drillbif.v1.SweepPartRequest, its result a drillbif.v1.SweepResult of the piece's values.
inline constexpr char kSweepPartKind[] = "sweep_part";

// Largest request whatever the limits configured.
inline constexpr int64_t kMaxSweepSamples = 10'000'000;  // Poincare samples of one sweep
inline constexpr int kMaxSweepThreads = 512;

// A checked sweep request as the engine takes it.
struct SweepPlan {
  SweepOptions options;
  Params params;
  StateVector x0;
};

// Every check that needs no engine run: parameter name, range, steps, periods, threads, model
// parameters at both ends, initial state. INVALID_ARGUMENT naming the field otherwise.
StatusOr<SweepPlan> PlanSweep(const v1::SweepRequest& request);

// The cost of running `plan` (job_cost.h): forcing periods over the grid, samples recorded.
JobCost SweepCost(const SweepPlan& plan);

// PlanSweep of the whole sweep, then the piece (INVALID_ARGUMENT naming "piece" when out of
// range); the plan's options.piece is set.
StatusOr<SweepPlan> PlanSweepPart(const v1::SweepPartRequest& request);

// SweepCost of the whole sweep in proportion to the piece's share of its values.
JobCost SweepPartCost(const SweepPlan& plan);

// Runs a sweep's pieces elsewhere than on the job's threads (e.g. the store's child jobs).
class SweepPartRunner {
 public:
  virtual ~SweepPartRunner() = default;
  // Called on the runner's calling thread as each piece finishes, in any order: its index (the
  // position of the part in Run's list, which is the piece) and its result (RunSweepPart's).
  // An error stops the run.
  using PartDone = std::function<Status(int piece, v1::SweepResult part)>;
  // Runs parts[k] for every k, calling `done` for each. `progress` receives the fraction of parts
  // done and stops the run when it returns false (CANCELLED then). Other errors: the runner's
  // (the store's, or a part's run failing).
  virtual Status Run(const std::vector<v1::SweepPartRequest>& parts, const PartDone& done,
                     const ProgressCallback& progress) = 0;
};

// Runs a parameter sweep. Errors: PlanSweep's. `context.progress` is called about every 10 ms
// with the fraction of grid values done. With `context.sweep_parts` and more than one piece
// (drillbif/simulate/sweep.h), the pieces run there and their values stream to the sink in the
// order of a local run: the result is the local run's but for wall_seconds.
StatusOr<v1::SweepResult> RunSweep(const v1::SweepRequest& request, const RunContext& context = {});

// One piece of a sweep: its values in up or down (not streamed: the result holds them), the
// piece's periods and events. Errors: PlanSweepPart's.
StatusOr<v1::SweepResult> RunSweepPart(const v1::SweepPartRequest& request,
                                       const RunContext& context = {});

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_SWEEP_JOB_H_
