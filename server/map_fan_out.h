// StoreMapCells: an optimum map's cells (jobs/optimum_map_job.h) as child jobs of kind
// "optimum_map_cell" in the store (server/store_children.h: every worker of every process sharing
// it computes them, and a map run again finds the cells its earlier runs finished). A child's
// request is the cell's OptimumRequest, its result the OptimumMapCell; a cell whose run failed is
// a cell saying so (status "FAILED"), and a resumed child whose result does not parse runs again.
#ifndef DRILLBIF_SERVER_MAP_FAN_OUT_H_
#define DRILLBIF_SERVER_MAP_FAN_OUT_H_

#include <chrono>
#include <functional>
#include <string>
#include <vector>

#include "jobs/optimum_map_job.h"
#include "server/store/job_store.h"
#include "server/store_children.h"

namespace drillbif::server {

class StoreMapCells final : public jobs::MapCellRunner {
 public:
  // Runs a child the parent claimed on the parent's thread (WorkerPool::RunOne).
  using RunChild = StoreChildren::RunChild;

  // `parent` (RUNNING, claimed by `worker_id`) and `store` outlive the runner. `submitted` is
  // called after the cells are stored (to wake idle workers). `poll`: how often the parent looks
  // for the results of cells other workers run.
  StoreMapCells(JobStore& store, const JobRecord& parent, std::string worker_id, int64_t lease_ms,
                RunChild run_child, std::function<void()> submitted,
                std::chrono::milliseconds poll = std::chrono::milliseconds(20));

  Status Run(const std::vector<v1::OptimumRequest>& requests, const CellDone& done,
             const ProgressCallback& progress) override;

  // Cells resumed from earlier runs, stored, and run by this parent itself.
  int64_t resumed() const { return children_.resumed(); }
  int64_t stored() const { return children_.stored(); }
  int64_t run_here() const { return children_.run_here(); }

 private:
  // The cell of a finished child, or why none (its state, or an unreadable result).
  StatusOr<v1::OptimumMapCell> CellOf(const JobRecord& child);

  StoreChildren children_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_MAP_FAN_OUT_H_
