// Bitwise equality of engine results, for tests that require two runs to agree exactly (a sweep
// on several threads against one, values streamed against values kept): doubles compared by
// their bits, so that -0.0 and 0.0 differ and NaN equals itself.
#ifndef DRILLBIF_TESTS_SUPPORT_SAME_BITS_H_
#define DRILLBIF_TESTS_SUPPORT_SAME_BITS_H_

#include <cstring>

#include "drillbif/simulate/sweep.h"

namespace drillbif::testing {

inline bool SameBits(const StateVector& a, const StateVector& b) {
  return a.size() == b.size() &&
         std::memcmp(a.data(), b.data(), sizeof(double) * static_cast<size_t>(a.size())) == 0;
}

inline bool SameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

// Every field of two sweep values, samples included.
inline bool SameBits(const SweepPoint& a, const SweepPoint& b) {
  const SimulationSummary &as = a.summary, &bs = b.summary;
  if (!SameBits(a.value, b.value) || as.termination != bs.termination || as.message != bs.message ||
      as.segments != bs.segments || as.events != bs.events || as.evaluations != bs.evaluations ||
      a.start != b.start || a.transient_periods != b.transient_periods ||
      a.samples.size() != b.samples.size()) {
    return false;
  }
  for (size_t k = 0; k < a.samples.size(); ++k) {
    if (a.samples[k].period != b.samples[k].period || a.samples[k].mode != b.samples[k].mode ||
        !SameBits(a.samples[k].x, b.samples[k].x)) {
      return false;
    }
  }
  return true;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_SAME_BITS_H_
