// A canonical test problem with a known answer: the forced, damped, linear oscillator with a wall,
//   x'' + 2 zeta x' + x = A cos(s),   s' = omega,
// state (x, v, s) with v = x'. One mode ("free"), one guard "wall": h = w - x (the mode is valid
// while x < w; the event fires when x reaches the wall w from below). The jump is a Newtonian
// impact with restitution r: v -> -r v, staying in the same mode (jump Jacobian diag(1, -r, 1)).
// Measures: "displacement" (rate v, increment x(t) - x0) and "position_integral" (rate x,
// increment A/omega (sin s(t) - sin s0) - 2 zeta (x(t) - x0) - (v(t) - v0), from integrating the
// equation of motion), both known in closed form.
//
// Closed form (0 <= zeta < 1): x = x_p + x_h with the steady state
//   x_p(s) = R cos(s - delta),  R = A / sqrt((1 - omega^2)^2 + (2 zeta omega)^2),
//   delta = atan2(2 zeta omega, 1 - omega^2),
// and the transient x_h = exp(-zeta t) (c1 cos(wd t) + c2 sin(wd t)), wd = sqrt(1 - zeta^2).
// The problem implements HybridModel, LinearForm (z = (x, v, cos s, sin s, 1)) and ClosedFormFlow,
// so that both propagators can be checked against it.
#ifndef DRILLBIF_TESTS_PROBLEMS_FORCED_LINEAR_OSCILLATOR_H_
#define DRILLBIF_TESTS_PROBLEMS_FORCED_LINEAR_OSCILLATOR_H_

#include <string>
#include <vector>

#include "drillbif/model/hybrid_model.h"

namespace drillbif::testing {

class ForcedLinearOscillator final : public HybridModel, public LinearForm, public ClosedFormFlow {
 public:
  enum Param : int { kZeta = 0, kAmplitude = 1, kOmega = 2, kWall = 3, kRestitution = 4 };
  enum StateIndex : int { kX = 0, kV = 1, kS = 2 };
  enum Measure : int { kDisplacement = 0, kPositionIntegral = 1 };
  static constexpr int kFree = 0;  // the only mode
  static constexpr int kWallGuard = 0;

  ForcedLinearOscillator();

  // Parameters (zeta, A, omega, w, r). The defaults give a steady-state amplitude R ~ 2.54.
  static Params MakeParams(double zeta = 0.1, double amplitude = 1.0, double omega = 0.8,
                           double wall = 2.0, double restitution = 0.8);
  static StateVector MakeState(double x, double v, double s);

  // ---- closed forms (no wall: the free flow) ----
  // Steady-state amplitude R and phase lag delta.
  static double SteadyAmplitude(const Params& params);
  static double PhaseLag(const Params& params);
  // The state at time t from x0 (phase not wrapped).
  static StateVector ExactState(const StateVector& x0, double t, const Params& params);
  // The first time in [0, t_end] at which x reaches `level` from below (0 if x0 is at or above
  // it), by bracketing on a grid of step dt_grid (looking at the maxima inside each cell, so that
  // shallow grazes are not stepped over) and bisection on the closed form to adjacent doubles;
  // negative if none.
  static double FirstUpCrossing(const StateVector& x0, double level, double t_end,
                                const Params& params, double dt_grid = 1e-3);
  // The first local maximum of x in (0, t_end] (v = 0, v decreasing) and its time, by bisection
  // on v of the closed form; false if none.
  static bool FirstMaximum(const StateVector& x0, double t_end, const Params& params, double* t_max,
                           double* x_max, double dt_grid = 1e-3);

  // HybridModel.
  std::string_view name() const override { return "forced_linear_oscillator"; }
  int state_dim() const override { return 3; }
  int phase_index() const override { return kS; }
  const std::vector<std::string>& state_names() const override { return state_names_; }
  int num_modes() const override { return 1; }
  std::string_view mode_name(int mode) const override;
  const std::vector<std::string>& param_names() const override { return param_names_; }
  Params DefaultParams() const override { return MakeParams(); }
  double ForcingFrequency(const Params& params) const override { return params[kOmega]; }
  Status ValidateParams(const Params& params) const override;
  Status ValidateState(const StateVector& x, const Params& params, double tol) const override;
  int ModeAt(const StateVector& /*x*/, const Params& /*params*/) const override { return kFree; }
  void VectorField(int mode, const StateVector& x, const Params& params,
                   StateVector* dx) const override;
  void StateJacobian(int mode, const StateVector& x, const Params& params,
                     StateMatrix* jac) const override;
  void ParamJacobian(int mode, const StateVector& x, const Params& params,
                     ParamMatrix* jac) const override;
  const std::vector<GuardSpec>& guards(int /*mode*/) const override { return guards_; }
  GuardValue Guard(int mode, int guard, const StateVector& x, const Params& params) const override;
  StateRow GuardGradient(int mode, int guard, const StateVector& x,
                         const Params& params) const override;
  ParamVector GuardParamGradient(int mode, int guard, const StateVector& x,
                                 const Params& params) const override;
  double GuardCurvatureBound(int mode, int guard, const StateVector& x,
                             const Params& params) const override;
  Transition Jump(int mode, int guard, const StateVector& x, const Params& params) const override;
  int ModeAcross(int /*mode*/, int /*guard*/) const override { return 0; }
  const std::vector<std::string>& measure_names() const override { return measure_names_; }
  MeasureVector MeasureRates(int mode, const StateVector& x, const Params& params) const override;
  double TimeScale(int mode, const Params& params) const override;

  // LinearForm: z = (x, v, cos s, sin s, 1).
  int augmented_dim() const override { return 5; }
  void ToAugmented(const StateVector& x, const Params& params, Eigen::VectorXd* z) const override;
  void AugmentedMatrix(int mode, const Params& params, Eigen::MatrixXd* a) const override;
  void AugmentedMatrixDerivative(int mode, const Params& params, int k,
                                 Eigen::MatrixXd* da) const override;
  void AugmentedInitialDerivative(const StateVector& x, const Params& params, int k,
                                  Eigen::VectorXd* dz) const override;

  // ClosedFormFlow.
  void Flow(int mode, const StateVector& x0, double t, const Params& params, StateVector* x,
            StateMatrix* jac) const override;
  // A prepared segment only records the mode and x0: the closed form is cheap enough.
  bool FlowParamDerivative(int /*mode*/, const StateVector& /*x0*/, double /*t*/,
                           const Params& /*params*/, int /*k*/,
                           StateVector* /*dx*/) const override {
    return false;  // the exact propagator's matrix exponential serves
  }
  void PrepareSegment(int mode, const StateVector& x0, const Params& params,
                      PreparedSegment* segment) const override;
  void EvaluateSegment(const PreparedSegment& segment, double t, const Params& params,
                       bool with_guards, SegmentPoint* point) const override;
  MeasureVector MeasureIncrements(int mode, const StateVector& x0, double t, const Params& params,
                                  unsigned which) const override;

 private:
  std::vector<std::string> state_names_, param_names_, measure_names_;
  std::vector<GuardSpec> guards_;
};

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_PROBLEMS_FORCED_LINEAR_OSCILLATOR_H_
