// StoreSweepParts: a sweep's independent pieces (drillbif/simulate/sweep.h: each direction, and
// each chunk of a direction, starts from the initial state) as child jobs of kind "sweep_part" in
// the store (server/store_children.h), so that every worker of every process sharing it sweeps
// them, and a sweep run again finds the pieces its earlier runs finished. A child's request is a
// SweepPartRequest (the sweep's request and the piece), its result the piece's SweepResult. A
// piece whose run failed fails the sweep with its error; a resumed child whose result does not
// parse runs again.
#ifndef DRILLBIF_SERVER_SWEEP_FAN_OUT_H_
#define DRILLBIF_SERVER_SWEEP_FAN_OUT_H_

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "jobs/sweep_job.h"
#include "server/store/job_store.h"
#include "server/store_children.h"

namespace drillbif::server {

class StoreSweepParts final : public jobs::SweepPartRunner {
 public:
  // Runs a child the parent claimed on the parent's thread (WorkerPool::RunOne).
  using RunChild = StoreChildren::RunChild;

  // As StoreChildren's (the parent: the sweep's job, RUNNING, claimed by `worker_id`).
  StoreSweepParts(JobStore& store, const JobRecord& parent, std::string worker_id, int64_t lease_ms,
                  RunChild run_child, std::function<void()> submitted,
                  std::chrono::milliseconds poll = std::chrono::milliseconds(20));

  Status Run(const std::vector<v1::SweepPartRequest>& parts, const PartDone& done,
             const ProgressCallback& progress) override;

  // Pieces resumed from earlier runs, stored, and run by this parent itself.
  int64_t resumed() const { return children_.resumed(); }
  int64_t stored() const { return children_.stored(); }
  int64_t run_here() const { return children_.run_here(); }

 private:
  // The piece of a finished child, or why none (its state, its error, an unreadable result).
  StatusOr<v1::SweepResult> PartOf(const JobRecord& child);

  StoreChildren children_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_SWEEP_FAN_OUT_H_
