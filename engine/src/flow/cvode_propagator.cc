// CvodePropagator: see the header for the design. Notes on the implementation:
//
// Memory. One SUNContext, one CVODES memory block, state vector, dense matrix and dense linear
// solver live in Impl for the propagator's lifetime and are re-initialised (CVodeReInit) for every
// call. They are recreated only when the state dimension changes. Root functions are registered
// once for the mode with the most guards (unused ones are constant), so that mode switches cost
// nothing; the quadrature is allocated when measures are first requested and freed when a call
// does not want them (the simulator asks for them in whole runs of segments); sensitivities are
// allocated for a count Ns = (state columns) + (parameter columns), re-allocated only when that
// count changes, and toggled off (not freed) by calls that do not need them.
//
// Event semantics of Advance, the same as the exact propagator's (flow/safe_event_locator.h) up to
// integration accuracy, so that the two can be compared event by event:
//  - Root functions: for guard i, g_2i = h (direction decreasing: crossings into h < 0) and
//    g_2i+1 = h' (direction increasing: the minima of h, where a graze turns back). CVode runs in
//    CV_ONE_STEP mode with the stop time t_max, so that every internal step end is seen: the start
//    logic below needs it, samples and crossings inside a step come from its dense output.
//  - A crossing (h root) is an event at the crossing.
//  - A minimum (h' root) with 0 < h <= tolerance is a tangential event at the minimum (the flow
//    turns back inside the band). A minimum with h <= 0 means that both crossings of a shallow dip
//    fell inside one internal step, so that no sign change of h was seen at the step ends: the
//    first crossing is located on the dense output of the step (grid, then bisection) and reported.
//    Minima with h > tolerance (near misses) are ignored.
//  - The tangential flag of a crossing: set when the crossing cannot be told from a graze at the
//    integrator's accuracy, i.e. when its local parabola h' tau + h'' tau^2 / 2 dips at most
//        d_graze = max(tolerance, kGrazeResolution * sum_j |dh/dx_j| (rtol |x_j| + atol))
//    below the surface (h'^2 <= 2 |h''| d_graze); the sum is the tolerance CVODE keeps on h per
//    step (global errors are larger). The exact propagator is accurate to rounding and flags only
//    the minima inside the band.
//  - Start: a guard with h(x0) <= tolerance fires at once (duration 0) when its local parabola
//    moves into h < 0 (internal::MovesInto, shared with the exact propagator); otherwise it is
//    leaving the surface (the usual situation right after the simulator applied its jump): it is
//    disarmed until h > tolerance at a step end. If it falls below -tolerance instead, it fires at
//    the start of that step.
//  - A disarmed guard's root functions are masked while it is inside the band: g_2i = max(h, tol)
//    and g_2i+1 = (h > tol ? h' : 1), which have no roots there and equal h and h' where it leaves,
//    so that CVODE's values at the step end where it is armed are the true ones. Handing CVODE the
//    raw functions instead fails: right after a separation (F = 0) the drifting oscillator's
//    impact guard starts with h and h' = -F / (2 xi) both at rounding level, so that h' (or h)
//    has a "root" within ~1e-17 of the start; CVODE returns it, and on the next call finds the
//    function exactly zero at that root and again ttol = 100 u (|t| + |step|) ~ 1e-20 later, and
//    stops with CV_ILL_INPUT (cvRcheck2, "Root found at and very near t"). A root reported for a
//    masked function (h came back down through tol inside the step) arms the guard but is not an
//    event. Root values are never exactly zero either (NonZero), which rules that failure out for
//    armed guards too, e.g. a rounding-level minimum of h just above the band, a near miss that
//    CVode must step past.
#include "drillbif/flow/cvode_propagator.h"

#include <cvodes/cvodes.h>
#include <nvector/nvector_serial.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <limits>
#include <string>
#include <vector>

#include "flow/safe_event_locator.h"

namespace drillbif {
namespace {

// Crossings whose dip below the surface is within this many local tolerances of h are flagged
// tangential (see d_graze above). Adams' global error on the test oscillator is 5-15 local
// tolerances over the first periods, BDF's up to 50 times more.
constexpr double kGrazeResolution = 100.0;
// Safety cap on trajectory samples of one Advance call.
constexpr size_t kMaxSamples = 10000000;

std::string FormatDouble(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.6g", v);
  return buf;
}

std::string FormatState(const StateVector& x) {
  std::string s = "(";
  for (int i = 0; i < x.size(); ++i) s += (i ? ", " : "") + FormatDouble(x[i]);
  return s + ")";
}

// CVodeGetReturnFlagName allocates the string it returns.
std::string FlagName(int flag) {
  char* name = CVodeGetReturnFlagName(flag);
  if (name == nullptr) return "flag " + std::to_string(flag);
  std::string s(name);
  std::free(name);
  return s;
}

inline const double* Data(N_Vector v) { return N_VGetArrayPointer(v); }
inline double* MutableData(N_Vector v) { return N_VGetArrayPointer(v); }

StateVector ToState(N_Vector v, int n) { return Eigen::Map<const Eigen::VectorXd>(Data(v), n); }
void FromState(const StateVector& x, N_Vector v) {
  Eigen::Map<Eigen::VectorXd>(MutableData(v), x.size()) = x;
}

// A root function value that is never exactly zero: an exact zero counts as positive. CVODE cannot
// tell the direction of a root function that is exactly zero at a root it just returned and again
// ttol = 100 u (|t| + |step|) later (cvRcheck2: CV_ILL_INPUT "Root found at and very near t"),
// which happens whenever the function is zero to rounding over such an interval: near t = 0 ttol
// is ~1e-20, and h' = 0 + O(u) holds over ~1e-17 at an extremum of h at the segment start. Seen
// as positive, a zero is never a root by itself: a decreasing h is found where it turns negative,
// an increasing h' where it turns positive (t moves by at most the rounding band of the function).
// The stand-in is far below any meaningful value but not tiny enough for CVODE's sign tests
// glo * ghi < 0 to underflow to zero (which breaks its root bracket): its product with any value
// above 1e-158 is a normal double.
constexpr double kZeroStandIn = 1e-150;
inline double NonZero(double v) { return v != 0.0 ? v : kZeroStandIn; }

bool Finite(const GuardValue& g) {
  return std::isfinite(g.h) && std::isfinite(g.dh) && std::isfinite(g.ddh);
}

// Checks shared by FlowMap and Advance: options, mode, state and parameters.
Status CheckCommon(const HybridModel& model, const CvodeOptions& options, int mode,
                   const StateVector& x0, const Params& params) {
  Status st = options.Validate();
  if (!st.ok()) return st;
  if (mode < 0 || mode >= model.num_modes()) {
    return InvalidArgument("mode " + std::to_string(mode) + " is out of range [0, " +
                           std::to_string(model.num_modes()) + ")");
  }
  const int n = model.state_dim();
  if (n <= 0 || n > kMaxStateDim) {
    return InvalidArgument("model state dimension " + std::to_string(n) + " is outside [1, " +
                           std::to_string(kMaxStateDim) + "]");
  }
  if (x0.size() != n) {
    return InvalidArgument("x0 has " + std::to_string(x0.size()) + " components, the model " +
                           std::to_string(n));
  }
  for (int i = 0; i < n; ++i) {
    if (!std::isfinite(x0[i])) {
      return InvalidArgument("x0[" + std::to_string(i) + "] (" + model.state_names()[i] +
                             ") is not finite");
    }
  }
  if (params.size() != model.num_params()) {
    return InvalidArgument("params has " + std::to_string(params.size()) +
                           " components, the model " + std::to_string(model.num_params()));
  }
  return model.ValidateParams(params);
}

}  // namespace

Status CvodeOptions::Validate() const {
  if (!(rtol > 0.0 && rtol <= 1e-2)) {
    return InvalidArgument("CvodeOptions.rtol must be in (0, 1e-2] (got " + FormatDouble(rtol) +
                           ")");
  }
  if (!(atol > 0.0) || !std::isfinite(atol)) {
    return InvalidArgument("CvodeOptions.atol must be finite and > 0 (got " + FormatDouble(atol) +
                           ")");
  }
  if (max_steps <= 0) {
    return InvalidArgument("CvodeOptions.max_steps must be > 0 (got " + std::to_string(max_steps) +
                           ")");
  }
  if (!std::isfinite(max_step_fraction)) {
    return InvalidArgument("CvodeOptions.max_step_fraction must be finite (got " +
                           FormatDouble(max_step_fraction) + ")");
  }
  return events.Validate();
}

struct CvodePropagator::Impl {
  Impl(const HybridModel& m, const CvodeOptions& o) : model(m), options(o) {}
  ~Impl() {
    FreeIntegrator();
    if (ctx != nullptr) SUNContext_Free(&ctx);
  }

  const HybridModel& model;
  const CvodeOptions& options;

  SUNContext ctx = nullptr;
  void* mem = nullptr;
  N_Vector y = nullptr;    // state
  N_Vector tmp = nullptr;  // dense output scratch
  SUNMatrix matrix = nullptr;
  SUNLinearSolver solver = nullptr;
  int dim = 0;  // state dimension the integrator is set up for

  // Root functions registered with CVodeRootInit: 2 x the largest guard count of any mode, so
  // that switching modes never re-allocates; those beyond the current mode's guards (all of them
  // in FlowMap) are the constant 1, which has no roots.
  int num_roots = 0;
  int active_guards = 0;  // guards of the current call's mode (0 in FlowMap)
  std::vector<int> root_dirs, roots_found;

  N_Vector q = nullptr;     // quadratures (null when off)
  N_Vector qtmp = nullptr;  // quadrature dense output scratch
  int num_measures = 0;

  N_Vector* ys = nullptr;  // sensitivities (allocated for ns vectors)
  int ns = 0;
  bool sens_on = false;
  int num_state_sens = 0;  // the first num_state_sens sensitivities are w.r.t. x0, the rest params

  // Callback context.
  int active_mode = 0;
  Params active_params;
  std::string last_error;      // last message of CVODES's error handler
  std::string callback_error;  // exception text from a model callback

  // Per guard, Advance: whether its roots are events (false while a guard that started on its
  // surface is still inside the band; the Roots callback masks its functions then), and the same
  // during the step just returned (before this return armed any guard).
  std::vector<char> armed, armed_before;

  // ---- SUNDIALS callbacks (C linkage compatible, never throw) ----
  // A non-finite value from the model is unrecoverable: retrying with smaller steps would only
  // creep up to the boundary of the model's domain for max_steps steps.
  static int Rhs(double t, N_Vector yv, N_Vector ydot, void* data) {
    auto* self = static_cast<Impl*>(data);
    try {
      StateVector dx;
      const StateVector x = ToState(yv, self->dim);
      self->model.VectorField(self->active_mode, x, self->active_params, &dx);
      if (dx.size() != self->dim || !dx.allFinite()) {
        self->callback_error =
            "VectorField is not finite at t = " + FormatDouble(t) + ", x = " + FormatState(x);
        return -1;
      }
      FromState(dx, ydot);
      return 0;
    } catch (const std::exception& e) {
      self->callback_error = std::string("VectorField threw: ") + e.what();
    } catch (...) {
      self->callback_error = "VectorField threw";
    }
    return -1;
  }

  static int Jac(double t, N_Vector yv, N_Vector /*fy*/, SUNMatrix jm, void* data, N_Vector /*t1*/,
                 N_Vector /*t2*/, N_Vector /*t3*/) {
    auto* self = static_cast<Impl*>(data);
    try {
      StateMatrix j;
      const StateVector x = ToState(yv, self->dim);
      self->model.StateJacobian(self->active_mode, x, self->active_params, &j);
      if (j.rows() != self->dim || j.cols() != self->dim || !j.allFinite()) {
        self->callback_error =
            "StateJacobian is not finite at t = " + FormatDouble(t) + ", x = " + FormatState(x);
        return -1;
      }
      for (int c = 0; c < self->dim; ++c) {
        double* col = SUNDenseMatrix_Column(jm, c);
        for (int r = 0; r < self->dim; ++r) col[r] = j(r, c);
      }
      return 0;
    } catch (const std::exception& e) {
      self->callback_error = std::string("StateJacobian threw: ") + e.what();
    } catch (...) {
      self->callback_error = "StateJacobian threw";
    }
    return -1;
  }

  // Root functions (see "Root functions" in the file comment): h and h' of armed guards; a
  // departing guard's are masked while it is inside the band, and no value is ever exactly zero.
  static int Roots(double /*t*/, N_Vector yv, double* gout, void* data) {
    auto* self = static_cast<Impl*>(data);
    try {
      const StateVector x = ToState(yv, self->dim);
      const int ng = self->active_guards;
      const double tol = self->options.events.tolerance;
      for (int i = ng; i < self->num_roots / 2; ++i) gout[2 * i] = gout[2 * i + 1] = 1.0;
      for (int i = 0; i < ng; ++i) {
        const GuardValue g = self->model.Guard(self->active_mode, i, x, self->active_params);
        if (!std::isfinite(g.h) || !std::isfinite(g.dh)) {
          self->callback_error = "guard " + std::to_string(i) + " is not finite";
          return -1;
        }
        double gh = g.h, gdh = g.dh;
        if (!self->armed[i] && !(g.h > tol)) {
          gh = tol;   // max(h, tol): no root, and equal to h where the guard leaves the band
          gdh = 1.0;  // no root of h' in the direction sought (increasing)
        }
        gout[2 * i] = NonZero(gh);
        gout[2 * i + 1] = NonZero(gdh);
      }
      return 0;
    } catch (const std::exception& e) {
      self->callback_error = std::string("Guard threw: ") + e.what();
    } catch (...) {
      self->callback_error = "Guard threw";
    }
    return -1;
  }

  static int Quad(double t, N_Vector yv, N_Vector qdot, void* data) {
    auto* self = static_cast<Impl*>(data);
    try {
      const StateVector x = ToState(yv, self->dim);
      const MeasureVector m = self->model.MeasureRates(self->active_mode, x, self->active_params);
      if (m.size() != self->num_measures || !m.allFinite()) {
        self->callback_error =
            "MeasureRates is not finite at t = " + FormatDouble(t) + ", x = " + FormatState(x);
        return -1;
      }
      Eigen::Map<Eigen::VectorXd>(MutableData(qdot), self->num_measures) = m;
      return 0;
    } catch (const std::exception& e) {
      self->callback_error = std::string("MeasureRates threw: ") + e.what();
    } catch (...) {
      self->callback_error = "MeasureRates threw";
    }
    return -1;
  }

  // All sensitivities at once: s_i' = J s_i (+ df/dp_k for a parameter column), so that the
  // Jacobians are evaluated once per call rather than once per sensitivity.
  static int SensRhs(int num, double t, N_Vector yv, N_Vector /*ydot*/, N_Vector* yS,
                     N_Vector* ySdot, void* data, N_Vector /*t1*/, N_Vector /*t2*/) {
    auto* self = static_cast<Impl*>(data);
    try {
      const StateVector x = ToState(yv, self->dim);
      StateMatrix j;
      self->model.StateJacobian(self->active_mode, x, self->active_params, &j);
      ParamMatrix pj;
      if (num > self->num_state_sens) {
        self->model.ParamJacobian(self->active_mode, x, self->active_params, &pj);
      }
      if (!j.allFinite() || (num > self->num_state_sens && !pj.allFinite())) {
        self->callback_error =
            "StateJacobian or ParamJacobian is not finite at t = " + FormatDouble(t) +
            ", x = " + FormatState(x);
        return -1;
      }
      for (int is = 0; is < num; ++is) {
        Eigen::Map<const Eigen::VectorXd> s(Data(yS[is]), self->dim);
        Eigen::Map<Eigen::VectorXd> sdot(MutableData(ySdot[is]), self->dim);
        sdot = j * s;
        if (is >= self->num_state_sens) sdot += pj.col(is - self->num_state_sens);
      }
      return 0;
    } catch (const std::exception& e) {
      self->callback_error = std::string("sensitivity right-hand side threw: ") + e.what();
    } catch (...) {
      self->callback_error = "sensitivity right-hand side threw";
    }
    return -1;
  }

  static void ErrHandler(int code, const char* module, const char* function, char* msg,
                         void* data) {
    auto* self = static_cast<Impl*>(data);
    if (code < 0) {  // errors only; warnings are not printed either
      self->last_error = std::string(module ? module : "") + "::" + (function ? function : "") +
                         ": " + (msg ? msg : "");
    }
  }

  // ---- set-up ----
  Status Fail(int flag, const char* what) {
    std::string m = std::string("CVODES ") + what + " failed: " + FlagName(flag);
    if (!callback_error.empty()) m += " (" + callback_error + ")";
    if (!last_error.empty()) m += " [" + last_error + "]";
    return Internal(m);
  }

  void FreeIntegrator() {
    if (ys != nullptr) N_VDestroyVectorArray(ys, ns);
    ys = nullptr;
    ns = 0;
    sens_on = false;
    if (mem != nullptr) CVodeFree(&mem);
    mem = nullptr;
    if (solver != nullptr) SUNLinSolFree(solver);
    solver = nullptr;
    if (matrix != nullptr) SUNMatDestroy(matrix);
    matrix = nullptr;
    for (N_Vector* v : {&y, &tmp, &q, &qtmp}) {
      if (*v != nullptr) N_VDestroy(*v);
      *v = nullptr;
    }
    dim = 0;
    num_measures = 0;
    num_roots = 0;
  }

  Status EnsureIntegrator(int n) {
    if (mem != nullptr && n == dim) return Status::Ok();
    FreeIntegrator();
    if (ctx == nullptr && SUNContext_Create(nullptr, &ctx) != 0) {
      return Internal("SUNContext_Create failed");
    }
    y = N_VNew_Serial(n, ctx);
    tmp = N_VNew_Serial(n, ctx);
    matrix = SUNDenseMatrix(n, n, ctx);
    if (y == nullptr || tmp == nullptr || matrix == nullptr) {
      FreeIntegrator();
      return Internal("CVODES: allocation of the state vector or matrix failed");
    }
    N_VConst(0.0, y);
    solver = SUNLinSol_Dense(y, matrix, ctx);
    mem = CVodeCreate(options.bdf ? CV_BDF : CV_ADAMS, ctx);
    if (solver == nullptr || mem == nullptr) {
      FreeIntegrator();
      return Internal("CVODES: CVodeCreate or SUNLinSol_Dense failed");
    }
    dim = n;
    int flag = CVodeSetErrHandlerFn(mem, &Impl::ErrHandler, this);
    if (flag == CV_SUCCESS) flag = CVodeInit(mem, &Impl::Rhs, 0.0, y);
    if (flag == CV_SUCCESS) flag = CVodeSetUserData(mem, this);
    if (flag == CV_SUCCESS) flag = CVodeSStolerances(mem, options.rtol, options.atol);
    if (flag == CV_SUCCESS) flag = CVodeSetLinearSolver(mem, solver, matrix);
    if (flag == CV_SUCCESS) flag = CVodeSetJacFn(mem, &Impl::Jac);
    if (flag == CV_SUCCESS) flag = CVodeSetMaxNumSteps(mem, options.max_steps);
    if (flag == CV_SUCCESS) flag = CVodeSetNoInactiveRootWarn(mem);
    if (flag != CV_SUCCESS) {
      Status s = Fail(flag, "initialisation");
      FreeIntegrator();
      return s;
    }
    return Status::Ok();
  }

  struct Setup {
    int mode = 0;
    const StateVector* x0 = nullptr;
    double t_stop = 0.0;
    int active_guards = 0;  // the mode's guards when events are located, 0 for FlowMap
    bool quadrature = false;
    int state_sens = 0;  // number of state sensitivity columns (0 or n)
    int param_sens = 0;  // number of parameter sensitivity columns (0 or num_params)
  };

  // Prepares the integrator for one call from t = 0.
  Status Prepare(const Setup& s, const Params& p) {
    last_error.clear();
    callback_error.clear();
    Status st = EnsureIntegrator(static_cast<int>(s.x0->size()));
    if (!st.ok()) return st;
    active_mode = s.mode;
    active_params = p;
    FromState(*s.x0, y);
    int flag = CVodeReInit(mem, 0.0, y);
    if (flag != CV_SUCCESS) return Fail(flag, "CVodeReInit");

    // Root functions.
    int max_guards = 0;
    for (int m = 0; m < model.num_modes(); ++m) {
      max_guards = std::max(max_guards, static_cast<int>(model.guards(m).size()));
    }
    if (2 * max_guards != num_roots) {
      flag = CVodeRootInit(mem, 2 * max_guards, max_guards > 0 ? &Impl::Roots : nullptr);
      if (flag != CV_SUCCESS) return Fail(flag, "CVodeRootInit");
      num_roots = 2 * max_guards;
    }
    active_guards = s.active_guards;
    if (num_roots > 0) {
      root_dirs.resize(num_roots);
      roots_found.resize(num_roots);
      for (int i = 0; i < num_roots; ++i) root_dirs[i] = (i % 2 == 0) ? -1 : +1;
      flag = CVodeSetRootDirection(mem, root_dirs.data());
      if (flag != CV_SUCCESS) return Fail(flag, "CVodeSetRootDirection");
    }

    // Quadratures.
    const int want_nq = s.quadrature ? static_cast<int>(model.measure_names().size()) : 0;
    if (q != nullptr && want_nq != num_measures) {
      CVodeQuadFree(mem);
      N_VDestroy(q);
      N_VDestroy(qtmp);
      q = qtmp = nullptr;
      num_measures = 0;
    }
    if (want_nq > 0) {
      if (q == nullptr) {
        q = N_VNew_Serial(want_nq, ctx);
        qtmp = N_VNew_Serial(want_nq, ctx);
        if (q == nullptr || qtmp == nullptr)
          return Internal("CVODES: quadrature allocation failed");
        N_VConst(0.0, q);
        flag = CVodeQuadInit(mem, &Impl::Quad, q);
        if (flag == CV_SUCCESS) flag = CVodeQuadSStolerances(mem, options.rtol, options.atol);
        if (flag == CV_SUCCESS) flag = CVodeSetQuadErrCon(mem, SUNTRUE);
        if (flag != CV_SUCCESS) {
          Status failed = Fail(flag, "CVodeQuadInit");
          FreeIntegrator();  // start afresh next time
          return failed;
        }
        num_measures = want_nq;
      } else {
        N_VConst(0.0, q);
        flag = CVodeQuadReInit(mem, q);
        if (flag != CV_SUCCESS) return Fail(flag, "CVodeQuadReInit");
      }
    }

    // Sensitivities.
    const int want_ns = s.state_sens + s.param_sens;
    if (want_ns > 0) {
      num_state_sens = s.state_sens;
      if (ys != nullptr && ns != want_ns) {
        CVodeSensFree(mem);
        N_VDestroyVectorArray(ys, ns);
        ys = nullptr;
        ns = 0;
        sens_on = false;
      }
      const bool fresh = (ys == nullptr);
      if (fresh) {
        ys = N_VCloneVectorArray(want_ns, y);
        if (ys == nullptr) return Internal("CVODES: sensitivity allocation failed");
        ns = want_ns;
      }
      for (int is = 0; is < ns; ++is) {
        N_VConst(0.0, ys[is]);
        if (is < num_state_sens) MutableData(ys[is])[is] = 1.0;  // d x0 / d x0 = I
      }
      if (fresh) {
        flag = CVodeSensInit(mem, ns, CV_STAGGERED, &Impl::SensRhs, ys);
        if (flag == CV_SUCCESS) flag = CVodeSensEEtolerances(mem);
        if (flag == CV_SUCCESS) flag = CVodeSetSensErrCon(mem, SUNTRUE);
        if (flag != CV_SUCCESS) {
          Status failed = Fail(flag, "CVodeSensInit");
          FreeIntegrator();  // start afresh next time
          return failed;
        }
      } else {
        flag = CVodeSensReInit(mem, CV_STAGGERED, ys);
        if (flag != CV_SUCCESS) return Fail(flag, "CVodeSensReInit");
      }
      sens_on = true;
    } else if (sens_on) {
      flag = CVodeSensToggleOff(mem);
      if (flag != CV_SUCCESS) return Fail(flag, "CVodeSensToggleOff");
      sens_on = false;
    }

    // Step bound and stop time.
    double hmax = 0.0;  // 0: no bound
    if (options.max_step_fraction > 0.0) {
      const double scale = model.TimeScale(s.mode, p);
      if (std::isfinite(scale) && scale > 0.0) hmax = options.max_step_fraction * scale;
    }
    flag = CVodeSetMaxStep(mem, hmax);
    if (flag == CV_SUCCESS) flag = CVodeSetStopTime(mem, s.t_stop);
    if (flag == CV_SUCCESS) flag = CVodeSetMaxNumSteps(mem, options.max_steps);
    if (flag != CV_SUCCESS) return Fail(flag, "set-up");
    return Status::Ok();
  }

  // Whether a crossing of guard i at x with values g is tangential at the integrator's accuracy:
  // its local parabola dips at most d_graze below the surface (see the file comment).
  bool Shallow(int i, const StateVector& x, const GuardValue& g) const {
    return g.dh >= 0.0 || g.dh * g.dh <= 2.0 * std::abs(g.ddh) * GrazeDepth(i, x);
  }

  // d_graze of guard i at x (see the file comment).
  double GrazeDepth(int i, const StateVector& x) const {
    const StateRow grad = model.GuardGradient(active_mode, i, x, active_params);
    double acc = 0.0;
    const int n = std::min<int>(static_cast<int>(grad.size()), static_cast<int>(x.size()));
    for (int j = 0; j < n; ++j) {
      acc += std::abs(grad[j]) * (options.rtol * std::abs(x[j]) + options.atol);
    }
    if (!std::isfinite(acc)) acc = 0.0;
    return std::max(options.events.tolerance, kGrazeResolution * acc);
  }

  // State (and measures into *m when quadratures are on) at time t within the last step.
  Status DenseOutput(double t, StateVector* x, MeasureVector* m) {
    int flag = CVodeGetDky(mem, t, 0, tmp);
    if (flag != CV_SUCCESS) return Fail(flag, "CVodeGetDky");
    *x = ToState(tmp, dim);
    if (m != nullptr && q != nullptr) {
      flag = CVodeGetQuadDky(mem, t, 0, qtmp);
      if (flag != CV_SUCCESS) return Fail(flag, "CVodeGetQuadDky");
      *m = Eigen::Map<const Eigen::VectorXd>(Data(qtmp), num_measures);
    }
    return Status::Ok();
  }

  // Measures at the last return time.
  Status CurrentMeasures(MeasureVector* m) {
    if (q == nullptr) return Status::Ok();
    double t = 0.0;
    const int flag = CVodeGetQuad(mem, &t, q);
    if (flag != CV_SUCCESS) return Fail(flag, "CVodeGetQuad");
    *m = Eigen::Map<const Eigen::VectorXd>(Data(q), num_measures);
    return Status::Ok();
  }

  // The first zero of guard i's h in [ta, tb] (inside the last step; h(ta) > 0 >= h(tb)) on the
  // dense output: first sign change on a uniform grid, then bisection to adjacent doubles.
  // Returns the time, the state and (when quadratures are on) the measures there.
  Status LocateCrossing(int i, double ta, double tb, double* tc, StateVector* xc,
                        MeasureVector* mc) {
    StateVector xt;
    auto h_at = [&](double t, double* h) -> Status {
      Status s = DenseOutput(t, &xt, nullptr);
      if (s.ok()) *h = model.Guard(active_mode, i, xt, active_params).h;
      return s;
    };
    double h = 0.0;
    Status s = h_at(ta, &h);
    if (!s.ok()) return s;
    if (h > 0.0) {
      constexpr int kGrid = 16;
      double lo = ta;
      for (int k = 1; k <= kGrid; ++k) {
        const double tk = (k == kGrid) ? tb : ta + (tb - ta) * k / kGrid;
        if (!(s = h_at(tk, &h)).ok()) return s;
        if (!(h > 0.0)) {
          ta = lo;
          tb = tk;
          break;
        }
        lo = tk;
      }
      for (int it = 0; it < 200; ++it) {
        const double tm = 0.5 * (ta + tb);
        if (tm <= ta || tm >= tb) break;
        if (!(s = h_at(tm, &h)).ok()) return s;
        if (h > 0.0) {
          ta = tm;
        } else {
          tb = tm;
        }
      }
    } else {
      tb = ta;  // already on or below the surface at the start of the interval
    }
    *tc = tb;
    return DenseOutput(tb, xc, mc);
  }

  // The bodies of CvodePropagator::FlowMap and Advance (which add exception safety).
  FlowResult RunFlowMap(int mode, const StateVector& x0, double t, const Params& params,
                        const FlowRequest& request);
  AdvanceResult RunAdvance(const AdvanceRequest& request, const Params& params);
};

CvodePropagator::CvodePropagator(const HybridModel& model, CvodeOptions options)
    : model_(model),
      options_(std::move(options)),
      impl_(std::make_unique<Impl>(model_, options_)) {}

CvodePropagator::~CvodePropagator() = default;

FlowResult CvodePropagator::Impl::RunFlowMap(int mode, const StateVector& x0, double t,
                                             const Params& params, const FlowRequest& request) {
  FlowResult r;
  r.x = x0;
  r.status = CheckCommon(model, options, mode, x0, params);
  if (r.status.ok() && !(t >= 0.0 && std::isfinite(t))) {
    r.status =
        InvalidArgument("FlowMap time must be finite and >= 0 (got " + FormatDouble(t) + ")");
  }
  if (!r.status.ok()) return r;
  const int n = model.state_dim();
  const int np = model.num_params();
  if (request.state_jacobian) r.state_jacobian = StateMatrix::Identity(n, n);
  if (request.param_jacobian) r.param_jacobian = ParamMatrix::Zero(n, np);
  if (t == 0.0) return r;

  Setup s;
  s.mode = mode;
  s.x0 = &x0;
  s.t_stop = t;
  s.state_sens = request.state_jacobian ? n : 0;
  s.param_sens = request.param_jacobian ? np : 0;
  Status st = Prepare(s, params);
  if (!st.ok()) {
    r.status = st;
    return r;
  }
  double tret = 0.0;
  const int flag = CVode(mem, t, y, &tret, CV_NORMAL);
  if (flag < 0) {
    r.status = Fail(flag, "CVode");
    return r;
  }
  r.x = ToState(y, n);
  if (s.state_sens + s.param_sens > 0) {
    const int gflag = CVodeGetSens(mem, &tret, ys);
    if (gflag != CV_SUCCESS) {
      r.status = Fail(gflag, "CVodeGetSens");
      return r;
    }
    for (int c = 0; c < s.state_sens; ++c) r.state_jacobian.col(c) = ToState(ys[c], n);
    for (int k = 0; k < s.param_sens; ++k) {
      r.param_jacobian.col(k) = ToState(ys[s.state_sens + k], n);
    }
  }
  if (!r.x.allFinite() || (request.state_jacobian && !r.state_jacobian.allFinite()) ||
      (request.param_jacobian && !r.param_jacobian.allFinite())) {
    r.status = Internal("CVODES FlowMap produced a non-finite result in mode " +
                        std::string(model.mode_name(mode)) + " at t = " + FormatDouble(t));
  }
  return r;
}

AdvanceResult CvodePropagator::Impl::RunAdvance(const AdvanceRequest& request,
                                                const Params& params) {
  AdvanceResult res;
  res.x = request.x0;
  res.status = CheckCommon(model, options, request.mode, request.x0, params);
  if (res.status.ok() && !(request.t_max >= 0.0 && std::isfinite(request.t_max))) {
    res.status = InvalidArgument("AdvanceRequest.t_max must be finite and >= 0 (got " +
                                 FormatDouble(request.t_max) + ")");
  }
  if (res.status.ok() && !(request.sample_dt >= 0.0 && std::isfinite(request.sample_dt))) {
    res.status = InvalidArgument("AdvanceRequest.sample_dt must be finite and >= 0 (got " +
                                 FormatDouble(request.sample_dt) + ")");
  }
  if (res.status.ok() && request.measures &&
      static_cast<int>(model.measure_names().size()) > kMaxMeasures) {
    res.status = InvalidArgument("the model has more than kMaxMeasures measures");
  }
  if (!res.status.ok()) return res;

  const int mode = request.mode;
  const int n = model.state_dim();
  const int ng = static_cast<int>(model.guards(mode).size());
  const int nq = static_cast<int>(model.measure_names().size());
  const double tol = options.events.tolerance;
  const double sample_dt = request.sample_dt;
  if (request.measures) res.measures = MeasureVector::Zero(nq);

  auto fail = [&res](Status st) {
    res.status = std::move(st);
    res.end = AdvanceEnd::kFailed;
  };
  // Ends the segment at (t, x) with measures m: drops samples at or after t, adds the end point.
  auto finish = [&](AdvanceEnd end, int guard, bool tangential, double t, const StateVector& x,
                    const MeasureVector& m) {
    res.end = end;
    res.guard = guard;
    res.tangential = tangential;
    res.duration = t;
    res.x = x;
    if (request.measures) res.measures = m;
    if (sample_dt > 0.0) {
      while (!res.samples.empty() && res.samples.back().t >= t) res.samples.pop_back();
      res.samples.push_back(TrajectorySample{t, x});
    }
    if (!res.x.allFinite() || (request.measures && !res.measures.allFinite())) {
      fail(Internal("CVODES Advance produced a non-finite state or measure in mode " +
                    std::string(model.mode_name(mode))));
    }
  };

  // ---- start: guards already on their surface (see the file comment) ----
  armed.assign(ng, 1);
  for (int i = 0; i < ng; ++i) {
    const GuardValue g = model.Guard(mode, i, request.x0, params);
    if (!Finite(g)) {
      fail(Internal("guard " + model.guards(mode)[i].name + " is not finite at x0"));
      return res;
    }
    if (g.h > tol) continue;
    if (internal::MovesInto(g, tol)) {
      // Tangential as in the exact propagator: a touch from inside the band, or a slow approach.
      finish(AdvanceEnd::kEvent, i, g.h > 0.0 || g.dh * g.dh <= 2.0 * tol, 0.0, request.x0,
             res.measures);
      return res;
    }
    armed[i] = 0;  // leaving the surface
  }
  if (request.t_max == 0.0) {
    finish(AdvanceEnd::kTimeLimit, -1, false, 0.0, request.x0, res.measures);
    return res;
  }

  Setup setup;
  setup.mode = mode;
  setup.x0 = &request.x0;
  setup.t_stop = request.t_max;
  setup.active_guards = ng;
  setup.quadrature = request.measures && nq > 0;
  Status st = Prepare(setup, params);
  if (!st.ok()) {
    fail(st);
    return res;
  }

  long next_sample = 0;
  if (sample_dt > 0.0) {
    res.samples.push_back(TrajectorySample{0.0, request.x0});
    next_sample = 1;
  }

  // The earliest event found at one return (ties: lowest guard index).
  struct Candidate {
    int guard = -1;
    double t = 0.0;
    bool tangential = false;
    StateVector x;
    MeasureVector m;
  } ev;
  auto consider = [&ev](int i, double t, bool tangential, const StateVector& x,
                        const MeasureVector& m) {
    if (ev.guard >= 0 && (ev.t < t || (ev.t == t && ev.guard <= i))) return;
    ev.guard = i;
    ev.t = t;
    ev.tangential = tangential;
    ev.x = x;
    ev.m = m;
  };

  double t_prev = 0.0;
  int root_returns = 0;
  MeasureVector m_now = res.measures;
  while (true) {
    double tret = 0.0;
    const int flag = CVode(mem, request.t_max, y, &tret, CV_ONE_STEP);
    long nfe = 0;
    CVodeGetNumRhsEvals(mem, &nfe);
    res.evaluations = static_cast<int>(std::min<long>(nfe, std::numeric_limits<int>::max()));
    if (flag < 0) {
      res.duration = t_prev;
      fail(Fail(flag, "CVode"));
      return res;
    }
    const StateVector x = ToState(y, n);
    long nst = 0;
    CVodeGetNumSteps(mem, &nst);
    if (nst > options.max_steps) {
      res.duration = tret;
      res.x = x;
      fail(Internal("CVODES Advance: more than max_steps = " + std::to_string(options.max_steps) +
                    " internal steps before t_max or an event (CV_TOO_MUCH_WORK)"));
      return res;
    }

    // Samples in (t_prev, tret], from the dense output of the current step.
    if (sample_dt > 0.0) {
      while (static_cast<double>(next_sample) * sample_dt <= tret) {
        const double ts = static_cast<double>(next_sample) * sample_dt;
        StateVector xs = x;
        if (ts != tret) {
          st = DenseOutput(ts, &xs, nullptr);
          if (!st.ok()) {
            fail(st);
            return res;
          }
        }
        res.samples.push_back(TrajectorySample{ts, xs});
        ++next_sample;
        if (res.samples.size() > kMaxSamples) {
          fail(OutOfRange("Advance: more than " + std::to_string(kMaxSamples) +
                          " trajectory samples (sample_dt too small for t_max)"));
          return res;
        }
      }
    }

    ev.guard = -1;
    if (flag == CV_ROOT_RETURN) {
      st = CurrentMeasures(&m_now);
      if (!st.ok()) {
        fail(st);
        return res;
      }
    }

    // Guards that started on their surface take part once they have left the band; one that
    // falls through it instead fires at the start of the step (as in the exact propagator).
    // A root of a masked function means that the guard left the band inside the step (h' then
    // had a root with h > tol, or h came back down through tol): it is armed here too. Roots
    // reported at this return for a guard armed only now came from its masked functions and
    // are not events (skipped below).
    if (flag == CV_ROOT_RETURN) {
      const int rflag = CVodeGetRootInfo(mem, roots_found.data());
      if (rflag != CV_SUCCESS) {
        fail(Fail(rflag, "CVodeGetRootInfo"));
        return res;
      }
    }
    armed_before.assign(armed.begin(), armed.end());
    for (int i = 0; i < ng; ++i) {
      if (armed[i]) continue;
      const double h = model.Guard(mode, i, x, params).h;
      const bool masked_root =
          flag == CV_ROOT_RETURN && (roots_found[2 * i] != 0 || roots_found[2 * i + 1] != 0);
      if (h > tol || (masked_root && h >= -tol)) {
        armed[i] = 1;
      } else if (h < -tol) {
        StateVector xp;
        MeasureVector mp = m_now;
        st = DenseOutput(t_prev, &xp, &mp);
        if (!st.ok()) {
          fail(st);
          return res;
        }
        consider(i, t_prev, false, xp, mp);
      }
    }

    if (flag == CV_ROOT_RETURN) {
      if (++root_returns > options.events.max_iterations) {
        fail(Internal("CVODES Advance: more than events.max_iterations = " +
                      std::to_string(options.events.max_iterations) + " root returns"));
        return res;
      }
      for (int i = 0; i < ng; ++i) {
        if (!armed_before[i]) continue;
        const bool crossing = roots_found[2 * i] < 0;     // h decreasing through 0
        const bool minimum = roots_found[2 * i + 1] > 0;  // h' increasing through 0
        if (!crossing && !minimum) continue;
        const GuardValue g = model.Guard(mode, i, x, params);
        if (!Finite(g)) {
          fail(Internal("guard " + model.guards(mode)[i].name + " is not finite"));
          return res;
        }
        if (crossing) {
          consider(i, tret, Shallow(i, x, g), x, m_now);
        } else if (g.h > 0.0 && g.h <= tol) {
          consider(i, tret, true, x, m_now);  // turned back inside the band: a graze
        } else if (g.h <= 0.0) {
          // Both crossings of a dip fell inside the last step: report the first one.
          double tc = 0.0;
          StateVector xc;
          MeasureVector mc = m_now;
          st = LocateCrossing(i, t_prev, tret, &tc, &xc, &mc);
          if (!st.ok()) {
            fail(st);
            return res;
          }
          consider(i, tc, Shallow(i, xc, model.Guard(mode, i, xc, params)), xc, mc);
        }
      }
    }

    if (ev.guard >= 0) {
      finish(AdvanceEnd::kEvent, ev.guard, ev.tangential, ev.t, ev.x, ev.m);
      return res;
    }
    if (flag == CV_TSTOP_RETURN || tret >= request.t_max) {
      st = CurrentMeasures(&m_now);
      if (!st.ok()) {
        fail(st);
        return res;
      }
      finish(AdvanceEnd::kTimeLimit, -1, false, tret, x, m_now);
      return res;
    }
    t_prev = tret;
  }
}

FlowResult CvodePropagator::FlowMap(int mode, const StateVector& x0, double t, const Params& params,
                                    const FlowRequest& request) {
  try {
    return impl_->RunFlowMap(mode, x0, t, params, request);
  } catch (const std::exception& e) {
    FlowResult r;
    r.x = x0;
    r.status = Internal(std::string("CvodePropagator::FlowMap: ") + e.what());
    return r;
  } catch (...) {
    FlowResult r;
    r.x = x0;
    r.status = Internal("CvodePropagator::FlowMap: unknown exception");
    return r;
  }
}

AdvanceResult CvodePropagator::Advance(const AdvanceRequest& request, const Params& params) {
  try {
    return impl_->RunAdvance(request, params);
  } catch (const std::exception& e) {
    AdvanceResult r;
    r.x = request.x0;
    r.status = Internal(std::string("CvodePropagator::Advance: ") + e.what());
    return r;
  } catch (...) {
    AdvanceResult r;
    r.x = request.x0;
    r.status = Internal("CvodePropagator::Advance: unknown exception");
    return r;
  }
}

}  // namespace drillbif
