// CvodePropagator: SUNDIALS CVODES (BDF or Adams, dense direct linear solver with the model's
// analytic Jacobian) for any smooth mode of a HybridModel.
//  - Events: CVODE rootfinding on every guard h of the mode and on its time derivative dh/dt, so
//    that an extremum of h (a possible tangential crossing) is always a located root; at each such
//    extremum h is tested against EventOptions::tolerance, so grazing contacts are found. The
//    step is also bounded by the model's TimeScale so that h cannot have two extrema in one step
//    of a resolved solution.
//  - Measures: CVODES quadratures of HybridModel::MeasureRates.
//  - FlowMap derivatives: CVODES forward sensitivities with respect to the initial state and the
//    parameters (staggered corrector, analytic right-hand side from StateJacobian/ParamJacobian).
// Reference: Hindmarsh et al., "SUNDIALS: Suite of nonlinear and differential/algebraic equation
// solvers", ACM TOMS 31 (2005); CVODES user guide v6.4.
#ifndef DRILLBIF_FLOW_CVODE_PROPAGATOR_H_
#define DRILLBIF_FLOW_CVODE_PROPAGATOR_H_

#include <memory>

#include "drillbif/flow/propagator.h"

namespace drillbif {

struct CvodeOptions {
  double rtol = 1e-10;       // relative tolerance of the state (and of quadratures, sensitivities)
  double atol = 1e-12;       // absolute tolerance, all components
  bool bdf = false;          // false: Adams-Moulton (non-stiff, cheaper); true: BDF (stiff)
  long max_steps = 1000000;  // internal steps per call before giving up
  // Upper bound on the internal step as a fraction of the model's TimeScale (so that the root
  // functions h and dh/dt are resolved between steps). <= 0: no bound.
  double max_step_fraction = 0.5;
  EventOptions events;

  Status Validate() const;
};

class CvodePropagator final : public Propagator {
 public:
  // The model must outlive the propagator. Not thread-safe: one propagator per thread.
  CvodePropagator(const HybridModel& model, CvodeOptions options = {});
  ~CvodePropagator() override;
  CvodePropagator(const CvodePropagator&) = delete;
  CvodePropagator& operator=(const CvodePropagator&) = delete;

  std::string_view name() const override { return "cvode"; }
  FlowResult FlowMap(int mode, const StateVector& x0, double t, const Params& params,
                     const FlowRequest& request) override;
  AdvanceResult Advance(const AdvanceRequest& request, const Params& params) override;
  std::unique_ptr<Propagator> Clone() const override;

  const CvodeOptions& options() const { return options_; }

 private:
  struct Impl;
  const HybridModel& model_;
  CvodeOptions options_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace drillbif

#endif  // DRILLBIF_FLOW_CVODE_PROPAGATOR_H_
