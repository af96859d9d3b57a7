// A harmonically forced linear rotation with growth rate mu, one mode and no guards:
//   x' = mu x - y + A cos s,   y' = x + mu y,   s' = omega.
// Its forced periodic orbit exists for every mu when the forcing period T = 2 pi / omega is not a
// multiple of 2 pi, and its Floquet multipliers are exp((mu +- i) T): a complex pair that crosses
// the unit circle at mu = 0 exactly, a Neimark-Sacker point with a closed-form location. Having
// no guard, the mode needs no curvature bound (growth for mu > 0 would admit none).
#ifndef DRILLBIF_TESTS_PROBLEMS_FORCED_ROTATION_H_
#define DRILLBIF_TESTS_PROBLEMS_FORCED_ROTATION_H_

#include "drillbif/model/hybrid_model.h"

namespace drillbif::testing {

class ForcedRotation final : public HybridModel, public LinearForm {
 public:
  enum Param : int { kMu = 0, kAmplitude = 1, kOmega = 2 };
  enum StateIndex : int { kX = 0, kY = 1, kS = 2 };

  static Params MakeParams(double mu, double amplitude = 1.0, double omega = 0.7);

  std::string_view name() const override { return "forced_rotation"; }
  int state_dim() const override { return 3; }
  int phase_index() const override { return kS; }
  const std::vector<std::string>& state_names() const override { return state_names_; }
  int num_modes() const override { return 1; }
  std::string_view mode_name(int) const override { return "R"; }
  const std::vector<std::string>& param_names() const override { return param_names_; }
  Params DefaultParams() const override { return MakeParams(-0.05); }
  double ForcingFrequency(const Params& p) const override { return p[kOmega]; }
  Status ValidateParams(const Params& p) const override;
  Status ValidateState(const StateVector& x, const Params&, double) const override;
  int ModeAt(const StateVector&, const Params&) const override { return 0; }
  void VectorField(int, const StateVector& x, const Params& p, StateVector* dx) const override;
  void StateJacobian(int, const StateVector& x, const Params& p, StateMatrix* j) const override;
  void ParamJacobian(int, const StateVector& x, const Params& p, ParamMatrix* j) const override;
  const std::vector<GuardSpec>& guards(int) const override { return guards_; }
  GuardValue Guard(int, int, const StateVector&, const Params&) const override { return {}; }
  StateRow GuardGradient(int, int, const StateVector&, const Params&) const override {
    return StateRow::Zero(3);
  }
  ParamVector GuardParamGradient(int, int, const StateVector&, const Params&) const override {
    return ParamVector::Zero(3);
  }
  double GuardCurvatureBound(int, int, const StateVector&, const Params&) const override {
    return 1.0;  // never asked: the mode has no guard
  }
  Transition Jump(int, int, const StateVector& x, const Params&) const override;
  int ModeAcross(int, int) const override { return 0; }
  const std::vector<std::string>& measure_names() const override { return measure_names_; }
  MeasureVector MeasureRates(int, const StateVector& x, const Params&) const override;
  double TimeScale(int, const Params& p) const override;

  int augmented_dim() const override { return 5; }
  void ToAugmented(const StateVector& x, const Params& p, Eigen::VectorXd* z) const override;
  void AugmentedMatrix(int, const Params& p, Eigen::MatrixXd* a) const override;
  void AugmentedMatrixDerivative(int, const Params& p, int k, Eigen::MatrixXd* da) const override;
  void AugmentedInitialDerivative(const StateVector&, const Params&, int,
                                  Eigen::VectorXd* dz) const override;

 private:
  std::vector<std::string> state_names_{"x", "y", "s"};
  std::vector<std::string> param_names_{"mu", "amplitude", "omega"};
  std::vector<std::string> measure_names_{"x2", "y2"};
  std::vector<GuardSpec> guards_;
};

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_PROBLEMS_FORCED_ROTATION_H_
