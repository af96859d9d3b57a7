// CvodeIntegrator's SUNDIALS callbacks: right-hand side, Jacobian, root functions, quadratures,
// sensitivities and the error handler (see flow/cvode_integrator.h).
//
// A non-finite value from the model is unrecoverable: retrying with smaller steps would only
// creep up to the boundary of the model's domain for max_steps steps.
#include <sunmatrix/sunmatrix_dense.h>

#include <cmath>
#include <exception>
#include <string>

#include "flow/cvode_integrator.h"
#include "flow/cvode_util.h"

namespace drillbif::internal {
namespace {

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

}  // namespace

int CvodeIntegrator::Rhs(double t, N_Vector yv, N_Vector ydot, void* data) {
  auto* self = static_cast<CvodeIntegrator*>(data);
  // A stop ends the integration: an unrecoverable right-hand-side failure returns from CVode at
  // once (however long the call still had to go).
  if (self->progress_ != nullptr && !self->progress_->Tick()) {
    self->cancelled_ = true;
    return -1;
  }
  try {
    StateVector dx;
    const StateVector x = ToState(yv, self->dim_);
    self->model_.VectorField(self->active_mode_, x, self->active_params_, &dx);
    if (dx.size() != self->dim_ || !dx.allFinite()) {
      self->callback_error_ =
          "VectorField is not finite at t = " + FormatDouble(t) + ", x = " + FormatState(x);
      return -1;
    }
    FromState(dx, ydot);
    return 0;
  } catch (const std::exception& e) {
    self->callback_error_ = std::string("VectorField threw: ") + e.what();
  } catch (...) {
    self->callback_error_ = "VectorField threw";
  }
  return -1;
}

int CvodeIntegrator::Jac(double t, N_Vector yv, N_Vector /*fy*/, SUNMatrix jm, void* data,
                         N_Vector /*t1*/, N_Vector /*t2*/, N_Vector /*t3*/) {
  auto* self = static_cast<CvodeIntegrator*>(data);
  try {
    StateMatrix j;
    const StateVector x = ToState(yv, self->dim_);
    self->model_.StateJacobian(self->active_mode_, x, self->active_params_, &j);
    if (j.rows() != self->dim_ || j.cols() != self->dim_ || !j.allFinite()) {
      self->callback_error_ =
          "StateJacobian is not finite at t = " + FormatDouble(t) + ", x = " + FormatState(x);
      return -1;
    }
    for (int c = 0; c < self->dim_; ++c) {
      double* col = SUNDenseMatrix_Column(jm, c);
      for (int r = 0; r < self->dim_; ++r) col[r] = j(r, c);
    }
    return 0;
  } catch (const std::exception& e) {
    self->callback_error_ = std::string("StateJacobian threw: ") + e.what();
  } catch (...) {
    self->callback_error_ = "StateJacobian threw";
  }
  return -1;
}

// Root functions (see "Root functions" in the file comment of flow/cvode_advance.cc): h and h' of
// armed guards; a departing guard's are masked while it is inside the band, and no value is ever
// exactly zero.
int CvodeIntegrator::Roots(double /*t*/, N_Vector yv, double* gout, void* data) {
  auto* self = static_cast<CvodeIntegrator*>(data);
  try {
    const StateVector x = ToState(yv, self->dim_);
    const int ng = self->active_guards_;
    const double tol = self->options_.events.tolerance;
    for (int i = ng; i < self->num_roots_ / 2; ++i) gout[2 * i] = gout[2 * i + 1] = 1.0;
    for (int i = 0; i < ng; ++i) {
      const GuardValue g = self->model_.Guard(self->active_mode_, i, x, self->active_params_);
      if (!std::isfinite(g.h) || !std::isfinite(g.dh)) {
        self->callback_error_ = "guard " + std::to_string(i) + " is not finite";
        return -1;
      }
      double gh = g.h, gdh = g.dh;
      if (!self->armed_[i] && !(g.h > tol)) {
        gh = tol;   // max(h, tol): no root, and equal to h where the guard leaves the band
        gdh = 1.0;  // no root of h' in the direction sought (increasing)
      }
      gout[2 * i] = NonZero(gh);
      gout[2 * i + 1] = NonZero(gdh);
    }
    return 0;
  } catch (const std::exception& e) {
    self->callback_error_ = std::string("Guard threw: ") + e.what();
  } catch (...) {
    self->callback_error_ = "Guard threw";
  }
  return -1;
}

int CvodeIntegrator::Quad(double t, N_Vector yv, N_Vector qdot, void* data) {
  auto* self = static_cast<CvodeIntegrator*>(data);
  try {
    const StateVector x = ToState(yv, self->dim_);
    const MeasureVector m = self->model_.MeasureRates(self->active_mode_, x, self->active_params_);
    if (m.size() != self->num_measures_ || !m.allFinite()) {
      self->callback_error_ =
          "MeasureRates is not finite at t = " + FormatDouble(t) + ", x = " + FormatState(x);
      return -1;
    }
    Eigen::Map<Eigen::VectorXd>(MutableData(qdot), self->num_measures_) = m;
    return 0;
  } catch (const std::exception& e) {
    self->callback_error_ = std::string("MeasureRates threw: ") + e.what();
  } catch (...) {
    self->callback_error_ = "MeasureRates threw";
  }
  return -1;
}

// All sensitivities at once: s_i' = J s_i (+ df/dp_k for a parameter column), so that the
// Jacobians are evaluated once per call rather than once per sensitivity.
int CvodeIntegrator::SensRhs(int num, double t, N_Vector yv, N_Vector /*ydot*/, N_Vector* yS,
                             N_Vector* ySdot, void* data, N_Vector /*t1*/, N_Vector /*t2*/) {
  auto* self = static_cast<CvodeIntegrator*>(data);
  try {
    const StateVector x = ToState(yv, self->dim_);
    StateMatrix j;
    self->model_.StateJacobian(self->active_mode_, x, self->active_params_, &j);
    ParamMatrix pj;
    if (num > self->num_state_sens_) {
      self->model_.ParamJacobian(self->active_mode_, x, self->active_params_, &pj);
    }
    if (!j.allFinite() || (num > self->num_state_sens_ && !pj.allFinite())) {
      self->callback_error_ =
          "StateJacobian or ParamJacobian is not finite at t = " + FormatDouble(t) +
          ", x = " + FormatState(x);
      return -1;
    }
    for (int is = 0; is < num; ++is) {
      Eigen::Map<const Eigen::VectorXd> s(Data(yS[is]), self->dim_);
      Eigen::Map<Eigen::VectorXd> sdot(MutableData(ySdot[is]), self->dim_);
      sdot = j * s;
      if (is >= self->num_state_sens_) sdot += pj.col(is - self->num_state_sens_);
    }
    return 0;
  } catch (const std::exception& e) {
    self->callback_error_ = std::string("sensitivity right-hand side threw: ") + e.what();
  } catch (...) {
    self->callback_error_ = "sensitivity right-hand side threw";
  }
  return -1;
}

void CvodeIntegrator::ErrHandler(int code, const char* module, const char* function, char* msg,
                                 void* data) {
  auto* self = static_cast<CvodeIntegrator*>(data);
  if (code < 0) {  // errors only; warnings are not printed either
    self->last_error_ = std::string(module ? module : "") + "::" + (function ? function : "") +
                        ": " + (msg ? msg : "");
  }
}

}  // namespace drillbif::internal
