// Reading google.longrunning Operations in the service tests: the JobMetadata and the response,
// each expected to be there (a test failure otherwise).
#ifndef DRILLBIF_TESTS_SUPPORT_OPERATIONS_H_
#define DRILLBIF_TESTS_SUPPORT_OPERATIONS_H_

#include <gtest/gtest.h>

#include "drillbif/v1/service.pb.h"
#include "google/longrunning/operations.pb.h"

namespace drillbif::testing {

inline v1::JobMetadata MetadataOf(const google::longrunning::Operation& op) {
  v1::JobMetadata metadata;
  EXPECT_TRUE(op.metadata().UnpackTo(&metadata));
  return metadata;
}

template <typename Result>
Result ResponseOf(const google::longrunning::Operation& op) {
  Result result;
  EXPECT_TRUE(op.has_response()) << op.ShortDebugString().substr(0, 500);
  EXPECT_TRUE(op.response().UnpackTo(&result));
  return result;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_OPERATIONS_H_
