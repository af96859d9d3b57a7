// Trajectories constructed to graze a switching surface of the drifting oscillator by a chosen
// signed depth, from closed-form flows (independent of the event locator under test):
// the minimum over the window of the guard h along the mode's flow equals `depth`
// (depth < 0: the trajectory crosses by |depth|; depth > 0: it misses by depth).
#ifndef DRILLBIF_TESTS_PROBLEMS_GRAZING_H_
#define DRILLBIF_TESTS_PROBLEMS_GRAZING_H_

#include "drillbif/model/drifting_oscillator.h"

namespace drillbif::testing {

struct GrazingCase {
  int mode = 0;
  int guard = 0;
  Params params;
  StateVector x0;
  double t_touch = 0.0;  // time of the guard's minimum
  double t_end = 0.0;    // a window end after the minimum with no other event in between
};

// Pi: a free flight (NC) whose bit rises towards the slider and turns back at depth from it.
GrazingCase GrazeImpact(double depth);
// l1: a contact phase (CwoP) whose force rises towards 1 and turns back at depth below it.
GrazingCase GrazeProgression(double depth);
// l2: a contact phase (CwoP) whose force falls towards 0 and turns back at depth above it.
GrazingCase GrazeSeparation(double depth);

// The minimum over t in [0, t_end] of guard `guard` of `mode` along the closed-form flow from x0,
// located by Newton on dh/dt (returns the minimum value; *t_min its time).
double GuardMinimum(const DriftingOscillator& model, int mode, int guard, const Params& params,
                    const StateVector& x0, double t_guess, double* t_min);

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_PROBLEMS_GRAZING_H_
