#include "drillbif/orbit/attractors.h"

#include <cmath>
#include <string>
#include <utility>

#include "common/phase_progress.h"
#include "drillbif/orbit/signature.h"
#include "drillbif/simulate/simulator.h"

namespace drillbif {

StatusOr<AttractorSample> SampleAttractors(const HybridModel& model, Propagator& propagator,
                                           const Params& params,
                                           const std::vector<StateVector>& initial_states,
                                           const GuessOptions& guess,
                                           const ProgressCallback& progress) {
  if (Status s = model.ValidateParams(params); !s.ok()) return s;
  const double tol = SimulationOptions().state_tolerance;
  for (size_t i = 0; i < initial_states.size(); ++i) {
    if (Status s = model.ValidateState(initial_states[i], params, tol); !s.ok()) {
      return InvalidArgument("initial state " + std::to_string(i) + ": " + s.message());
    }
  }
  AttractorSample out;
  internal::PhaseProgress phase(propagator, progress);
  const int n = static_cast<int>(initial_states.size());
  for (int i = 0; i < n; ++i) {
    // Most of a state's time is its transient.
    const StatusOr<PeriodicOrbit> found =
        OrbitFromSimulation(model, propagator, params, initial_states[i], guess,
                            phase.Sub(static_cast<double>(i) / n, static_cast<double>(i + 1) / n));
    PeriodicOrbit orbit;
    std::string why;
    if (found.ok()) {
      orbit = *found;
      const OrbitSolveSummary solved = SolveOrbit(model, propagator, {}, &orbit);
      if (!solved.completed()) why = "Newton: " + solved.message;
    } else {
      why = found.status().message();
    }
    const double rop = why.empty() ? OrbitMeasures(model, propagator, orbit, 1u).front() : 0.0;
    const bool stable = why.empty() && OrbitStability(model, propagator, orbit).stable;
    // Nothing computed after a stop is kept.
    if (phase.stopped() || !phase.Continue(static_cast<double>(i + 1) / n)) {
      out.summary.Cancel("cancelled at initial state " + std::to_string(i));
      return out;
    }
    if (!why.empty()) {
      out.not_periodic.push_back(i);
      out.why_not.push_back(std::move(why));
      continue;
    }
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
    a.stable = stable;
    a.rop = rop;
    a.orbit = std::move(orbit);
    a.reached_from.push_back(i);
    out.attractors.push_back(std::move(a));
  }
  out.summary.Complete();
  return out;
}

}  // namespace drillbif
