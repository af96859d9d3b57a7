// The periodic attractors reached by simulation from several initial states at one parameter
// point: which stable motions coexist there, sampled (a sample, not a proof: an attractor whose
// basin none of the states lies in is not seen). At an operating point such as the robust ROP
// optimum a second attractor means a disturbance of the state, not of the parameters, can move
// the drill onto another motion (e.g. pure contact, ROP 0), which no margin from the bifurcation
// curves guards against.
#ifndef DRILLBIF_ORBIT_ATTRACTORS_H_
#define DRILLBIF_ORBIT_ATTRACTORS_H_

#include <vector>

#include "drillbif/common/termination.h"
#include "drillbif/orbit/periodic_orbit.h"

namespace drillbif {

struct Attractor {
  PeriodicOrbit orbit;            // solved (Newton from the simulated guess)
  double rop = 0.0;               // measure 0 over the orbit (the drifting oscillator's ROP)
  bool stable = false;            // from the orbit's multipliers
  std::vector<int> reached_from;  // indices of the initial states that settle on it
};

struct AttractorSample {
  // Distinct attractors in order of first appearance: two settled motions are one attractor when
  // their signatures are the same up to where the section cuts them (SameUpToSection) and their
  // measure 0 agrees to 1e-8 (1 + |value|) (both from orbits solved to ~1e-11).
  std::vector<Attractor> attractors;
  // Initial states whose motion settled on no periodic orbit of period <= guess.max_period within
  // the transient (chaotic, or a longer transient), with why.
  std::vector<int> not_periodic;
  std::vector<std::string> why_not;
  // kCompleted once every state was followed; kCancelled when the progress callback stopped the
  // sampling (the states from the one it stopped in on are in neither list). Invalid input is
  // not a sample: SampleAttractors returns its error instead.
  RunSummary summary;
};

// Simulates from each initial state (guess.transient_periods forcing periods), finds the periodic
// orbit it settles on and solves it. INVALID_ARGUMENT for invalid parameters or an invalid initial
// state (naming its index). `progress` (optional, common/progress.h) receives the fraction of the
// states done and can stop the sampling (AttractorSample::summary kCancelled; without it the
// sampling polls the throttle the propagator carries, if any).
StatusOr<AttractorSample> SampleAttractors(const HybridModel& model, Propagator& propagator,
                                           const Params& params,
                                           const std::vector<StateVector>& initial_states,
                                           const GuessOptions& guess = {},
                                           const ProgressCallback& progress = {});

}  // namespace drillbif

#endif  // DRILLBIF_ORBIT_ATTRACTORS_H_
