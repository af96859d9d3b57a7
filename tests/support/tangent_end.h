// A grazing orbit's guard at its tangent end (the end of its first tangent segment, where the
// guard touches zero: h = 0 and h' = 0 on a grazing curve). Shared by the curve tests.
#ifndef DRILLBIF_TESTS_SUPPORT_TANGENT_END_H_
#define DRILLBIF_TESTS_SUPPORT_TANGENT_END_H_

#include <optional>
#include <string>
#include <vector>

#include "drillbif/orbit/periodic_orbit.h"

namespace drillbif::testing {

// The guard's value and rates there, and (when asked) the name of its surface; nullopt when the
// orbit has no tangent end.
inline std::optional<GuardValue> TangentEndGuard(const HybridModel& model, Propagator& prop,
                                                 const PeriodicOrbit& o,
                                                 std::string* surface = nullptr) {
  const auto& segs = o.signature.segments;
  for (size_t k = 0; k < segs.size(); ++k) {
    if (!segs[k].tangent) continue;
    const StateVector xe = prop.FlowMap(segs[k].mode, o.starts[k], o.durations[k], o.params, {}).x;
    if (surface) *surface = model.guards(segs[k].mode)[segs[k].guard].surface;
    return model.Guard(segs[k].mode, segs[k].guard, xe, o.params);
  }
  return std::nullopt;
}

// The guard at every tangent end, in order (a double grazing has two).
inline std::vector<GuardValue> TangentEndGuards(const HybridModel& model, Propagator& prop,
                                                const PeriodicOrbit& o) {
  std::vector<GuardValue> out;
  const auto& segs = o.signature.segments;
  for (size_t k = 0; k < segs.size(); ++k) {
    if (!segs[k].tangent) continue;
    const StateVector xe = prop.FlowMap(segs[k].mode, o.starts[k], o.durations[k], o.params, {}).x;
    out.push_back(model.Guard(segs[k].mode, segs[k].guard, xe, o.params));
  }
  return out;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_TANGENT_END_H_
