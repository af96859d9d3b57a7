#include "server/store/job_store.h"

#include <string>

namespace drillbif::server {

const char* JobStateName(JobState state) {
  switch (state) {
    case JobState::kQueued:
      return "QUEUED";
    case JobState::kRunning:
      return "RUNNING";
    case JobState::kSucceeded:
      return "SUCCEEDED";
    case JobState::kFailed:
      return "FAILED";
    case JobState::kCancelled:
      return "CANCELLED";
  }
  return "UNKNOWN";
}

const char* LaneName(int lane) {
  switch (lane) {
    case kLaneShort:
      return "short";
    case kLaneLong:
      return "long";
    default:
      return "unknown";
  }
}

Status ClaimOptions::Validate() const {
  for (const int lane : lanes) {
    if (lane < 0 || lane >= kLaneCount) {
      return InvalidArgument("lanes: " + std::to_string(lane) +
                             " is not a lane (0 = short, 1 = long)");
    }
  }
  if (lease_ms < 0) return InvalidArgument("lease_ms: must be >= 0 (0 = no lease)");
  return Status::Ok();
}

Status RetentionOptions::Validate() const {
  if (max_age_ms < 0) return InvalidArgument("max_age_ms: must be >= 0 (0 = no age limit)");
  if (max_db_bytes < 0) return InvalidArgument("max_db_bytes: must be >= 0 (0 = no size limit)");
  return Status::Ok();
}

}  // namespace drillbif::server
