// CvodeIntegrator: the SUNDIALS CVODES objects behind CvodePropagator (flow/cvode_propagator.h)
// and the callbacks that connect them to a HybridModel. CvodePropagator's FlowMap
// (flow/cvode_propagator.cc) and Advance (flow/cvode_advance.cc, which also states the event
// semantics) drive it.
//
// Memory. One SUNContext, one CVODES memory block, state vector, dense matrix and dense linear
// solver live here for the propagator's lifetime and are re-initialised (CVodeReInit) for every
// call. They are recreated only when the state dimension changes. Root functions are registered
// once for the mode with the most guards (unused ones are constant), so that mode switches cost
// nothing; the quadrature is allocated when measures are first requested and freed when a call
// does not want them (the simulator asks for them in whole runs of segments); sensitivities are
// allocated for a count Ns = (state columns) + (parameter columns), re-allocated only when that
// count changes, and toggled off (not freed) by calls that do not need them.
//
// Callbacks (flow/cvode_integrator_callbacks.cc): the right-hand side (HybridModel::VectorField),
// the dense Jacobian (StateJacobian), the root functions h and h' of every guard of the mode, with
// the masking of departing guards (see "Root functions" and "A disarmed guard's root functions are
// masked" in flow/cvode_advance.cc), the quadratures (MeasureRates) and the forward sensitivities
// (StateJacobian, ParamJacobian). They never throw: an exception or a non-finite value from the
// model fails the CVODES call, and Fail() names it.
#ifndef DRILLBIF_FLOW_CVODE_INTEGRATOR_H_
#define DRILLBIF_FLOW_CVODE_INTEGRATOR_H_

#include <cvodes/cvodes.h>

#include <string>
#include <vector>

#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/model/hybrid_model.h"

namespace drillbif::internal {

class CvodeIntegrator {
 public:
  // One call: the mode, the start state (at t = 0) and the stop time, and what is integrated
  // along with the state.
  struct Setup {
    int mode = 0;
    const StateVector* x0 = nullptr;
    double t_stop = 0.0;
    int active_guards = 0;  // the mode's guards when events are located, 0 for FlowMap
    bool quadrature = false;
    int state_sens = 0;  // number of state sensitivity columns (0 or n)
    int param_sens = 0;  // number of parameter sensitivity columns (0 or num_params)
  };

  // The model and the options must outlive the integrator. Nothing is allocated before Prepare.
  CvodeIntegrator(const HybridModel& model, const CvodeOptions& options)
      : model_(model), options_(options) {}
  ~CvodeIntegrator();
  CvodeIntegrator(const CvodeIntegrator&) = delete;
  CvodeIntegrator& operator=(const CvodeIntegrator&) = delete;

  // Prepares the integrator for one call from t = 0.
  Status Prepare(const Setup& s, const Params& p);

  // CVode towards tout with itask CV_NORMAL or CV_ONE_STEP; returns CVode's flag, and in *tret the
  // time reached.
  int Integrate(double tout, int itask, double* tret);
  // The state at the last return.
  StateVector State() const;
  // Fetches the sensitivities at the last return: then Sensitivity(is) is column is.
  Status FetchSensitivities();
  StateVector Sensitivity(int is) const;
  // Fetches, after a CV_ROOT_RETURN, which root functions have a root: then roots_found() holds
  // CVodeGetRootInfo's directions, g_2i for h and g_2i+1 for h' of guard i.
  Status FetchRootInfo();
  const std::vector<int>& roots_found() const { return roots_found_; }
  // CVODES's counters since the last Prepare.
  long NumRhsEvals() const;
  long NumSteps() const;

  // State (and measures into *m when quadratures are on) at time t within the last step.
  Status DenseOutput(double t, StateVector* x, MeasureVector* m);
  // Measures at the last return time.
  Status CurrentMeasures(MeasureVector* m);
  // The first zero of guard i's h in [ta, tb] (inside the last step; h(ta) > 0 >= h(tb)) on the
  // dense output: first sign change on a uniform grid, then bisection to adjacent doubles.
  // Returns the time, the state and (when quadratures are on) the measures there.
  Status LocateCrossing(int i, double ta, double tb, double* tc, StateVector* xc,
                        MeasureVector* mc);

  // Per guard, Advance: whether its roots are events (false while a guard that started on its
  // surface is still inside the band; the Roots callback masks its functions then).
  std::vector<char>& armed() { return armed_; }

  // The mode and parameters of the current call.
  int mode() const { return active_mode_; }
  const Params& params() const { return active_params_; }

  // A failed CVODES call `what` as an internal error naming the flag, the model callback's error
  // and CVODES's last error message.
  Status Fail(int flag, const char* what) const;

  // The throttle the right-hand side polls (every ProgressThrottle::kTickStride-th evaluation
  // reads the clock), or null; a stop fails the CVODES call in progress at once, and cancelled()
  // says so. Set before each call (clears cancelled()).
  void set_progress(ProgressThrottle* progress) {
    progress_ = progress;
    cancelled_ = false;
  }
  bool cancelled() const { return cancelled_; }
  // Polls the throttle as the right-hand side does, for loops outside CVode (dense output).
  bool KeepGoing() {
    if (progress_ != nullptr && !progress_->Tick()) cancelled_ = true;
    return !cancelled_;
  }

 private:
  // ---- SUNDIALS callbacks (C linkage compatible, never throw) ----
  static int Rhs(double t, N_Vector yv, N_Vector ydot, void* data);
  static int Jac(double t, N_Vector yv, N_Vector fy, SUNMatrix jm, void* data, N_Vector t1,
                 N_Vector t2, N_Vector t3);
  static int Roots(double t, N_Vector yv, double* gout, void* data);
  static int Quad(double t, N_Vector yv, N_Vector qdot, void* data);
  static int SensRhs(int num, double t, N_Vector yv, N_Vector ydot, N_Vector* yS, N_Vector* ySdot,
                     void* data, N_Vector t1, N_Vector t2);
  static void ErrHandler(int code, const char* module, const char* function, char* msg, void* data);

  // ---- set-up ----
  void FreeIntegrator();
  Status EnsureIntegrator(int n);

  const HybridModel& model_;
  const CvodeOptions& options_;

  SUNContext ctx_ = nullptr;
  void* mem_ = nullptr;
  N_Vector y_ = nullptr;    // state
  N_Vector tmp_ = nullptr;  // dense output scratch
  SUNMatrix matrix_ = nullptr;
  SUNLinearSolver solver_ = nullptr;
  int dim_ = 0;  // state dimension the integrator is set up for

  // Root functions registered with CVodeRootInit: 2 x the largest guard count of any mode, so
  // that switching modes never re-allocates; those beyond the current mode's guards (all of them
  // in FlowMap) are the constant 1, which has no roots.
  int num_roots_ = 0;
  int active_guards_ = 0;  // guards of the current call's mode (0 in FlowMap)
  std::vector<int> root_dirs_, roots_found_;

  N_Vector q_ = nullptr;     // quadratures (null when off)
  N_Vector qtmp_ = nullptr;  // quadrature dense output scratch
  int num_measures_ = 0;

  N_Vector* ys_ = nullptr;  // sensitivities (allocated for ns_ vectors)
  int ns_ = 0;
  bool sens_on_ = false;
  // The first num_state_sens_ sensitivities are w.r.t. x0, the rest params.
  int num_state_sens_ = 0;

  // Callback context.
  int active_mode_ = 0;
  Params active_params_;
  std::string last_error_;      // last message of CVODES's error handler
  std::string callback_error_;  // exception text from a model callback

  std::vector<char> armed_;  // see armed()

  ProgressThrottle* progress_ = nullptr;  // see set_progress()
  bool cancelled_ = false;
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_FLOW_CVODE_INTEGRATOR_H_
