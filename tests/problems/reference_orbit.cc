#include "problems/reference_orbit.h"

namespace drillbif::testing {

StatusOr<PeriodicOrbit> SolvedOrbitFromRest(const DriftingOscillator& model, Propagator& propagator,
                                            const Params& params) {
  StatusOr<PeriodicOrbit> guess =
      OrbitFromSimulation(model, propagator, params, DefaultInitialState(model));
  if (!guess.ok()) return guess.status();
  PeriodicOrbit orbit = *guess;
  const OrbitSolveSummary s = SolveOrbit(model, propagator, {}, &orbit);
  if (s.termination != Termination::kCompleted) return Internal("orbit solve: " + s.message);
  return orbit;
}

}  // namespace drillbif::testing
