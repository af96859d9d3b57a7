// CvodePropagator::Impl: the state behind a CvodePropagator (its CvodeIntegrator) and the bodies of
// its calls, FlowMap in flow/cvode_propagator.cc and Advance in flow/cvode_advance.cc.
#ifndef DRILLBIF_FLOW_CVODE_PROPAGATOR_IMPL_H_
#define DRILLBIF_FLOW_CVODE_PROPAGATOR_IMPL_H_

#include <vector>

#include "drillbif/flow/cvode_propagator.h"
#include "flow/cvode_integrator.h"

namespace drillbif {

struct CvodePropagator::Impl {
  Impl(const HybridModel& m, const CvodeOptions& o) : model(m), options(o), integrator(m, o) {}

  const HybridModel& model;
  const CvodeOptions& options;
  internal::CvodeIntegrator integrator;

  // Per guard, Advance: whether its roots were events during the step just returned (before this
  // return armed any guard; see CvodeIntegrator::armed()).
  std::vector<char> armed_before;

  // Checks shared by FlowMap and Advance: options, mode, state and parameters.
  Status CheckCommon(int mode, const StateVector& x0, const Params& params) const;

  // The bodies of CvodePropagator::FlowMap and Advance (which add exception safety).
  FlowResult RunFlowMap(int mode, const StateVector& x0, double t, const Params& params,
                        const FlowRequest& request);
  AdvanceResult RunAdvance(const AdvanceRequest& request, const Params& params);

  // Whether a crossing of guard i at x with values g is tangential at the integrator's accuracy:
  // its local parabola dips at most d_graze below the surface (see flow/cvode_advance.cc).
  bool Shallow(int i, const StateVector& x, const GuardValue& g) const;
  // d_graze of guard i at x (see flow/cvode_advance.cc).
  double GrazeDepth(int i, const StateVector& x) const;
};

}  // namespace drillbif

#endif  // DRILLBIF_FLOW_CVODE_PROPAGATOR_IMPL_H_
