// Orbits of an even number of forcing periods that are an orbit of half as many traversed twice
// (the orbits a period-2n branch meets at the doublings it joins), told from the others.
#ifndef DRILLBIF_CONTINUATION_PERIOD_DOUBLING_H_
#define DRILLBIF_CONTINUATION_PERIOD_DOUBLING_H_

#include "drillbif/flow/propagator.h"
#include "drillbif/model/hybrid_model.h"
#include "drillbif/orbit/periodic_orbit.h"

namespace drillbif::internal {

// Euclidean distance of two states over every component but the phase.
double DistanceWithoutPhase(const HybridModel& model, const StateVector& x, const StateVector& y);

// Whether a period-2n orbit is the period-n orbit traversed twice: direct simulation from its
// section state returns after n forcing periods to 1e-6 (1 + |x|) (DistanceWithoutPhase; |x| the
// largest component but the phase). A doubled orbit returns to the corrector's tolerance
// amplified by its multipliers (2.7e-12 measured at the fold TraceCurves skips so, on the
// period-2 omega-branch at a = 0.3); the genuine period-2 folds of those branches, no closer
// than 0.29; the fold where a period-2 branch turns at its birth (told apart by its branch
// point), ~sqrt of its location tolerance (1.3e-3).
bool TraversedTwice(const HybridModel& model, Propagator& propagator, const PeriodicOrbit& o);

// Where a branch of orbits of 2n periods meets the orbit of n periods traversed twice (the
// branch's turn, a pitchfork of the 2n-period system): that orbit at its period doubling, as an
// orbit of 2n periods in `near`'s signature. `near` is an orbit of the branch next to the
// meeting; its first pass is the guess for the orbit of n periods, solved with parameter `param`
// free and the doubling's condition (sigma of M + I, SolveWithConditions). FAILED_PRECONDITION
// where `near`'s signature is no signature of n periods doubled, INTERNAL where Newton fails.
StatusOr<PeriodicOrbit> PitchforkTip(const HybridModel& model, Propagator& propagator,
                                     const PeriodicOrbit& near, int param);

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_PERIOD_DOUBLING_H_
