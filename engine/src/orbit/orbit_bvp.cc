#include "orbit/orbit_bvp.h"

#include "orbit/column_sum.h"

namespace drillbif::internal {

namespace {

// out = a * b for an n x n column-major `a` (leading dimension lda) and an n-vector b.
template <int N>
void ColumnOf(int n, const double* a, int lda, const double* b, double* out) {
  ColumnSum<N, (N > 0 ? N : kMaxStateDim)> sum(n);
  for (int p = 0; p < n; ++p) sum.Add(a + p * lda, b[p]);
  sum.StoreTo(out);
}

}  // namespace

void ProductOnColumns(const StateMatrix& a, const Eigen::MatrixXd& b, std::span<const int> columns,
                      Eigen::MatrixXd* out) {
  const int n = static_cast<int>(a.rows()), m = static_cast<int>(b.cols());
  if (2 * n + m < EIGEN_GEMM_TO_COEFFBASED_THRESHOLD || !a.allFinite()) {
    out->noalias() = a * b;
    return;
  }
  out->resize(n, m);
  // Each entry from +0, in the depth's order, as the kernel; its final `destination + 1 * sum`
  // with a zeroed destination changes no bit (a sum started from +0 is never -0).
  const int lda = static_cast<int>(a.outerStride());
  for (const int c : columns) {
    if (n == 4) {
      ColumnOf<4>(n, a.data(), lda, &b(0, c), &(*out)(0, c));
    } else {
      ColumnOf<0>(n, a.data(), lda, &b(0, c), &(*out)(0, c));
    }
  }
}

OrbitBvp::OrbitBvp(const HybridModel& model, Propagator& propagator, Signature signature, int param,
                   int param2)
    : model_(model),
      propagator_(propagator),
      signature_(std::move(signature)),
      param_(param),
      param2_(param2),
      d_(model.state_dim() - 1),
      ps_(model.phase_index()) {}

Eigen::VectorXd OrbitBvp::Pack(const PeriodicOrbit& orbit) const {
  Eigen::VectorXd x(size());
  for (int i = 0; i < segments(); ++i) {
    for (int j = 0, r = 0; j <= d_; ++j) {
      if (j != ps_) x[i * (d_ + 1) + r++] = orbit.starts[i][j];
    }
    x[i * (d_ + 1) + d_] = orbit.durations[i];
  }
  return x;
}

void OrbitBvp::Unpack(const Eigen::Ref<const Eigen::VectorXd>& x, const Params& params,
                      PeriodicOrbit* orbit) const {
  const double omega = model_.ForcingFrequency(params);
  orbit->signature = signature_;
  orbit->params = params;
  orbit->starts.resize(segments());
  orbit->durations.resize(segments());
  double elapsed = 0.0;
  for (int i = 0; i < segments(); ++i) {
    StateVector& s = orbit->starts[i];
    s.resize(d_ + 1);
    // Segment i's unknowns: its start without the phase, then its duration.
    const double* xi = x.data() + i * (d_ + 1);
    for (int j = 0; j < ps_; ++j) s[j] = xi[j];
    s[ps_] = omega * elapsed;
    for (int j = ps_ + 1; j <= d_; ++j) s[j] = xi[j - 1];
    orbit->durations[i] = xi[d_];
    elapsed += orbit->durations[i];
  }
}

Status OrbitBvp::Evaluate(const Eigen::Ref<const Eigen::VectorXd>& x, const Params& params,
                          Eigen::VectorXd* g, Eigen::MatrixXd* gx, Eigen::VectorXd* gp,
                          Eigen::VectorXd* gp2, std::vector<FlowResult>* flows) const {
  if (gx == nullptr) return EvaluateImpl(x, params, g, nullptr, gp, gp2, flows);
  gx->resize(size(), size());
  Eigen::Ref<Eigen::MatrixXd> block(*gx);
  return EvaluateImpl(x, params, g, &block, gp, gp2, flows);
}

Status OrbitBvp::EvaluateInto(const Eigen::Ref<const Eigen::VectorXd>& x, const Params& params,
                              Eigen::VectorXd* g, Eigen::Ref<Eigen::MatrixXd> gx,
                              Eigen::VectorXd* gp, Eigen::VectorXd* gp2,
                              std::vector<FlowResult>* flows) const {
  return EvaluateImpl(x, params, g, &gx, gp, gp2, flows);
}

void OrbitBvp::NegatedRowsWithoutPhase(const Eigen::MatrixXd& src, int first,
                                       Eigen::Ref<Eigen::MatrixXd>* gx) const {
  // Column by column (both matrices are column-major: a column's rows are adjacent), the rows
  // before the phase's and after it.
  for (const int c : dend_columns_) {
    for (int r = 0; r < ps_; ++r) (*gx)(first + r, c) = -src(r, c);
    for (int r = ps_; r < d_; ++r) (*gx)(first + r, c) = -src(r + 1, c);
  }
}

Status OrbitBvp::EvaluateImpl(const Eigen::Ref<const Eigen::VectorXd>& x, const Params& params,
                              Eigen::VectorXd* g, Eigen::Ref<Eigen::MatrixXd>* gx,
                              Eigen::VectorXd* gp, Eigen::VectorXd* gp2,
                              std::vector<FlowResult>* flows) const {
  const int k = segments(), n = d_ + 1, m = size();
  const double omega = model_.ForcingFrequency(params);
  // The parameter derivatives asked for: (index, output), at most two.
  struct Wanted {
    int index;
    Eigen::VectorXd* out;
    double domega;  // d omega / d param: the phase row of the vector field's parameter Jacobian
  };
  Wanted wanted[2];
  int num_wanted = 0;
  if (gp != nullptr && param_ >= 0) wanted[num_wanted++] = {param_, gp, 0.0};
  if (gp2 != nullptr && param2_ >= 0) wanted[num_wanted++] = {param2_, gp2, 0.0};
  const bool want_p = num_wanted > 0;
  if (want_p) {
    ParamMatrix fp;
    model_.ParamJacobian(signature_.segments[0].mode, StateVector::Zero(n), params, &fp);
    for (int w = 0; w < num_wanted; ++w) wanted[w].domega = fp(ps_, wanted[w].index);
  }
  g->setZero(m);
  // gx is zeroed once, then each segment's rows are written in the columns where they are not
  // zero: its own start and duration and the earlier durations (dend_columns_).
  if (gx) gx->setZero();
  if (gp) gp->setZero(m);
  if (gp2) gp2->setZero(m);
  if (flows) flows->resize(k);

  // Derivatives of a segment's end state with respect to X (n x m) and the parameters (n each).
  // Kept between calls (members): sized once per signature, not at every Newton iteration.
  Eigen::MatrixXd& dend = dend_;
  Eigen::MatrixXd& jdend = jdend_;
  dend.resize(n, m);
  StateVector dend_p[2];
  // Segment i's start (Unpack's: the phase s_i = omega * elapsed), and the first one's.
  StateVector start(n), start0;
  double elapsed = 0.0;
  for (int i = 0; i < k; ++i) {
    const SegmentSpec& seg = signature_.segments[i];
    const int col = i * (d_ + 1);
    for (int j = 0, r = 0; j < n; ++j) start[j] = (j == ps_) ? omega * elapsed : x[col + r++];
    const double duration = x[col + d_];
    if (i == 0) start0 = start;
    FlowRequest req;
    // The parameter derivative needs the phase column too (s_i moves with omega).
    req.state_jacobian = gx != nullptr || want_p || flows != nullptr;
    req.param_jacobian = want_p;
    if (want_p) {
      req.param = wanted[0].index;
      if (num_wanted > 1) req.also_param = wanted[1].index;
    }
    const FlowResult fr = propagator_.FlowMap(seg.mode, start, duration, params, req);
    if (!fr.status.ok()) return fr.status;
    if (flows) (*flows)[i] = fr;
    const StateVector& xe = fr.x;
    if (gx) {
      StateVector f;
      model_.VectorField(seg.mode, xe, params, &f);
      // Zero where an earlier segment wrote (all of it at the first): its own columns and the
      // durations before it, the only columns that are not zero already.
      if (i == 0) {
        dend.setZero();
      } else {
        dend.middleCols(col - (d_ + 1), d_ + 1).setZero();
        for (int jseg = 0; jseg + 1 < i; ++jseg) dend.col(jseg * (d_ + 1) + d_).setZero();
      }
      for (int j = 0, r = 0; j < n; ++j) {
        if (j == ps_) continue;
        dend.col(col + r++) = fr.state_jacobian.col(j);
      }
      dend.col(col + d_) = f;
      // The start phase s_i = omega * sum_{j<i} tau_j.
      for (int jseg = 0; jseg < i; ++jseg) {
        dend.col(jseg * (d_ + 1) + d_) += omega * fr.state_jacobian.col(ps_);
      }
      // dend is zero outside these columns.
      dend_columns_.clear();
      for (int jseg = 0; jseg < i; ++jseg) dend_columns_.push_back(jseg * (d_ + 1) + d_);
      for (int j = 0; j <= d_; ++j) dend_columns_.push_back(col + j);
    }
    for (int w = 0; w < num_wanted; ++w) {
      dend_p[w] = fr.param_jacobian.col(wanted[w].index) +
                  fr.state_jacobian.col(ps_) * (wanted[w].domega * elapsed);
    }
    const int row = i * (d_ + 1);
    if (seg.guard >= 0) {
      // Event condition, then continuity through the jump into the next segment's start.
      (*g)[row] = model_.Guard(seg.mode, seg.guard, xe, params).h;
      const StateRow grad = model_.GuardGradient(seg.mode, seg.guard, xe, params);
      // Column by column, each the dot product Eigen's product of the row and dend would sum.
      if (gx) {
        for (const int c : dend_columns_) (*gx)(row, c) = grad.dot(dend.col(c).transpose());
      }
      if (want_p) {
        const ParamVector pgrad = model_.GuardParamGradient(seg.mode, seg.guard, xe, params);
        for (int w = 0; w < num_wanted; ++w) {
          (*wanted[w].out)[row] = grad.dot(dend_p[w].transpose()) + pgrad[wanted[w].index];
        }
      }
      // A tangent end touches the surface and goes on in the same mode: no jump.
      Transition tr;
      if (seg.tangent) {
        tr.next_mode = seg.mode;
        tr.x = xe;
        tr.jacobian = StateMatrix::Identity(n, n);
        tr.param_jacobian = ParamMatrix::Zero(n, model_.num_params());
      } else {
        tr = model_.Jump(seg.mode, seg.guard, xe, params);
      }
      // Only dend's nonzero columns (one product per segment over all m columns dominated the
      // evaluation's cost).
      if (gx) ProductOnColumns(tr.jacobian, dend, dend_columns_, &jdend);
      StateVector jdend_p[2];
      for (int w = 0; w < num_wanted; ++w) {
        jdend_p[w] = tr.jacobian * dend_p[w] + tr.param_jacobian.col(wanted[w].index);
      }
      const int next = (i + 1) * (d_ + 1);
      if (gx) NegatedRowsWithoutPhase(jdend, row + 1, gx);
      for (int j = 0, r = 0; j < n; ++j) {
        if (j == ps_) continue;
        (*g)[row + 1 + r] = x[next + r] - tr.x[j];
        if (gx) (*gx)(row + 1 + r, next + r) += 1.0;
        for (int w = 0; w < num_wanted; ++w) (*wanted[w].out)[row + 1 + r] = -jdend_p[w][j];
        ++r;
      }
    } else {
      // Periodicity back to the first segment's start, then the phase condition.
      if (gx) NegatedRowsWithoutPhase(dend, row, gx);
      for (int j = 0, r = 0; j < n; ++j) {
        if (j == ps_) continue;
        (*g)[row + r] = x[r] - xe[j];
        if (gx) (*gx)(row + r, r) += 1.0;
        for (int w = 0; w < num_wanted; ++w) (*wanted[w].out)[row + r] = -dend_p[w][j];
        ++r;
      }
      // A first segment in a mode confined to a surface: the periodicity of the component along
      // the constraint's gradient is implied by the others on that surface (and is the identity
      // 0 = 0 when no jump projects onto it, e.g. an orbit that never leaves contact), so that
      // row states the constraint at the start instead.
      double c = 0.0;
      StateRow cgrad;
      ParamVector cpgrad;
      if (model_.ModeConstraint(signature_.segments[0].mode, start0, params, &c, &cgrad, &cpgrad)) {
        int j_row = -1;
        for (int j = 0, r = 0; j < n && j_row < 0; ++j) {
          if (j == ps_) continue;
          if (cgrad[j] != 0.0) j_row = r;
          ++r;
        }
        if (j_row >= 0) {
          (*g)[row + j_row] = c;
          if (gx) {
            gx->row(row + j_row).setZero();
            for (int j = 0, r = 0; j < n; ++j) {
              if (j != ps_) (*gx)(row + j_row, r++) = cgrad[j];
            }
          }
          for (int w = 0; w < num_wanted; ++w) {
            (*wanted[w].out)[row + j_row] = cpgrad[wanted[w].index];
          }
        }
      }
      double total = 0.0;
      for (int jseg = 0; jseg < k; ++jseg) total += x[jseg * (d_ + 1) + d_];
      (*g)[row + d_] = total - kTwoPi * signature_.periods / omega;
      if (gx) {
        gx->row(row + d_).setZero();
        for (int jseg = 0; jseg < k; ++jseg) (*gx)(row + d_, jseg * (d_ + 1) + d_) = 1.0;
      }
      for (int w = 0; w < num_wanted; ++w) {
        (*wanted[w].out)[row + d_] =
            kTwoPi * signature_.periods / (omega * omega) * wanted[w].domega;
      }
    }
    elapsed += duration;
  }
  return Status::Ok();
}

}  // namespace drillbif::internal
