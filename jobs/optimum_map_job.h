// The optimum map job (proto/drillbif/v1/optimum_map.proto): the robust optimum at every cell of a
// grid of one or two operating conditions (e.g. the weight on bit b), each cell an independent
// optimum run (optimum_job.h) at its condition values. The cells run on the job's own threads, or
// on a MapCellRunner (the server's: child jobs in the store that any worker takes, and that a
// restarted map finds again). Each finished cell is streamed to the run's sink.
#ifndef DRILLBIF_JOBS_OPTIMUM_MAP_JOB_H_
#define DRILLBIF_JOBS_OPTIMUM_MAP_JOB_H_

#include <cstdint>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/v1/optimum_map.pb.h"
#include "jobs/job_cost.h"
#include "jobs/optimum_job.h"
#include "jobs/run_context.h"

namespace drillbif::jobs {

// The store's kind of a map cell run as a child job: its request a drillbif.v1.OptimumRequest
// (the cell's), its result a drillbif.v1.OptimumMapCell without index and condition.
inline constexpr char kMapCellKind[] = "optimum_map_cell";

// Most cells of one map.
inline constexpr int64_t kMaxMapCells = 10000;

// A checked map request.
struct OptimumMapPlan {
  OptimumPlan cell;               // the plan of the first cell (every cell's is alike)
  std::vector<std::string> over;  // the conditions: ModelParams field names
  std::vector<double> from, to;
  std::vector<int> steps;
  int64_t cells = 0;  // the product of steps
  int threads = 1;    // threads the cells run on locally
};

// Every check that needs no engine run: over, from, to, steps (INVALID_ARGUMENT naming the
// field), then PlanOptimum of the first and the last cell ("optimum." before its fields).
StatusOr<OptimumMapPlan> PlanOptimumMap(const v1::OptimumMapRequest& request);

// The cells' optimum costs added up (seconds on one core), the memory of the cells running at
// once, and the cells' results.
JobCost OptimumMapCost(const OptimumMapPlan& plan);

// Cell `cell` (0 .. cells - 1; the first condition's index varies fastest): its index along each
// condition, its condition values, and its optimum request.
std::vector<int> CellIndex(const OptimumMapPlan& plan, int64_t cell);
std::vector<double> CellCondition(const OptimumMapPlan& plan, int64_t cell);
v1::OptimumRequest CellRequest(const v1::OptimumMapRequest& request, const OptimumMapPlan& plan,
                               int64_t cell);

// The values of `request`'s two trace parameters in `params` (every field set, as in an
// OptimumResult).
std::pair<double, double> TracePoint(const v1::OptimumRequest& request,
                                     const v1::ModelParams& params);

// One cell: the optimum of `request` with its orbit and the boundary segments within four margins.
// A run that fails (e.g. no stable start orbit at that condition) is a cell whose optimum says so
// (status "FAILED"); only a stop (`progress` returned false) gives a cell "CANCELLED".
v1::OptimumMapCell RunMapCell(const v1::OptimumRequest& request, const ProgressCallback& progress);

// RunMapCell as the child job of kind kMapCellKind runs it.
StatusOr<v1::OptimumMapCell> RunMapCellJob(const v1::OptimumRequest& request,
                                           const RunContext& context);

// Runs a map's cells elsewhere than on the job's threads (e.g. the store's child jobs).
class MapCellRunner {
 public:
  virtual ~MapCellRunner() = default;
  // Called on the runner's calling thread as each cell finishes, in any order: its flat index,
  // the cell (optimum, orbit, boundary; index and condition unset), and whether an earlier run of
  // the same job computed it. An error stops the run.
  using CellDone = std::function<Status(int64_t cell, v1::OptimumMapCell result, bool resumed)>;
  // Runs requests[k] for every k, calling `done` for each. `progress` receives the fraction of
  // cells done and stops the run when it returns false (CANCELLED then). Other errors: the
  // runner's (the store's).
  virtual Status Run(const std::vector<v1::OptimumRequest>& requests, const CellDone& done,
                     const ProgressCallback& progress) = 0;
};

// Errors: INVALID_ARGUMENT naming the field; the sink's or the cell runner's errors. Cells stream
// to `context.sink` as they finish; `context.map_cells` (optional) runs them.
StatusOr<v1::OptimumMapResult> RunOptimumMap(const v1::OptimumMapRequest& request,
                                             const RunContext& context = {});

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_OPTIMUM_MAP_JOB_H_
