#include "drillbif/flow/propagator.h"

#include <cmath>

namespace drillbif {

Status EventOptions::Validate() const {
  if (!(tolerance > 0.0 && tolerance <= 1e-3)) {
    return InvalidArgument("event tolerance must be in (0, 1e-3], got " +
                           std::to_string(tolerance));
  }
  if (!(time_rtol >= 1e-16 && time_rtol <= 1e-3)) {
    return InvalidArgument("event time_rtol must be in [1e-16, 1e-3], got " +
                           std::to_string(time_rtol));
  }
  if (max_iterations <= 0) return InvalidArgument("event max_iterations must be > 0");
  return Status::Ok();
}

}  // namespace drillbif
