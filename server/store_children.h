// StoreChildren: a parent job's independent parts as child jobs in the store, so that every worker
// of every process sharing it computes them, and a parent run again (after a crash, a lost lease
// or a restart) finds the parts its earlier runs finished. The store-side half of StoreMapCells
// (an optimum map's cells) and StoreSweepParts (a sweep's pieces); they decode the results.
//
// A run first reads the SUCCEEDED children of the parent's kind `kind` (the store keeps finished
// children when a parent leaves RUNNING: docs/store.md, "Child jobs"): a child whose request is a
// part's request is that part, resumed. The other parts are stored as QUEUED children (in the
// parent's client and lane, fenced by its run). Then, until every part is in, the parent claims
// and runs its own queued children (the worker pool's run of a job: leases, outcome; the child
// keeps its result in the store, so that a later run can resume from it) and reads the outcomes
// of those other workers ran. A part is a task of seconds, so the store's few milliseconds per
// part do not count.
#ifndef DRILLBIF_SERVER_STORE_CHILDREN_H_
#define DRILLBIF_SERVER_STORE_CHILDREN_H_

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/simulate/simulator.h"
#include "jobs/request_bytes.h"
#include "server/store/job_store.h"

namespace drillbif::server {

class StoreChildren {
 public:
  // Runs a child the parent claimed on the parent's thread (WorkerPool::RunOne); true when it
  // succeeded.
  using RunChild = std::function<bool(const JobRecord& child)>;

  // `parent` (RUNNING, claimed by `worker_id`) and `store` outlive the runner. `kind`: the
  // children's kind. `what` names the parent in messages ("map", "sweep"). `submitted` is called
  // after the children are stored (to wake idle workers). `poll`: how often the parent looks for
  // the outcomes of children other workers run.
  StoreChildren(JobStore& store, const JobRecord& parent, std::string kind, std::string what,
                std::string worker_id, int64_t lease_ms, RunChild run_child,
                std::function<void()> submitted, std::chrono::milliseconds poll);

  // Runs a child for each of `requests` (serialized deterministically, so that an earlier run's
  // child of the same part has the same bytes). Each finished child's result is read by `read`
  // and handed to `done` (the part's index, the result, whether an earlier run of the parent
  // finished it). A resumed child whose result `read` refuses runs again (logged); `read`'s error
  // for a child of this run, and `done`'s, stop the run. `progress` receives the fraction of
  // parts in and stops the run (CANCELLED) when it returns false. A child that cannot be stored
  // because the parent left RUNNING: CANCELLED too. Other errors: the store's.
  template <typename Request, typename Result>
  Status Run(const std::vector<Request>& requests,
             const std::function<StatusOr<Result>(const JobRecord& child)>& read,
             const std::function<Status(size_t part, Result result, bool resumed)>& done,
             const ProgressCallback& progress) {
    std::vector<std::string> keys;
    keys.reserve(requests.size());
    for (const Request& r : requests) keys.push_back(jobs::DeterministicBytes(r));
    return RunKeys(
        keys,
        [&](size_t part, const JobRecord& child, bool resumed) -> StatusOr<bool> {
          StatusOr<Result> result = read(child);
          if (!result.ok() && resumed) {
            NotResumed(child, result.status());
            return false;
          }
          if (!result.ok()) return result.status();
          DRILLBIF_RETURN_IF_ERROR(done(part, *std::move(result), resumed));
          return true;
        },
        progress);
  }

  // The stored result of a SUCCEEDED child; CANCELLED for a cancelled one, the child's error for
  // a failed one (callers that treat a failure as a result look at the record first).
  StatusOr<std::string> ResultOf(const JobRecord& child);

  // Parts resumed from earlier runs, stored, and run by this parent itself.
  int64_t resumed() const { return resumed_; }
  int64_t stored() const { return stored_; }
  int64_t run_here() const { return run_here_; }

 private:
  // Called for each finished child: the index of its request, its record (a resumed one
  // SUCCEEDED) and whether an earlier run of the parent finished it. Returns whether the part is
  // taken: false only for a resumed child whose result is not usable (the part then runs
  // again); an error stops the run.
  using Take = std::function<StatusOr<bool>(size_t part, const JobRecord& child, bool resumed)>;

  // Run on the serialized requests.
  Status RunKeys(const std::vector<std::string>& requests, const Take& take,
                 const ProgressCallback& progress);
  // Logs a resumed child that runs again because its result is not usable.
  void NotResumed(const JobRecord& child, const Status& why) const;
  // Hands on the parts earlier runs finished; marks them in `in`.
  Status Resume(const std::vector<std::string>& requests, const Take& take, std::vector<bool>* in);
  // Claims one of the parent's queued children and runs it here; false when none is queued.
  StatusOr<bool> RunOneHere();

  JobStore& store_;
  const JobRecord parent_;
  const std::string kind_;
  const std::string what_;
  const std::string worker_id_;
  const int64_t lease_ms_;
  const RunChild run_child_;
  const std::function<void()> submitted_;
  const std::chrono::milliseconds poll_;
  int64_t resumed_ = 0, stored_ = 0, run_here_ = 0;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_STORE_CHILDREN_H_
