#include "orbit/monodromy.h"

namespace drillbif::internal {

StateMatrix SegmentFactor(const HybridModel& model, Propagator& propagator,
                          const PeriodicOrbit& orbit, int i) {
  const SegmentSpec& seg = orbit.signature.segments[i];
  FlowRequest req;
  req.state_jacobian = true;
  const FlowResult fr =
      propagator.FlowMap(seg.mode, orbit.starts[i], orbit.durations[i], orbit.params, req);
  return FactorFromFlow(model, orbit, i, fr.x, fr.state_jacobian);
}

StateMatrix FactorFromFlow(const HybridModel& model, const PeriodicOrbit& orbit, int i,
                           const StateVector& x_end, const StateMatrix& phi) {
  StateMatrix out;
  FactorFromFlowInto(model, orbit, i, x_end, phi, &out);
  return out;
}

void FactorFromFlowInto(const HybridModel& model, const PeriodicOrbit& orbit, int i,
                        const StateVector& x_end, const StateMatrix& phi, StateMatrix* out) {
  const SegmentSpec& seg = orbit.signature.segments[i];
  // No saltation at the section, nor at a tangent end (same mode on both sides: it would be the
  // identity, and its formula divides by h' = 0 there).
  if (seg.guard < 0 || seg.tangent) {
    *out = phi;
    return;
  }
  const StateMatrix salt = model.Saltation(
      seg.mode, seg.guard, orbit.signature.segments[i + 1].mode, x_end, orbit.params);
  MultiplyFactors(salt, phi, out);
}

std::vector<StateMatrix> MonodromyFactors(const HybridModel& model, Propagator& propagator,
                                          const PeriodicOrbit& orbit,
                                          std::vector<FlowResult>* flows) {
  std::vector<StateMatrix> factors;
  MonodromyFactorsInto(model, propagator, orbit, &factors, flows);
  return factors;
}

void MonodromyFactorsInto(const HybridModel& model, Propagator& propagator,
                          const PeriodicOrbit& orbit, std::vector<StateMatrix>* factors,
                          std::vector<FlowResult>* flows) {
  factors->resize(orbit.durations.size());
  if (flows) flows->resize(factors->size());
  FlowResult own;
  for (size_t i = 0; i < factors->size(); ++i) {
    FlowRequest req;
    req.state_jacobian = true;
    FlowResult& fr = flows ? (*flows)[i] : own;
    fr = propagator.FlowMap(orbit.signature.segments[i].mode, orbit.starts[i], orbit.durations[i],
                            orbit.params, req);
    FactorFromFlowInto(model, orbit, static_cast<int>(i), fr.x, fr.state_jacobian, &(*factors)[i]);
  }
}

void FactorsFromFlows(const HybridModel& model, const PeriodicOrbit& orbit,
                      const std::vector<FlowResult>& flows, std::vector<StateMatrix>* factors) {
  factors->resize(flows.size());
  for (size_t i = 0; i < flows.size(); ++i) {
    FactorFromFlowInto(model, orbit, static_cast<int>(i), flows[i].x, flows[i].state_jacobian,
                       &(*factors)[i]);
  }
}

StateMatrix WithoutPhase(const HybridModel& model, const StateMatrix& full) {
  const int n = model.state_dim(), ps = model.phase_index();
  StateMatrix reduced(n - 1, n - 1);
  for (int i = 0, r = 0; i < n; ++i) {
    if (i == ps) continue;
    for (int j = 0, c = 0; j < n; ++j) {
      if (j != ps) reduced(r, c++) = full(i, j);
    }
    ++r;
  }
  return reduced;
}

StateMatrix ReducedMonodromy(const HybridModel& model, const std::vector<StateMatrix>& factors) {
  const int n = model.state_dim();
  StateMatrix m = StateMatrix::Identity(n, n);
  if (n == 4) {
    // The drifting oscillator's size at fixed size, as in FactorFromFlow: the same sums in the
    // same order as the dynamic product (monodromy_test.cc compares the bits).
    using Mat4 = Eigen::Matrix4d;
    Mat4 m4 = Mat4::Identity();
    for (const StateMatrix& f : factors) m4 = Mat4::Map(f.data()) * m4;
    Mat4::Map(m.data()) = m4;
  } else {
    for (const StateMatrix& f : factors) m = f * m;
  }
  return WithoutPhase(model, m);
}

}  // namespace drillbif::internal
