// Periodic orbits of harmonically forced hybrid models as multi-segment boundary-value problems.
//
// An orbit of signature (m_0, e_0), ..., (m_{k-1}, -1) over n forcing periods has unknowns
//   X = (z_0, tau_0, z_1, tau_1, ..., z_{k-1}, tau_{k-1}),
// z_i the start state of segment i without its phase, tau_i its duration; the phase at the start
// of segment i is s_i = omega * sum_{j<i} tau_j (s_0 = 0, the Poincare section). Conditions:
//   h_{e_i}(phi_i(tau_i))           = 0    segment i < k-1 ends on its guard         (1 each)
//   z_{i+1} - R_{e_i}(phi_i(tau_i)) = 0    continuity through the jump map R         (d each)
//   z_0 - phi_{k-1}(tau_{k-1})      = 0    periodicity                               (d)
//   sum_i tau_i - 2 pi n / omega    = 0    the last segment ends at the section      (1)
// with phi_i the flow of mode m_i from (z_i, s_i) and d = state_dim - 1: 4k equations in 4k
// unknowns for the drifting oscillator. Newton uses exact derivatives: flow Jacobians and
// parameter derivatives from the exact propagator, guard gradients, jump Jacobians.
//
// Stability: the monodromy matrix of the stroboscopic map is
//   M = Phi_{k-1} S_{k-2} Phi_{k-2} ... S_0 Phi_0,  S = DR + (f+ - DR f-) grad h / (grad h . f-)
// (saltation matrices at the events; Leine & Nijmeijer, "Dynamics and Bifurcations of Non-Smooth
// Mechanical Systems", 2004), restricted to the state without its phase. Multipliers that are zero
// to rounding (|mu| <= 1e-12) are structural (motion confined to a contact manifold, or a
// component decayed to nothing) and are reported apart from the others.
#ifndef DRILLBIF_ORBIT_PERIODIC_ORBIT_H_
#define DRILLBIF_ORBIT_PERIODIC_ORBIT_H_

#include <complex>
#include <string>
#include <vector>

#include "drillbif/flow/propagator.h"
#include "drillbif/orbit/signature.h"
#include "drillbif/simulate/simulator.h"

namespace drillbif {

// A periodic orbit: its signature, parameters and segments.
struct PeriodicOrbit {
  Signature signature;
  Params params;
  std::vector<StateVector> starts;  // full start state of each segment (phase s_i included)
  std::vector<double> durations;    // tau_i
};

// Floquet multipliers and stability.
struct Stability {
  std::vector<std::complex<double>> multipliers;  // nontrivial, by decreasing modulus
  int structural_zeros = 0;                       // multipliers zero to rounding, removed
  // An orbit that stays on a mode constraint's surface throughout (every segment in a mode with a
  // ModeConstraint: the drifting oscillator's pure-contact orbits, "CwoP|") carries the
  // constraint's value unchanged, so its monodromy has the multiplier 1 exactly, with the
  // constraint's gradient as left eigenvector: a direction off the surface the motion never
  // takes. It is removed (1 here) and does not count for stability; rounding put it at
  // 1 +- 1e-15, and such orbits were called stable or not by that noise.
  int structural_ones = 0;
  bool stable = false;        // every nontrivial |mu| < 1
  Eigen::MatrixXd monodromy;  // d z(T) / d z(0), state without phase
};

// Why an orbit is not admissible, if it is not.
struct Admissibility {
  bool admissible = true;
  // The first violation found: segment index, and the guard that vanishes inside it (-1: the
  // segment's duration is not positive).
  int segment = -1;
  int guard = -1;
  bool at_start = false;  // the guard fires at once at the segment's start
  double time = 0.0;      // where the guard fires, from the segment's start (0 for a duration)
  std::string message;
};

struct OrbitSolverOptions {
  double tolerance = 1e-11;  // Newton stops when the scaled step and residual are below this
  int max_iterations = 20;   // Newton iterations
  // Newton steps by condensing (orbit/condensed.h) instead of a rank-revealing QR of the whole
  // system (as ContinuationOptions::condensed_solve; off by default).
  bool condensed_solve = false;
  Status Validate() const;
};

// How a Newton solve of an orbit ended (common/termination.h): kCompleted when converged;
// kNoConvergence after max_iterations (the orbit is the last iterate); kCancelled when the
// progress callback stopped it and kFailed for invalid options, a failed flow or a singular
// system (the orbit is left as it was given).
struct OrbitSolveSummary : RunSummary {
  int64_t iterations = 0;  // Newton iterations
  double residual = 0.0;   // max-norm of the conditions at the returned orbit
  // "completed: 4 Newton iterations, residual 1.2e-13" (RunSummary::BriefReport).
  std::string BriefReport() const;
};

// The measures' means over the orbit (as in HybridModel::measure_names(): ROP, Pc); only those
// selected by the bit mask `which` are computed (the others are zero).
std::vector<double> OrbitMeasures(const HybridModel& model, Propagator& propagator,
                                  const PeriodicOrbit& orbit, unsigned which = kAllMeasures);

// Stability of an orbit (flow Jacobians, saltation matrices).
Stability OrbitStability(const HybridModel& model, Propagator& propagator,
                         const PeriodicOrbit& orbit);

// Whether every segment has a positive duration and no guard of its mode other than the one that
// ends it vanishes inside it (and that one not before its end), checked by the exact event
// locator along each segment.
Admissibility CheckAdmissible(const HybridModel& model, Propagator& propagator,
                              const PeriodicOrbit& orbit);
// Every violation: the segments whose duration is not positive, or (when none) each segment in
// which a guard fires before its end. Empty when the orbit is admissible.
std::vector<Admissibility> AdmissibilityViolations(const HybridModel& model, Propagator& propagator,
                                                   const PeriodicOrbit& orbit);

// Solves for the orbit near `guess` (same signature and parameters) by Newton. `progress`
// (optional; see common/progress.h) receives the fraction of max_iterations used and can stop
// the solve: termination kCancelled, *orbit unchanged. Without it the solve polls the throttle the
// propagator carries, if any (flow/propagator.h).
OrbitSolveSummary SolveOrbit(const HybridModel& model, Propagator& propagator,
                             const OrbitSolverOptions& options, PeriodicOrbit* orbit,
                             const ProgressCallback& progress = {});

// An initial guess from simulation: N transient periods from x0, then the smallest n <= max_period
// such that the Poincare map's n-th iterate returns within `return_tolerance`; the signature and
// segments are read off the simulated events of those n periods. FAILED_PRECONDITION when no
// periodic orbit of period <= max_period is found (e.g. chaos, or a start far from any orbit).
struct GuessOptions {
  int transient_periods = 500;
  int max_period = 16;
  double return_tolerance = 1e-6;
};
// `progress` (optional) receives the fraction of the periods simulated and can stop the search:
// CANCELLED then. Without it the search polls the throttle the propagator carries, if any.
StatusOr<PeriodicOrbit> OrbitFromSimulation(const HybridModel& model, Propagator& propagator,
                                            const Params& params, const StateVector& x0,
                                            const GuessOptions& options = {},
                                            const ProgressCallback& progress = {});

}  // namespace drillbif

#endif  // DRILLBIF_ORBIT_PERIODIC_ORBIT_H_
