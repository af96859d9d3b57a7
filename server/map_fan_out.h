// StoreMapCells: an optimum map's cells (jobs/optimum_map_job.h) as child jobs in the store, so
// that every worker of every process sharing it computes them, and a map run again (after a
// crash, a lost lease or a restart) finds the cells its earlier runs finished.
//
// A run first reads the SUCCEEDED children of every earlier run of the parent (the store keeps
// finished children when a parent leaves RUNNING: docs/store.md, "Child jobs"): a child whose
// request is a cell's request is that cell, resumed. The other cells are stored as QUEUED children
// of kind "optimum_map_cell" (the cell's OptimumRequest; in the parent's client and lane, fenced
// by its run). Then, until every cell is in, the parent claims and runs its own children (the
// worker pool's run of a job: leases, outcome; the child keeps its result in the store, so that a
// later run can resume from it) and reads the results of those other workers ran. A cell is a
// task of seconds, so the store's few milliseconds per cell do not count.
#ifndef DRILLBIF_SERVER_MAP_FAN_OUT_H_
#define DRILLBIF_SERVER_MAP_FAN_OUT_H_

#include <chrono>
#include <functional>
#include <string>
#include <vector>

#include "jobs/optimum_map_job.h"
#include "server/store/job_store.h"

namespace drillbif::server {

class StoreMapCells final : public jobs::MapCellRunner {
 public:
  // Runs a child the parent claimed on the parent's thread (WorkerPool::RunOne); true when it
  // succeeded.
  using RunChild = std::function<bool(const JobRecord& child)>;

  // `parent` (RUNNING, claimed by `worker_id`) and `store` outlive the runner. `submitted` is
  // called after the cells are stored (to wake idle workers). `poll`: how often the parent looks
  // for the results of cells other workers run.
  StoreMapCells(JobStore& store, const JobRecord& parent, std::string worker_id, int64_t lease_ms,
                RunChild run_child, std::function<void()> submitted,
                std::chrono::milliseconds poll = std::chrono::milliseconds(20));

  Status Run(const std::vector<v1::OptimumRequest>& requests, const CellDone& done,
             const ProgressCallback& progress) override;

  // Cells resumed from earlier runs, stored, and run by this parent itself.
  int64_t resumed() const { return resumed_; }
  int64_t stored() const { return stored_; }
  int64_t run_here() const { return run_here_; }

 private:
  struct Pending {
    int64_t cell = 0;
    std::string id;  // the child
  };
  // Hands on the cells earlier runs finished; marks them in `in`.
  Status Resume(const std::vector<std::string>& keys, const CellDone& done, std::vector<bool>* in);
  // The cell of a finished child, or why none (its state, or an unreadable result).
  StatusOr<v1::OptimumMapCell> CellOf(const JobRecord& child);
  // Claims one of the parent's queued children and runs it here; false when none is queued.
  StatusOr<bool> RunOneHere();

  JobStore& store_;
  const JobRecord parent_;
  const std::string worker_id_;
  const int64_t lease_ms_;
  const RunChild run_child_;
  const std::function<void()> submitted_;
  const std::chrono::milliseconds poll_;
  int64_t resumed_ = 0, stored_ = 0, run_here_ = 0;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_MAP_FAN_OUT_H_
