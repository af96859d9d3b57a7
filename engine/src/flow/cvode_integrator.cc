// CvodeIntegrator: allocation and per-call set-up of the CVODES objects, and access to their
// results (see flow/cvode_integrator.h; the callbacks are in flow/cvode_integrator_callbacks.cc).
#include "flow/cvode_integrator.h"

#include <nvector/nvector_serial.h>
#include <sunlinsol/sunlinsol_dense.h>
#include <sunmatrix/sunmatrix_dense.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <string>

#include "flow/cvode_util.h"

namespace drillbif::internal {
namespace {

// CVodeGetReturnFlagName allocates the string it returns.
std::string FlagName(int flag) {
  char* name = CVodeGetReturnFlagName(flag);
  if (name == nullptr) return "flag " + std::to_string(flag);
  std::string s(name);
  std::free(name);
  return s;
}

}  // namespace

CvodeIntegrator::~CvodeIntegrator() {
  FreeIntegrator();
  if (ctx_ != nullptr) SUNContext_Free(&ctx_);
}

Status CvodeIntegrator::Fail(int flag, const char* what) const {
  std::string m = std::string("CVODES ") + what + " failed: " + FlagName(flag);
  if (!callback_error_.empty()) m += " (" + callback_error_ + ")";
  if (!last_error_.empty()) m += " [" + last_error_ + "]";
  return Internal(m);
}

void CvodeIntegrator::FreeIntegrator() {
  if (ys_ != nullptr) N_VDestroyVectorArray(ys_, ns_);
  ys_ = nullptr;
  ns_ = 0;
  sens_on_ = false;
  if (mem_ != nullptr) CVodeFree(&mem_);
  mem_ = nullptr;
  if (solver_ != nullptr) SUNLinSolFree(solver_);
  solver_ = nullptr;
  if (matrix_ != nullptr) SUNMatDestroy(matrix_);
  matrix_ = nullptr;
  for (N_Vector* v : {&y_, &tmp_, &q_, &qtmp_}) {
    if (*v != nullptr) N_VDestroy(*v);
    *v = nullptr;
  }
  dim_ = 0;
  num_measures_ = 0;
  num_roots_ = 0;
}

Status CvodeIntegrator::EnsureIntegrator(int n) {
  if (mem_ != nullptr && n == dim_) return Status::Ok();
  FreeIntegrator();
  if (ctx_ == nullptr && SUNContext_Create(nullptr, &ctx_) != 0) {
    return Internal("SUNContext_Create failed");
  }
  y_ = N_VNew_Serial(n, ctx_);
  tmp_ = N_VNew_Serial(n, ctx_);
  matrix_ = SUNDenseMatrix(n, n, ctx_);
  if (y_ == nullptr || tmp_ == nullptr || matrix_ == nullptr) {
    FreeIntegrator();
    return Internal("CVODES: allocation of the state vector or matrix failed");
  }
  N_VConst(0.0, y_);
  solver_ = SUNLinSol_Dense(y_, matrix_, ctx_);
  mem_ = CVodeCreate(options_.bdf ? CV_BDF : CV_ADAMS, ctx_);
  if (solver_ == nullptr || mem_ == nullptr) {
    FreeIntegrator();
    return Internal("CVODES: CVodeCreate or SUNLinSol_Dense failed");
  }
  dim_ = n;
  int flag = CVodeSetErrHandlerFn(mem_, &CvodeIntegrator::ErrHandler, this);
  if (flag == CV_SUCCESS) flag = CVodeInit(mem_, &CvodeIntegrator::Rhs, 0.0, y_);
  if (flag == CV_SUCCESS) flag = CVodeSetUserData(mem_, this);
  if (flag == CV_SUCCESS) flag = CVodeSStolerances(mem_, options_.rtol, options_.atol);
  if (flag == CV_SUCCESS) flag = CVodeSetLinearSolver(mem_, solver_, matrix_);
  if (flag == CV_SUCCESS) flag = CVodeSetJacFn(mem_, &CvodeIntegrator::Jac);
  if (flag == CV_SUCCESS) flag = CVodeSetMaxNumSteps(mem_, options_.max_steps);
  if (flag == CV_SUCCESS) flag = CVodeSetNoInactiveRootWarn(mem_);
  if (flag != CV_SUCCESS) {
    Status s = Fail(flag, "initialisation");
    FreeIntegrator();
    return s;
  }
  return Status::Ok();
}

Status CvodeIntegrator::Prepare(const Setup& s, const Params& p) {
  last_error_.clear();
  callback_error_.clear();
  Status st = EnsureIntegrator(static_cast<int>(s.x0->size()));
  if (!st.ok()) return st;
  active_mode_ = s.mode;
  active_params_ = p;
  FromState(*s.x0, y_);
  int flag = CVodeReInit(mem_, 0.0, y_);
  if (flag != CV_SUCCESS) return Fail(flag, "CVodeReInit");

  // Root functions.
  int max_guards = 0;
  for (int m = 0; m < model_.num_modes(); ++m) {
    max_guards = std::max(max_guards, static_cast<int>(model_.guards(m).size()));
  }
  if (2 * max_guards != num_roots_) {
    flag = CVodeRootInit(mem_, 2 * max_guards, max_guards > 0 ? &CvodeIntegrator::Roots : nullptr);
    if (flag != CV_SUCCESS) return Fail(flag, "CVodeRootInit");
    num_roots_ = 2 * max_guards;
  }
  active_guards_ = s.active_guards;
  if (num_roots_ > 0) {
    root_dirs_.resize(num_roots_);
    roots_found_.resize(num_roots_);
    for (int i = 0; i < num_roots_; ++i) root_dirs_[i] = (i % 2 == 0) ? -1 : +1;
    flag = CVodeSetRootDirection(mem_, root_dirs_.data());
    if (flag != CV_SUCCESS) return Fail(flag, "CVodeSetRootDirection");
  }

  // Quadratures.
  const int want_nq = s.quadrature ? static_cast<int>(model_.measure_names().size()) : 0;
  if (q_ != nullptr && want_nq != num_measures_) {
    CVodeQuadFree(mem_);
    N_VDestroy(q_);
    N_VDestroy(qtmp_);
    q_ = qtmp_ = nullptr;
    num_measures_ = 0;
  }
  if (want_nq > 0) {
    if (q_ == nullptr) {
      q_ = N_VNew_Serial(want_nq, ctx_);
      qtmp_ = N_VNew_Serial(want_nq, ctx_);
      if (q_ == nullptr || qtmp_ == nullptr)
        return Internal("CVODES: quadrature allocation failed");
      N_VConst(0.0, q_);
      flag = CVodeQuadInit(mem_, &CvodeIntegrator::Quad, q_);
      if (flag == CV_SUCCESS) flag = CVodeQuadSStolerances(mem_, options_.rtol, options_.atol);
      if (flag == CV_SUCCESS) flag = CVodeSetQuadErrCon(mem_, SUNTRUE);
      if (flag != CV_SUCCESS) {
        Status failed = Fail(flag, "CVodeQuadInit");
        FreeIntegrator();  // start afresh next time
        return failed;
      }
      num_measures_ = want_nq;
    } else {
      N_VConst(0.0, q_);
      flag = CVodeQuadReInit(mem_, q_);
      if (flag != CV_SUCCESS) return Fail(flag, "CVodeQuadReInit");
    }
  }

  // Sensitivities.
  const int want_ns = s.state_sens + s.param_sens;
  if (want_ns > 0) {
    num_state_sens_ = s.state_sens;
    if (ys_ != nullptr && ns_ != want_ns) {
      CVodeSensFree(mem_);
      N_VDestroyVectorArray(ys_, ns_);
      ys_ = nullptr;
      ns_ = 0;
      sens_on_ = false;
    }
    const bool fresh = (ys_ == nullptr);
    if (fresh) {
      ys_ = N_VCloneVectorArray(want_ns, y_);
      if (ys_ == nullptr) return Internal("CVODES: sensitivity allocation failed");
      ns_ = want_ns;
    }
    for (int is = 0; is < ns_; ++is) {
      N_VConst(0.0, ys_[is]);
      if (is < num_state_sens_) MutableData(ys_[is])[is] = 1.0;  // d x0 / d x0 = I
    }
    if (fresh) {
      flag = CVodeSensInit(mem_, ns_, CV_STAGGERED, &CvodeIntegrator::SensRhs, ys_);
      if (flag == CV_SUCCESS) flag = CVodeSensEEtolerances(mem_);
      if (flag == CV_SUCCESS) flag = CVodeSetSensErrCon(mem_, SUNTRUE);
      if (flag != CV_SUCCESS) {
        Status failed = Fail(flag, "CVodeSensInit");
        FreeIntegrator();  // start afresh next time
        return failed;
      }
    } else {
      flag = CVodeSensReInit(mem_, CV_STAGGERED, ys_);
      if (flag != CV_SUCCESS) return Fail(flag, "CVodeSensReInit");
    }
    sens_on_ = true;
  } else if (sens_on_) {
    flag = CVodeSensToggleOff(mem_);
    if (flag != CV_SUCCESS) return Fail(flag, "CVodeSensToggleOff");
    sens_on_ = false;
  }

  // Step bound and stop time.
  double hmax = 0.0;  // 0: no bound
  if (options_.max_step_fraction > 0.0) {
    const double scale = model_.TimeScale(s.mode, p);
    if (std::isfinite(scale) && scale > 0.0) hmax = options_.max_step_fraction * scale;
  }
  flag = CVodeSetMaxStep(mem_, hmax);
  if (flag == CV_SUCCESS) flag = CVodeSetStopTime(mem_, s.t_stop);
  if (flag == CV_SUCCESS) flag = CVodeSetMaxNumSteps(mem_, options_.max_steps);
  if (flag != CV_SUCCESS) return Fail(flag, "set-up");
  return Status::Ok();
}

int CvodeIntegrator::Integrate(double tout, int itask, double* tret) {
  return CVode(mem_, tout, y_, tret, itask);
}

StateVector CvodeIntegrator::State() const { return ToState(y_, dim_); }

Status CvodeIntegrator::FetchSensitivities() {
  double tret = 0.0;
  const int flag = CVodeGetSens(mem_, &tret, ys_);
  if (flag != CV_SUCCESS) return Fail(flag, "CVodeGetSens");
  return Status::Ok();
}

StateVector CvodeIntegrator::Sensitivity(int is) const { return ToState(ys_[is], dim_); }

Status CvodeIntegrator::FetchRootInfo() {
  const int flag = CVodeGetRootInfo(mem_, roots_found_.data());
  if (flag != CV_SUCCESS) return Fail(flag, "CVodeGetRootInfo");
  return Status::Ok();
}

long CvodeIntegrator::NumRhsEvals() const {
  long nfe = 0;
  CVodeGetNumRhsEvals(mem_, &nfe);
  return nfe;
}

long CvodeIntegrator::NumSteps() const {
  long nst = 0;
  CVodeGetNumSteps(mem_, &nst);
  return nst;
}

Status CvodeIntegrator::DenseOutput(double t, StateVector* x, MeasureVector* m) {
  int flag = CVodeGetDky(mem_, t, 0, tmp_);
  if (flag != CV_SUCCESS) return Fail(flag, "CVodeGetDky");
  *x = ToState(tmp_, dim_);
  if (m != nullptr && q_ != nullptr) {
    flag = CVodeGetQuadDky(mem_, t, 0, qtmp_);
    if (flag != CV_SUCCESS) return Fail(flag, "CVodeGetQuadDky");
    *m = Eigen::Map<const Eigen::VectorXd>(Data(qtmp_), num_measures_);
  }
  return Status::Ok();
}

Status CvodeIntegrator::CurrentMeasures(MeasureVector* m) {
  if (q_ == nullptr) return Status::Ok();
  double t = 0.0;
  const int flag = CVodeGetQuad(mem_, &t, q_);
  if (flag != CV_SUCCESS) return Fail(flag, "CVodeGetQuad");
  *m = Eigen::Map<const Eigen::VectorXd>(Data(q_), num_measures_);
  return Status::Ok();
}

Status CvodeIntegrator::LocateCrossing(int i, double ta, double tb, double* tc, StateVector* xc,
                                       MeasureVector* mc) {
  StateVector xt;
  auto h_at = [&](double t, double* h) -> Status {
    Status s = DenseOutput(t, &xt, nullptr);
    if (s.ok()) *h = model_.Guard(active_mode_, i, xt, active_params_).h;
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

}  // namespace drillbif::internal
