// The monodromy matrix as a product of per-segment factors, M = F_{k-1} ... F_0 (full state,
// phase included), F_i = S_i Phi_i: segment i's flow Jacobian, then the saltation matrix at its
// end (none at the section, nor at a tangent end where the same mode goes on). F_i depends only
// on segment i's start (with its phase), duration and the parameters, so finite differences of a
// function of M recompute only the factors an unknown moves (continuation/curve.cc).
#ifndef DRILLBIF_ORBIT_MONODROMY_H_
#define DRILLBIF_ORBIT_MONODROMY_H_

#include <Eigen/Dense>
#include <vector>

#include "drillbif/orbit/periodic_orbit.h"

namespace drillbif::internal {

// F_i of the orbit (state_dim x state_dim).
StateMatrix SegmentFactor(const HybridModel& model, Propagator& propagator,
                          const PeriodicOrbit& orbit, int i);

// F_i = S_i Phi_i from segment i's end state `x_end` and flow Jacobian `phi` (SegmentFactor
// without the flow: for a model with a LinearForm the flow is affine in the state without its
// phase, so moving that part of a start by dx moves the end by phi dx and leaves phi as it is).
StateMatrix FactorFromFlow(const HybridModel& model, const PeriodicOrbit& orbit, int i,
                           const StateVector& x_end, const StateMatrix& phi);
// The same into *out (not `phi`), without a copy of the result.
void FactorFromFlowInto(const HybridModel& model, const PeriodicOrbit& orbit, int i,
                        const StateVector& x_end, const StateMatrix& phi, StateMatrix* out);

// *out = a * b for two factors (state_dim x state_dim; `out` neither of them): for a state of four
// (the drifting oscillator's) at fixed size, unrolled, with the same sums in the same order as the
// dynamic-size product (each entry accumulated over k = 0..3 in turn; monodromy_test compares
// the bits).
inline void MultiplyFactors(const StateMatrix& a, const StateMatrix& b, StateMatrix* out) {
  out->resize(a.rows(), b.cols());
  if (a.rows() == 4 && a.cols() == 4 && b.cols() == 4) {
    using Mat4 = Eigen::Matrix4d;
    Mat4::Map(out->data()).noalias() = Mat4::Map(a.data()) * Mat4::Map(b.data());
  } else {
    out->noalias() = a * b;
  }
}

// Every factor of the orbit, in segment order. `flows`, when given, receives each segment's flow
// (end state and flow Jacobian) its factor was made from.
std::vector<StateMatrix> MonodromyFactors(const HybridModel& model, Propagator& propagator,
                                          const PeriodicOrbit& orbit,
                                          std::vector<FlowResult>* flows = nullptr);
// The same into *factors (its storage reused: the curve solves make factors per evaluation).
void MonodromyFactorsInto(const HybridModel& model, Propagator& propagator,
                          const PeriodicOrbit& orbit, std::vector<StateMatrix>* factors,
                          std::vector<FlowResult>* flows = nullptr);

// Every factor of the orbit from its segments' flows (end state and flow Jacobian, as
// MonodromyFactors' `flows`, or OrbitBvp::Evaluate's): the factors MonodromyFactors gives from
// flows equal to these.
// Into *factors (its storage reused).
void FactorsFromFlows(const HybridModel& model, const PeriodicOrbit& orbit,
                      const std::vector<FlowResult>& flows, std::vector<StateMatrix>* factors);

// A full-state monodromy without its phase row and column (Stability::monodromy).
StateMatrix WithoutPhase(const HybridModel& model, const StateMatrix& full);

// The product of the factors, without the phase row and column.
StateMatrix ReducedMonodromy(const HybridModel& model, const std::vector<StateMatrix>& factors);

}  // namespace drillbif::internal

#endif  // DRILLBIF_ORBIT_MONODROMY_H_
