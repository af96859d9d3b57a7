// What a job will cost, estimated at submit from its request alone, and the limits it is checked
// against (admission control). Each kind estimates its own cost (simulate_job.h, ...); the
// numbers behind the estimates are measured on a 2-core machine and listed with their sources in
// docs/performance.md ("Admission control"). An estimate is not a promise: the run itself is
// bounded by its kind's wall-time limit and result-size limit, enforced while it runs.
#ifndef DRILLBIF_JOBS_JOB_COST_H_
#define DRILLBIF_JOBS_JOB_COST_H_

#include <cstdint>
#include <limits>
#include <optional>
#include <string>

#include "drillbif/common/status.h"

namespace drillbif::jobs {

// One dimension of a cost: its estimated amount and what in the request drives it.
struct CostTerm {
  double amount = 0;  // seconds or bytes; finite and >= 0 (overflowing counts become +infinity)
  // The request fields the amount comes from, with their values, for messages:
  // "request.transient_periods + request.sample_periods = 2147483747 forcing periods".
  std::string driver;
};

// The estimate of one run.
struct JobCost {
  CostTerm seconds;       // wall time on one core
  CostTerm result_bytes;  // the serialized result (what the store keeps)
  CostTerm memory_bytes;  // memory the run holds at its peak, beyond the server's own
};

// Limits of one kind. 0 means no limit.
struct KindLimits {
  // Longest run: a request estimated above it is refused at submit, and a run that reaches it
  // fails with DEADLINE_EXCEEDED. Seconds.
  double max_seconds = 0;
  // Largest result: refused at submit above it, and a run whose streamed result reaches it fails
  // with RESOURCE_EXHAUSTED. Bytes.
  int64_t max_result_bytes = 0;
  // Largest estimated peak memory of a run, checked at submit. Bytes.
  int64_t max_memory_bytes = 0;

  // INVALID_ARGUMENT naming the field when a value is negative or not finite.
  Status Validate() const;
};

// RESOURCE_EXHAUSTED naming the driver, its estimate and the limit when the cost exceeds a
// limit ("request.sample_periods = ...: about 3.2 GB of results, above the limit of 256 MB
// (max_result_bytes of kind simulate)"); OK otherwise.
Status CheckCost(const JobCost& cost, const KindLimits& limits, const char* kind);

// "3.2 GB", "512 kB", "17 B": decimal units, for messages.
std::string HumanBytes(double bytes);
// "2.5 h", "3 min", "12 s", "40 ms".
std::string HumanSeconds(double seconds);

// A count as a double, +infinity when it is nullopt (an overflowed checked count): costs compare
// against limits as doubles, and an overflow is over every limit.
inline double CountOrInfinity(std::optional<int64_t> count) {
  return count ? static_cast<double>(*count) : std::numeric_limits<double>::infinity();
}

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_JOB_COST_H_
