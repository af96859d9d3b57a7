// The drifting oscillator's period-1 orbit found the way a user's request finds it: 500 transient
// periods from rest, the signature read off the events, the boundary-value problem solved.
// Shared by orbit and continuation tests and benchmarks.
#ifndef DRILLBIF_TESTS_PROBLEMS_REFERENCE_ORBIT_H_
#define DRILLBIF_TESTS_PROBLEMS_REFERENCE_ORBIT_H_

#include "drillbif/model/drifting_oscillator.h"
#include "drillbif/orbit/periodic_orbit.h"

namespace drillbif::testing {

// The solved orbit reached from rest at `params`; the error when there is none or Newton fails.
StatusOr<PeriodicOrbit> SolvedOrbitFromRest(const DriftingOscillator& model, Propagator& propagator,
                                            const Params& params);

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_PROBLEMS_REFERENCE_ORBIT_H_
