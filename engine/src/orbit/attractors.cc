#include "drillbif/orbit/attractors.h"

#include <cmath>
#include <string>
#include <utility>

#include "drillbif/orbit/signature.h"
#include "drillbif/simulate/simulator.h"

namespace drillbif {

StatusOr<AttractorSample> SampleAttractors(const HybridModel& model, Propagator& propagator,
                                           const Params& params,
                                           const std::vector<StateVector>& initial_states,
                                           const GuessOptions& guess) {
  if (Status s = model.ValidateParams(params); !s.ok()) return s;
  const double tol = SimulationOptions().state_tolerance;
  for (size_t i = 0; i < initial_states.size(); ++i) {
    if (Status s = model.ValidateState(initial_states[i], params, tol); !s.ok()) {
      return InvalidArgument("initial state " + std::to_string(i) + ": " + s.message());
    }
  }
  AttractorSample out;
  for (int i = 0; i < static_cast<int>(initial_states.size()); ++i) {
    const StatusOr<PeriodicOrbit> found =
        OrbitFromSimulation(model, propagator, params, initial_states[i], guess);
    PeriodicOrbit orbit;
    std::string why;
    if (found.ok()) {
      orbit = *found;
      const OrbitSolveSummary solved = SolveOrbit(model, propagator, {}, &orbit);
      if (solved.status != SolveStatus::kConverged) why = "Newton: " + solved.message;
    } else {
      why = found.status().message();
    }
    if (!why.empty()) {
      out.not_periodic.push_back(i);
      out.why_not.push_back(std::move(why));
      continue;
    }
    const double rop = OrbitMeasures(model, propagator, orbit, 1u).front();
    bool seen = false;
    for (Attractor& a : out.attractors) {
      if (SameUpToSection(a.orbit.signature, orbit.signature) &&
          std::abs(a.rop - rop) <= 1e-8 * (1.0 + std::abs(rop))) {
        a.reached_from.push_back(i);
        seen = true;
        break;
      }
    }
    if (seen) continue;
    Attractor a;
    a.stable = OrbitStability(model, propagator, orbit).stable;
    a.rop = rop;
    a.orbit = std::move(orbit);
    a.reached_from.push_back(i);
    out.attractors.push_back(std::move(a));
  }
  return out;
}

}  // namespace drillbif
