// ExactPropagator: the closed-form flow of linear modes with harmonic forcing.
//  - x(t) and d x / d x0 from the model's ClosedFormFlow when it has one, else from
//    z(t) = expm(A t) z0 of its LinearForm (Eigen's Pade scaling-and-squaring, which is robust
//    to zero and repeated eigenvalues);
//  - d x / d params from the block-triangular exponential of Van Loan:
//      expm([[A, dA/dk], [0, A]] t) = [[E, dE/dk], [0, E]],  E = expm(A t)
//    (C. Van Loan, "Computing integrals involving the matrix exponential", IEEE TAC 23, 1978);
//  - events by safe stepping on the guards: from a state with h > 0, |h''| <= M (the model's
//    curvature bound) gives h(t + tau) >= h + h' tau - M tau^2 / 2, so no root can lie before the
//    first root of that parabola; where h' < 0 and |h'| > M tau, h is monotone and a sign change
//    brackets the unique root, polished by safeguarded Newton to machine precision. A near-tangent
//    approach (h' -> 0) is followed to the extremum, where h <= tolerance is a grazing event.
// Requires a model that implements LinearForm (ClosedFormFlow optional).
#ifndef DRILLBIF_FLOW_EXACT_PROPAGATOR_H_
#define DRILLBIF_FLOW_EXACT_PROPAGATOR_H_

#include "drillbif/flow/propagator.h"

namespace drillbif {

struct ExactOptions {
  // Use the model's ClosedFormFlow when it has one (false forces the matrix exponential: slower,
  // used as an independent check).
  bool use_closed_form = true;
  EventOptions events;
  // Quadrature of measures without a closed form: Gauss-Legendre panels no longer than this
  // fraction of the mode's TimeScale and of the forcing period / (2 pi).
  double quadrature_panel_fraction = 0.5;

  Status Validate() const;
};

class ExactPropagator final : public Propagator {
 public:
  // The model must outlive the propagator and implement LinearForm; check with Supports().
  ExactPropagator(const HybridModel& model, ExactOptions options = {});
  static bool Supports(const HybridModel& model);

  std::string_view name() const override { return "exact"; }
  FlowResult FlowMap(int mode, const StateVector& x0, double t, const Params& params,
                     const FlowRequest& request) override;
  AdvanceResult Advance(const AdvanceRequest& request, const Params& params) override;
  std::unique_ptr<Propagator> Clone() const override;
  // The state and its Jacobian are computed the same way whatever else is asked.
  bool FlowIndependentOfRequest() const override { return true; }

  const ExactOptions& options() const { return options_; }

 private:
  // x(t) and optionally d x / d x0, by closed form or matrix exponential.
  void StateAt(int mode, const StateVector& x0, double t, const Params& params, StateVector* x,
               StateMatrix* jac) const;

  const HybridModel& model_;
  const LinearForm* linear_;
  const ClosedFormFlow* closed_;
  ExactOptions options_;
};

}  // namespace drillbif

#endif  // DRILLBIF_FLOW_EXACT_PROPAGATOR_H_
