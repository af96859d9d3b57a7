// Equality of a served result with the job runner's own, ignoring the wall-clock fields (which
// differ between any two runs) and, for an optimum, whether its curves and region were reused
// from an earlier request (how it was computed, not what). Shared by the service tests.
#ifndef DRILLBIF_TESTS_SUPPORT_SAME_RESULT_H_
#define DRILLBIF_TESTS_SUPPORT_SAME_RESULT_H_

#include <google/protobuf/util/message_differencer.h>
#include <gtest/gtest.h>

#include "drillbif/v1/continue.pb.h"
#include "drillbif/v1/optimum.pb.h"
#include "drillbif/v1/simulate.pb.h"
#include "drillbif/v1/sweep.pb.h"
#include "drillbif/v1/trace.pb.h"

namespace drillbif::testing {

inline void ClearTimes(v1::SimulateResult* r) { r->clear_wall_seconds(); }
inline void ClearTimes(v1::SweepResult* r) { r->clear_wall_seconds(); }
inline void ClearTimes(v1::ContinueResult* r) {
  r->clear_wall_seconds();
  if (r->has_period_doubled_branch()) ClearTimes(r->mutable_period_doubled_branch());
}
inline void ClearTimes(v1::TraceResult* r) { r->clear_wall_seconds(); }
inline void ClearTimes(v1::OptimumResult* r) {
  r->clear_trace_seconds();
  r->clear_region_seconds();
  r->clear_query_seconds();
  r->clear_check_seconds();
  r->clear_curves_reused();
  r->clear_region_reused();
}

// Exact equality (the JSON mapping prints doubles with the digits to read them back exactly).
template <typename Result>
void ExpectSameResult(Result served, Result direct) {
  ClearTimes(&served);
  ClearTimes(&direct);
  EXPECT_TRUE(google::protobuf::util::MessageDifferencer::Equals(served, direct))
      << "served: " << served.ShortDebugString().substr(0, 400)
      << "\ndirect: " << direct.ShortDebugString().substr(0, 400);
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_SAME_RESULT_H_
