// The drifting impact oscillator (Pavlovskaia, Wiercigroch et al.; bifurcation study by Paez
// Chavez, Pavlovskaia and Wiercigroch, Nonlinear Dynamics 2014). See shared MODEL.md for the
// physics.
//
// State x = (p, y, q, s): bit position and slider-top position relative to the slider bottom, bit
// velocity, forcing phase s = omega t. Contact force F = 2 xi y + q. Parameters (a, b, omega, xi,
// g, phi0). Modes:
//   NC    no contact                 p' = y,               y' = a cos(s+phi0) + b,     q' = -q/(2
//   xi) CwoP  contact, no progression    p' = y,               y' = a cos(s+phi0) + b - F, q' = y
//   CwP   contact with progression   p' = -(q-1)/(2 xi),   y' = a cos(s+phi0) + b - 1, q' = p'
// and s' = omega everywhere. Guards (mode valid while h > 0; the event fires at h = 0):
//   NC:   "impact"       h = q + g - p     (surface Pi)
//   CwoP: "progression"  h = 1 - F         (surface l1),  "separation"  h = F  (surface l2)
//   CwP:  "stick"        h = F - 1         (surface l1)
// Jump maps are the identity, except that an impact places the state exactly on Pi (p = q + g);
// after an impact the next mode is CwP if F >= 1, CwoP if 0 < F < 1 and NC if F ~ 0 with F falling
// (a grazing touch). Measures: "drift" (v' = (F - 1)/(2 xi) in CwP, else 0; its mean
// is the ROP) and "power" (w' = q^2/(2 xi) in NC, 2 xi y^2 in CwoP, (q-1)^2/(2 xi) in CwP; its
// mean is Pc).
#ifndef DRILLBIF_MODEL_DRIFTING_OSCILLATOR_H_
#define DRILLBIF_MODEL_DRIFTING_OSCILLATOR_H_

#include <vector>

#include "drillbif/model/hybrid_model.h"

namespace drillbif {

class DriftingOscillator final : public HybridModel, public LinearForm, public ClosedFormFlow {
 public:
  enum Mode : int { kNoContact = 0, kContact = 1, kProgression = 2 };
  enum Param : int { kA = 0, kB = 1, kOmega = 2, kXi = 3, kG = 4, kPhi0 = 5 };
  enum StateIndex : int { kP = 0, kY = 1, kQ = 2, kS = 3 };
  enum Measure : int { kDrift = 0, kPower = 1 };
  // Guard indices within each mode's guard list.
  enum Guard : int { kImpact = 0, kProgressionStart = 0, kSeparation = 1, kProgressionEnd = 0 };

  // Contact forces within this of 0 at an impact count as a grazing touch (the guards' event
  // tolerance, EventOptions::tolerance, is of the same order).
  static constexpr double kForceTolerance = 1e-12;

  DriftingOscillator();

  // The parameters of a, b, omega, xi, g, phi0 (reference values of MODEL.md by default).
  static Params MakeParams(double a = 0.3, double b = 0.15, double omega = 0.1, double xi = 0.05,
                           double g = 0.02, double phi0 = 0.0);
  // Contact force F = 2 xi y + q.
  static double ContactForce(const StateVector& x, const Params& params);
  // Eight valid states (p, y, q, s) spread over the state space, starts for sampling coexisting
  // attractors (orbit/attractors.h): at rest; the bit far from the slider moving towards it or
  // away; at the slider's top (p = q + g); the slider pushed in halfway or fully; both phases
  // s = 0 and pi. At (omega, a) = (0.9, 0.02) they find both the pure-contact orbit and one with a
  // flight, at (0.3, 0.105) the pure-contact orbit and a two-flight orbit.
  static std::vector<StateVector> SpreadStates(const Params& params);

  // HybridModel.
  std::string_view name() const override { return "drifting_oscillator"; }
  int state_dim() const override { return 4; }
  int phase_index() const override { return kS; }
  const std::vector<std::string>& state_names() const override;
  int num_modes() const override { return 3; }
  std::string_view mode_name(int mode) const override;
  const std::vector<std::string>& param_names() const override;
  Params DefaultParams() const override { return MakeParams(); }
  double ForcingFrequency(const Params& params) const override { return params[kOmega]; }
  Status ValidateParams(const Params& params) const override;
  Status ValidateState(const StateVector& x, const Params& params, double tol) const override;
  int ModeAt(const StateVector& x, const Params& params) const override;
  void VectorField(int mode, const StateVector& x, const Params& params,
                   StateVector* dx) const override;
  void StateJacobian(int mode, const StateVector& x, const Params& params,
                     StateMatrix* jac) const override;
  void ParamJacobian(int mode, const StateVector& x, const Params& params,
                     ParamMatrix* jac) const override;
  const std::vector<GuardSpec>& guards(int mode) const override;
  GuardValue Guard(int mode, int guard, const StateVector& x, const Params& params) const override;
  StateRow GuardGradient(int mode, int guard, const StateVector& x,
                         const Params& params) const override;
  ParamVector GuardParamGradient(int mode, int guard, const StateVector& x,
                                 const Params& params) const override;
  double GuardCurvatureBound(int mode, int guard, const StateVector& x,
                             const Params& params) const override;
  Transition Jump(int mode, int guard, const StateVector& x, const Params& params) const override;
  int ModeAcross(int mode, int guard) const override;
  // The default's matrix bit for bit, from one cosine of the phase and no parameter Jacobian.
  StateMatrix Saltation(int mode, int guard, int next_mode, const StateVector& x,
                        const Params& params) const override;
  // Contact modes (CwoP, CwP) live on Pi: c = p - q - g = 0.
  bool ModeConstraint(int mode, const StateVector& x, const Params& params, double* c,
                      StateRow* grad, ParamVector* param_grad) const override;
  const std::vector<std::string>& measure_names() const override;
  MeasureVector MeasureRates(int mode, const StateVector& x, const Params& params) const override;
  double TimeScale(int mode, const Params& params) const override;

  // LinearForm: z = (p, y, q, cos(s + phi0), sin(s + phi0), 1).
  int augmented_dim() const override { return 6; }
  void ToAugmented(const StateVector& x, const Params& params, Eigen::VectorXd* z) const override;
  void AugmentedMatrix(int mode, const Params& params, Eigen::MatrixXd* a) const override;
  void AugmentedMatrixDerivative(int mode, const Params& params, int k,
                                 Eigen::MatrixXd* da) const override;
  void AugmentedInitialDerivative(const StateVector& x, const Params& params, int k,
                                  Eigen::VectorXd* dz) const override;

  // ClosedFormFlow.
  void Flow(int mode, const StateVector& x0, double t, const Params& params, StateVector* x,
            StateMatrix* jac) const override;
  bool FlowParamDerivative(int mode, const StateVector& x0, double t, const Params& params, int k,
                           StateVector* dx) const override;
  void FlowAndParamDerivatives(int mode, const StateVector& x0, double t, const Params& params,
                               StateVector* x, StateMatrix* jac, std::span<const int> ks,
                               std::span<StateVector> dx, std::span<bool> ok) const override;
  void PrepareSegment(int mode, const StateVector& x0, const Params& params,
                      PreparedSegment* segment) const override;
  void EvaluateSegment(const PreparedSegment& segment, double t, const Params& params,
                       bool with_guards, SegmentPoint* point) const override;
  MeasureVector MeasureIncrements(int mode, const StateVector& x0, double t, const Params& params,
                                  unsigned which) const override;

 private:
  std::vector<std::string> state_names_, param_names_, measure_names_;
  std::vector<std::vector<GuardSpec>> guards_;
};

}  // namespace drillbif

#endif  // DRILLBIF_MODEL_DRIFTING_OSCILLATOR_H_
