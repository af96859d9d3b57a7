// HybridModel: the abstraction of a piecewise-smooth (hybrid) dynamical system with harmonic
// forcing.
//
// A model has
//  - a continuous state x of dimension n whose component phase_index() is the forcing phase s,
//    kept on the circle [0, 2 pi) by the simulator (s' = omega in every mode);
//  - a finite set of modes, each with a smooth vector field x' = f_m(x; params) and analytic
//    Jacobians d f / d x and d f / d params;
//  - for every mode a list of guards (witness functions). Convention, the same for every event:
//    the mode is valid while h(x) > 0 and the event fires when h reaches 0 from above (direction
//    kDecreasing); a model whose natural function crosses upward negates it. A guard supplies h and
//    its first two derivatives along the mode's flow, and an upper bound on |h''| valid for all
//    forward time in the mode from the current state: the event locator uses that bound to step
//    safely, so that a tangential (grazing) crossing inside a step is never missed;
//  - jump maps: when guard e of mode m fires at x, Transition() gives the next mode, the new state
//    and the Jacobian of the jump;
//  - measures: integrands accumulated along the flow (for the drifting oscillator: drift speed of
//    the slider bottom and power dissipated in the slider damper).
//
// Models whose modes are linear with harmonic forcing also describe each mode as an augmented
// homogeneous linear system z' = A z (see LinearForm), which the exact propagator exponentiates.
#ifndef DRILLBIF_MODEL_HYBRID_MODEL_H_
#define DRILLBIF_MODEL_HYBRID_MODEL_H_

#include <span>
#include <string>
#include <string_view>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/common/types.h"

namespace drillbif {

// A model's parameter values, indexed as in HybridModel::param_names().
using Params = ParamVector;

// Value and derivatives of a guard function along the flow of a mode at one state.
struct GuardValue {
  double h = 0.0;    // h(x); > 0 while the mode is valid
  double dh = 0.0;   // dh/dt along the flow
  double ddh = 0.0;  // d2h/dt2 along the flow
};

// Static description of a guard (witness function) of a mode.
struct GuardSpec {
  std::string name;     // e.g. "impact"
  std::string surface;  // the switching surface it lies on, e.g. "Pi", "l1", "l2"
};

// What happens when a guard fires: the mode the flow continues in and the state after the jump.
struct Transition {
  int next_mode = 0;
  StateVector x;         // state after the jump map
  StateMatrix jacobian;  // d x_after / d x_before of the jump map (without the saltation term)
  ParamMatrix param_jacobian;  // d x_after / d params at fixed x_before
};

// Rates of the measures accumulated along a trajectory (see HybridModel::MeasureRates).
inline constexpr int kMaxMeasures = 4;
inline constexpr unsigned kAllMeasures = ~0u;
using MeasureVector = Eigen::Matrix<double, Eigen::Dynamic, 1, Eigen::ColMajor, kMaxMeasures, 1>;

class HybridModel {
 public:
  virtual ~HybridModel() = default;

  // ---- description ----
  virtual std::string_view name() const = 0;
  virtual int state_dim() const = 0;
  virtual int phase_index() const = 0;  // index of the forcing phase s in x
  virtual const std::vector<std::string>& state_names() const = 0;
  virtual int num_modes() const = 0;
  virtual std::string_view mode_name(int mode) const = 0;
  virtual const std::vector<std::string>& param_names() const = 0;
  int num_params() const { return static_cast<int>(param_names().size()); }
  // Index of a parameter by name, or NOT_FOUND naming the parameter and listing the valid names.
  StatusOr<int> ParamIndex(std::string_view name) const;
  // The reference parameter values (a valid default).
  virtual Params DefaultParams() const = 0;
  // Forcing frequency omega (s' = omega in every mode) for these parameters.
  virtual double ForcingFrequency(const Params& params) const = 0;

  // ---- validation ----
  // INVALID_ARGUMENT naming the first bad parameter (non-finite, or outside the model's domain).
  virtual Status ValidateParams(const Params& params) const = 0;
  // INVALID_ARGUMENT naming the offending component when x is non-finite or outside the invariant
  // set (tolerance tol, absolute).
  virtual Status ValidateState(const StateVector& x, const Params& params, double tol) const = 0;
  // The mode a trajectory starting at x (admissible) evolves in.
  virtual int ModeAt(const StateVector& x, const Params& params) const = 0;

  // ---- vector fields ----
  virtual void VectorField(int mode, const StateVector& x, const Params& params,
                           StateVector* dx) const = 0;
  // d f / d x.
  virtual void StateJacobian(int mode, const StateVector& x, const Params& params,
                             StateMatrix* jac) const = 0;
  // d f / d params (state_dim x num_params).
  virtual void ParamJacobian(int mode, const StateVector& x, const Params& params,
                             ParamMatrix* jac) const = 0;

  // ---- guards and jumps ----
  virtual const std::vector<GuardSpec>& guards(int mode) const = 0;
  virtual GuardValue Guard(int mode, int guard, const StateVector& x,
                           const Params& params) const = 0;
  // d h / d x of a guard (for saltation matrices and Newton on event times).
  virtual StateRow GuardGradient(int mode, int guard, const StateVector& x,
                                 const Params& params) const = 0;
  // d h / d params of a guard at fixed x.
  virtual ParamVector GuardParamGradient(int mode, int guard, const StateVector& x,
                                         const Params& params) const = 0;
  // An upper bound on |d2h/dt2| along the flow of `mode` from x, valid for all t >= 0 (as long as
  // the flow stays in the mode). Must be finite and positive.
  virtual double GuardCurvatureBound(int mode, int guard, const StateVector& x,
                                     const Params& params) const = 0;
  virtual Transition Jump(int mode, int guard, const StateVector& x,
                          const Params& params) const = 0;
  // The mode a transversal crossing of `guard` enters from `mode` (at a grazing touch Jump may
  // stay in `mode`; this is the mode on the guard's other side).
  virtual int ModeAcross(int mode, int guard) const = 0;
  // The saltation matrix of `guard` of `mode` firing at x with the flow going on in `next_mode`:
  // S = DR + (f+ - DR f-) grad h / (grad h . f-) (Leine & Nijmeijer 2004), d x_after / d x_before
  // of the event with the change of its time, f- the field of `mode` at x, DR and f+ the jump's
  // state Jacobian and `next_mode`'s field after the jump. The default makes it from VectorField,
  // Jump and GuardGradient. A model overrides it to share their common work (a monodromy factor
  // needs one per event, and the curves' condition rows one per unknown); an override gives the
  // default's matrix bit for bit, so that results do not depend on which is used.
  virtual StateMatrix Saltation(int mode, int guard, int next_mode, const StateVector& x,
                                const Params& params) const;

  // An equality c(x) = 0 that holds throughout `mode` when the mode lives on a surface (the
  // drifting oscillator's contact modes: p - q - g = 0), with its state and parameter gradients.
  // False when the mode has none.
  virtual bool ModeConstraint(int /*mode*/, const StateVector& /*x*/, const Params& /*params*/,
                              double* /*c*/, StateRow* /*grad*/,
                              ParamVector* /*param_grad*/) const {
    return false;
  }

  // ---- measures ----
  virtual const std::vector<std::string>& measure_names() const = 0;
  // Rates (time derivatives) of the measures in a mode at x.
  virtual MeasureVector MeasureRates(int mode, const StateVector& x,
                                     const Params& params) const = 0;

  // ---- time scales ----
  // The shortest intrinsic time scale of a mode (1 / largest rate), used to bound integrator steps
  // and quadrature panels.
  virtual double TimeScale(int mode, const Params& params) const = 0;
};

// Optional interface of models whose modes are linear with harmonic forcing:
//   x_r' = A_r x_r + f0 + f1 cos(s + phi) + f2 sin(s + phi),   s' = omega,
// where x_r is the state without its phase component. In augmented coordinates
//   z = (x_r, cos(s + phi), sin(s + phi), 1)
// each mode is z' = A z with A constant, and the flow is z(t) = expm(A t) z(0).
class LinearForm {
 public:
  virtual ~LinearForm() = default;
  // Dimension of z: (state_dim - 1) + 3.
  virtual int augmented_dim() const = 0;
  // z for a state x (cos and sin of s + the model's phase offset).
  virtual void ToAugmented(const StateVector& x, const Params& params,
                           Eigen::VectorXd* z) const = 0;
  // The augmented matrix A of a mode.
  virtual void AugmentedMatrix(int mode, const Params& params, Eigen::MatrixXd* a) const = 0;
  // dA / d params[k].
  virtual void AugmentedMatrixDerivative(int mode, const Params& params, int k,
                                         Eigen::MatrixXd* da) const = 0;
  // d z(0) / d params[k] at fixed x (nonzero only for a phase offset parameter).
  virtual void AugmentedInitialDerivative(const StateVector& x, const Params& params, int k,
                                          Eigen::VectorXd* dz) const = 0;
};

// Maximum number of guards of one mode.
inline constexpr int kMaxGuards = 8;

// Everything event location needs at one time of a segment: the state, every guard of the mode
// with its time derivatives, and every guard's curvature bound (HybridModel::GuardCurvatureBound).
// A closed-form flow may add a bound on |d3h/dt3| valid from that time on in the segment (0: none
// known), which lets event location take longer steps where the curvature bound is loose.
struct SegmentPoint {
  StateVector x;
  GuardValue guards[kMaxGuards];
  double bounds[kMaxGuards];
  double jerk_bounds[kMaxGuards] = {};
};

// Constants of one segment (a mode and a start state), computed once and reused for every time
// evaluated in it. Opaque storage: its meaning belongs to the model that filled it.
struct PreparedSegment {
  int mode = 0;
  StateVector x0;
  double c[24];
};

// Optional interface of models that know their flows in closed form. The exact propagator prefers
// it to the matrix exponential (much cheaper; the two are checked against each other in tests).
class ClosedFormFlow {
 public:
  virtual ~ClosedFormFlow() = default;
  // x(t) from x0 in `mode` (phase not wrapped: s0 + omega t), and d x(t) / d x0 when jac != null.
  virtual void Flow(int mode, const StateVector& x0, double t, const Params& params, StateVector* x,
                    StateMatrix* jac) const = 0;
  // d x(t) / d params[k] at fixed x0 and t in closed form, when the model has it for that
  // parameter and mode (false: the caller falls back to the matrix exponential).
  virtual bool FlowParamDerivative(int mode, const StateVector& x0, double t, const Params& params,
                                   int k, StateVector* dx) const = 0;
  // Flow (x, and jac when non-null) and FlowParamDerivative for each parameter ks[i] (its result
  // in ok[i], its value in dx[i]) in one call: the same values, bit for bit, as those calls give.
  // A model overrides it to share the segment's common work (the shooting system asks for the
  // flow and two parameter columns of every segment at every Newton iteration); the default makes
  // the separate calls.
  virtual void FlowAndParamDerivatives(int mode, const StateVector& x0, double t,
                                       const Params& params, StateVector* x, StateMatrix* jac,
                                       std::span<const int> ks, std::span<StateVector> dx,
                                       std::span<bool> ok) const;
  // Precomputes the constants of the segment from x0 in `mode`.
  virtual void PrepareSegment(int mode, const StateVector& x0, const Params& params,
                              PreparedSegment* segment) const = 0;
  // The state at time t of a prepared segment and, when with_guards, its guards and bounds
  // (the same values as Flow, Guard and GuardCurvatureBound give, sharing their common work).
  virtual void EvaluateSegment(const PreparedSegment& segment, double t, const Params& params,
                               bool with_guards, SegmentPoint* point) const = 0;
  // The measures' increments over [0, t] from x0 in `mode`: those whose bit is set in `which`
  // (bit k: measure k; kAllMeasures: every one), the others zero and not computed.
  virtual MeasureVector MeasureIncrements(int mode, const StateVector& x0, double t,
                                          const Params& params, unsigned which) const = 0;
};

}  // namespace drillbif

#endif  // DRILLBIF_MODEL_HYBRID_MODEL_H_
