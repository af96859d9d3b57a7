#include "drillbif/flow/exact_propagator.h"

#include <cstdint>
#include <string>
#include <unsupported/Eigen/MatrixFunctions>

#include "common/gauss_legendre.h"
#include "flow/safe_event_locator.h"

namespace drillbif {
namespace {

// Safety cap on trajectory samples of one Advance call (as the CVODE propagator's).
constexpr size_t kMaxSamples = 10000000;

}  // namespace

Status ExactOptions::Validate() const {
  if (!(quadrature_panel_fraction > 0.0 && quadrature_panel_fraction <= 1.0)) {
    return InvalidArgument("quadrature_panel_fraction must be in (0, 1]");
  }
  return events.Validate();
}

ExactPropagator::ExactPropagator(const HybridModel& model, ExactOptions options)
    : model_(model),
      linear_(dynamic_cast<const LinearForm*>(&model)),
      closed_(options.use_closed_form ? dynamic_cast<const ClosedFormFlow*>(&model) : nullptr),
      options_(options) {}

std::unique_ptr<Propagator> ExactPropagator::Clone() const {
  return std::make_unique<ExactPropagator>(model_, options_);
}

bool ExactPropagator::Supports(const HybridModel& model) {
  return dynamic_cast<const LinearForm*>(&model) != nullptr;
}

void ExactPropagator::StateAt(int mode, const StateVector& x0, double t, const Params& params,
                              StateVector* x, StateMatrix* jac) const {
  if (closed_) {
    closed_->Flow(mode, x0, t, params, x, jac);
    return;
  }
  // z(t) = expm(A t) z0; the phase advances exactly: s = s0 + omega t.
  const int n = model_.state_dim(), ps = model_.phase_index();
  Eigen::VectorXd z0;
  Eigen::MatrixXd a;
  linear_->ToAugmented(x0, params, &z0);
  linear_->AugmentedMatrix(mode, params, &a);
  const Eigen::MatrixXd e = (a * t).exp();
  const Eigen::VectorXd z = e * z0;
  x->resize(n);
  // Augmented rows 0..n-2 are the state without its phase, in state order.
  for (int i = 0, r = 0; i < n; ++i) {
    (*x)[i] = (i == ps) ? x0[ps] + model_.ForcingFrequency(params) * t : z[r++];
  }
  if (jac) {
    jac->setZero(n, n);
    const int m = n - 1;  // cos and sin of the phase sit at augmented rows m, m + 1
    for (int i = 0, r = 0; i < n; ++i) {
      if (i == ps) {
        (*jac)(i, ps) = 1.0;
        continue;
      }
      for (int j = 0, c = 0; j < n; ++j) {
        // d z / d s0 = E (0, ..., -sin, cos, 0).
        (*jac)(i, j) = (j == ps) ? -e(r, m) * z0[m + 1] + e(r, m + 1) * z0[m] : e(r, c++);
      }
      ++r;
    }
  }
}

FlowResult ExactPropagator::FlowMap(int mode, const StateVector& x0, double t, const Params& params,
                                    const FlowRequest& request) {
  if (!KeepGoing()) return CancelledFlow(model_, x0, request);
  FlowResult out;
  StateMatrix* jac = request.state_jacobian ? &out.state_jacobian : nullptr;
  if (!request.param_jacobian) {
    StateAt(mode, x0, t, params, &out.x, jac);
  } else {
    // Van Loan: expm([[A, dA], [0, A]] t) has d expm(A t) / dk in its upper right block.
    const int n = model_.state_dim(), ps = model_.phase_index(), np = model_.num_params();
    const int m = linear_->augmented_dim();
    // The columns asked for, in order, and those the closed form gives (with the flow, from one
    // preparation of the segment).
    int ks[kMaxParams];
    StateVector closed_dx[kMaxParams];
    bool closed_ok[kMaxParams];
    int count = 0;
    for (int k = 0; k < np; ++k) {
      if (request.param >= 0 && k != request.param && k != request.also_param) continue;
      closed_ok[count] = false;
      ks[count++] = k;
    }
    if (closed_) {
      closed_->FlowAndParamDerivatives(mode, x0, t, params, &out.x, jac, {ks, ks + count},
                                       {closed_dx, closed_dx + count},
                                       {closed_ok, closed_ok + count});
    } else {
      StateAt(mode, x0, t, params, &out.x, jac);
    }
    out.param_jacobian.setZero(n, np);
    // The exponentials are computed only for columns the closed form does not give.
    Eigen::VectorXd z0, dz0;
    Eigen::MatrixXd a, da, e, block;
    ParamMatrix fp;
    for (int i = 0; i < count; ++i) {
      const int k = ks[i];
      if (closed_ok[i]) {
        out.param_jacobian.col(k) = closed_dx[i];
        continue;
      }
      if (e.size() == 0) {
        linear_->ToAugmented(x0, params, &z0);
        linear_->AugmentedMatrix(mode, params, &a);
        e = (a * t).exp();
        model_.ParamJacobian(mode, x0, params, &fp);  // its phase row is d omega / d params
      }
      linear_->AugmentedMatrixDerivative(mode, params, k, &da);
      linear_->AugmentedInitialDerivative(x0, params, k, &dz0);
      Eigen::VectorXd dz = e * dz0;
      if (!da.isZero(0.0)) {
        block.setZero(2 * m, 2 * m);
        block.topLeftCorner(m, m) = a;
        block.topRightCorner(m, m) = da;
        block.bottomRightCorner(m, m) = a;
        const Eigen::MatrixXd big = (block * t).exp();
        dz += big.topRightCorner(m, m) * z0;
      }
      for (int j = 0, r = 0; j < n; ++j) {
        out.param_jacobian(j, k) = (j == ps) ? fp(ps, k) * t : dz[r++];
      }
    }
  }
  if (!out.x.allFinite()) out.status = Internal("exact flow produced a non-finite state");
  return out;
}

AdvanceResult ExactPropagator::Advance(const AdvanceRequest& request, const Params& params) {
  if (!KeepGoing()) return CancelledAdvance(model_, request);
  AdvanceResult out;
  const int mode = request.mode;
  auto state_at = [&](double t, StateVector* x) {
    StateAt(mode, request.x0, t, params, x, nullptr);
  };
  const auto keep_going = [this] { return KeepGoing(); };
  internal::LocatedEvent ev;
  if (closed_) {
    PreparedSegment seg;
    closed_->PrepareSegment(mode, request.x0, params, &seg);
    ev = internal::LocateFirstEvent(
        model_, mode, request.t_max, options_.events,
        [&](double t, SegmentPoint* p) { closed_->EvaluateSegment(seg, t, params, true, p); },
        keep_going);
  } else {
    const int n_guards = static_cast<int>(model_.guards(mode).size());
    ev = internal::LocateFirstEvent(
        model_, mode, request.t_max, options_.events,
        [&](double t, SegmentPoint* p) {
          state_at(t, &p->x);
          for (int i = 0; i < n_guards; ++i) {
            p->guards[i] = model_.Guard(mode, i, p->x, params);
            p->bounds[i] = model_.GuardCurvatureBound(mode, i, p->x, params);
          }
        },
        keep_going);
  }
  if (ev.status.code() == StatusCode::kCancelled) return CancelledAdvance(model_, request);
  out.status = ev.status;
  out.end = ev.end;
  out.guard = ev.guard;
  out.tangential = ev.tangential;
  out.duration = ev.t;
  out.x = ev.x;
  out.evaluations = ev.evaluations;
  if (!out.status.ok()) return out;
  if (!out.x.allFinite()) {
    out.end = AdvanceEnd::kFailed;
    out.status = Internal("exact flow produced a non-finite state in mode " +
                          std::string(model_.mode_name(mode)));
    return out;
  }
  if (request.measures) {
    if (closed_) {
      out.measures =
          closed_->MeasureIncrements(mode, request.x0, out.duration, params, kAllMeasures);
    } else {
      const double panel =
          options_.quadrature_panel_fraction *
          std::min(model_.TimeScale(mode, params), 1.0 / model_.ForcingFrequency(params));
      StateVector x;
      const MeasureVector zero = MeasureVector::Zero(model_.measure_names().size());
      out.measures = internal::IntegrateGaussLegendre(
          [&](double tau) {
            state_at(tau, &x);
            return MeasureVector(model_.MeasureRates(mode, x, params));
          },
          out.duration, panel, zero);
    }
  }
  if (request.sample_dt > 0.0) {
    // 64-bit: a segment can hold more than 2^31 samples of a tiny sample_dt (refused below).
    for (int64_t k = 0; static_cast<double>(k) * request.sample_dt < out.duration; ++k) {
      if (out.samples.size() >= kMaxSamples) {
        out.end = AdvanceEnd::kFailed;
        out.status = OutOfRange("Advance: more than " + std::to_string(kMaxSamples) +
                                " trajectory samples (sample_dt too small for t_max)");
        return out;
      }
      if (!KeepGoing()) return CancelledAdvance(model_, request);
      TrajectorySample s;
      s.t = static_cast<double>(k) * request.sample_dt;
      state_at(s.t, &s.x);
      out.samples.push_back(s);
    }
    out.samples.push_back({out.duration, out.x});
  }
  return out;
}

}  // namespace drillbif
