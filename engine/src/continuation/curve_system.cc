#include "continuation/curve_system.h"

#include <utility>

#include "continuation/arclength.h"
#include "continuation/tangent_grazing.h"
#include "orbit/monodromy.h"

namespace drillbif::internal {

using Vec = CurveSystem::Vec;
using Mat = CurveSystem::Mat;

namespace {

// Whether every entry of `a` is finite, as a.allFinite(), in one vectorized sum: 0 x is +-0 for
// a finite x and NaN for an infinite or NaN one, so the sum is NaN exactly when some entry is
// not finite. (allFinite tests entry by entry with a branch each: ~2% of the reference box's
// trace on these dense (m + 1) x n Jacobians.)
bool AllFinite(const Eigen::Ref<const Mat>& a) { return !std::isnan((a.array() * 0.0).sum()); }

}  // namespace

CurveSystem::CurveSystem(const HybridModel& model, Propagator& propagator,
                         const CurveOptions& options, CurveKind kind, int index1, int index2,
                         const PeriodicOrbit& start)
    : model_(model),
      propagator_(propagator),
      options_(options),
      kind_(kind),
      index1_(index1),
      index2_(index2),
      base_(start.params),
      bvp1_(model, propagator, start.signature, index1, index2) {
  if (std::isfinite(options.width1())) w1_ = options.width1();
  if (std::isfinite(options.width2())) w2_ = options.width2();
  if (kind_ == CurveKind::kGrazing) {
    corner_ = CornerSegment(model_, start);
    const std::vector<int> tangents = TangentSegments(start.signature);
    if (!tangents.empty()) tangent_ = tangents.front();
    return;
  }
  SetBorders(OrbitStability(model_, propagator_, Unpack(Pack(start))).monodromy);
}

Vec CurveSystem::Pack(const PeriodicOrbit& orbit) const {
  Vec y(n());
  y.head(m()) = bvp1_.Pack(orbit);
  y[m()] = orbit.params[index1_];
  y[m() + 1] = orbit.params[index2_];
  return y;
}

Params CurveSystem::ParamsAt(const Vec& y) const {
  Params p = base_;
  p[index1_] = y[m()];
  p[index2_] = y[m() + 1];
  return p;
}

PeriodicOrbit CurveSystem::Unpack(const Vec& y) const {
  PeriodicOrbit o;
  bvp1_.Unpack(y.head(m()), ParamsAt(y), &o);
  return o;
}

// Bordering vectors (bordered_sigma.h) from the shifted monodromy. Fixed ones serve only near
// where they were taken: far along a curve the bordered matrix can turn singular (sigma then
// blows up and the corrector fails in ever shorter steps: the a-branch fold curve from
// a = 0.2718 stalled so in the reference box), so they are renewed at every accepted point.
// sigma's zero set, the curve, does not depend on them.
void CurveSystem::SetBorders(const Mat& monodromy) const {
  if (kind_ == CurveKind::kGrazing) return;
  sigma_ = BorderedSigma(ShiftedMonodromy(kind_, monodromy));
}

double CurveSystem::Condition(const Vec& y) const {
  // Unpacked into the kept orbit: Condition is called once per difference of the row.
  bvp1_.Unpack(y.head(m()), ParamsAt(y), &moved_orbit_);
  return ConditionAt(moved_orbit_);
}

double CurveSystem::ConditionAt(const PeriodicOrbit& o, std::vector<StateMatrix>* factors,
                                std::vector<FlowResult>* flows) const {
  if (kind_ == CurveKind::kGrazing) {
    return corner_ >= 0 ? o.durations[corner_] : TangentEndRate(model_, propagator_, o);
  }
  std::vector<StateMatrix>& f = factors != nullptr ? *factors : moved_factors_;
  MonodromyFactorsInto(model_, propagator_, o, &f, flows);
  return Sigma(ReducedMonodromy(model_, f));
}

double CurveSystem::Sigma(const Eigen::Ref<const Mat>& monodromy) const {
  return sigma_(ShiftedMonodromy(kind_, monodromy));
}

bool CurveSystem::EvaluateInto(const Vec& y, Vec* f, Eigen::Ref<Mat>* jac) const {
  const Params prm = ParamsAt(y);
  if (!model_.ValidateParams(prm).ok()) return false;
  // Members, kept between calls so that Newton's iterations do not allocate them anew.
  Vec& g = g_;
  Vec& gp1 = gp1_;
  Vec& gp2 = gp2_;
  std::vector<FlowResult>& flows = flows_;
  std::vector<StateMatrix>& factors = factors_;
  // The condition's monodromy factors are made from the same segments' flows as G (same starts,
  // durations and parameters): taken from G's evaluation where the propagator gives them the
  // same bits whatever else it computed.
  const bool shared_flows = kind_ != CurveKind::kGrazing && propagator_.FlowIndependentOfRequest();
  // G's Jacobian goes straight into jac's top-left block (every entry written there).
  const Status evaluated =
      jac ? bvp1_.EvaluateInto(y.head(m()), prm, &g, jac->topLeftCorner(m(), m()), &gp1, &gp2,
                               shared_flows ? &flows : nullptr)
          : bvp1_.Evaluate(y.head(m()), prm, &g, nullptr, nullptr, nullptr,
                           shared_flows ? &flows : nullptr);
  if (!evaluated.ok()) return false;
  f->resize(m() + 1);
  f->head(m()) = g;
  bvp1_.Unpack(y.head(m()), prm, &orbit_);
  const PeriodicOrbit& o = orbit_;
  if (shared_flows) {
    FactorsFromFlows(model_, o, flows, &factors);
    (*f)[m()] = Sigma(ReducedMonodromy(model_, factors));
  } else {
    (*f)[m()] = ConditionAt(o, &factors, jac ? &flows : nullptr);
  }
  if (!jac) return f->allFinite();
  // Every entry is written below (G's rows by the evaluation and from gp1, gp2, the condition's row
  // zeroed and filled): no zeroing pass over the whole matrix.
  jac->row(m()).setZero();
  jac->col(m()).head(m()) = gp1;
  jac->col(m() + 1).head(m()) = gp2;
  // Forward differences of the condition (one evaluation per unknown, each a monodromy):
  // truncation h |sigma''| / 2 and rounding eps |sigma| / h, both ~1e-8 with
  // h = 1.5e-8 (1 + |y_j|) for these O(1) quantities. The Jacobian only steers Newton and the
  // tangent; the residual, and so every point on the curve, is exact.
  const double sigma0 = (*f)[m()];
  if (kind_ == CurveKind::kGrazing && corner_ >= 0) {
    // The corner's duration is one of the unknowns: its row is a unit vector.
    (*jac)(m(), bvp1_.DurationIndex(corner_)) = 1.0;
  } else if (kind_ == CurveKind::kGrazing) {
    // The condition, h' at the end of the first tangent segment, is a function of that segment's
    // flow alone: an unknown that does not move it (MovesSegmentFlow) gives the condition the
    // same bits, sigma0, and its entry is (sigma0 - sigma0) / h without the evaluation.
    const int block = Block();
    moved_y_ = y;  // moved one entry at a time and restored: the same bits as a fresh copy
    for (int j = 0; j < n(); ++j) {
      const double h = ForwardStep(y[j]);
      if (!MovesSegmentFlow(j, tangent_, block, m())) {
        (*jac)(m(), j) = (sigma0 - sigma0) / h;
        continue;
      }
      moved_y_[j] = y[j] + h;
      (*jac)(m(), j) = (Condition(moved_y_) - sigma0) / h;
      moved_y_[j] = y[j];
    }
  } else {
    SigmaRow(y, o, factors, flows, sigma0, jac);
  }
  return f->allFinite() && AllFinite(*jac);
}

// sigma's row: over the orbit's unknowns from sigma's gradient in the monodromy
// (MonodromyGradientRow: only the monodromy factors an unknown moves are recomputed, by forward
// differences, and contracted with the gradient, with no bordered solve per unknown), over the
// parameters by forward differences of whole evaluations (every factor moves with them). `o` is
// Unpack(y), `base` its factors, `flows` the segments' flows they were made from.
void CurveSystem::SigmaRow(const Vec& y, const PeriodicOrbit& o,
                           const std::vector<StateMatrix>& base,
                           const std::vector<FlowResult>& flows, double sigma0,
                           Eigen::Ref<Mat>* jac) const {
  SigmaWithGradient(kind_, sigma_, ReducedMonodromy(model_, base), &gradient_);
  MonodromyGradientRow(model_, propagator_, o, base, flows, gradient_, jac->row(m()).head(m()),
                       &row_scratch_);
  moved_y_ = y;  // moved one entry at a time and restored: the same bits as a fresh copy
  for (int j = m(); j < n(); ++j) {
    const double h = ForwardStep(y[j]);
    moved_y_[j] = y[j] + h;
    (*jac)(m(), j) = (Condition(moved_y_) - sigma0) / h;
    moved_y_[j] = y[j];
  }
}

// Newton on (F = 0, dir . (y - y_pred) = 0) from y_pred (PseudoArclengthCorrector), with the
// contraction-based convergence test. `tangent`, when given, receives the unit tangent at the
// result oriented along dir, from the last iteration's factorization, so that it costs no
// further evaluation.
// The condition's residual must be small too, not only the step (settle_condition): where the
// condition is steep in the unknowns (next to a segment vanishing between two of one mode its
// saltations grow like 1 / tau, and the multiplier's derivatives like 1 / tau^2) a point within
// the step tolerance of the curve can have its multiplier 1e-6 off +-1 (in the reference box:
// 327 of 58902 fold / PD vertices above 1e-8, up to 4.7e-5). Once the step has converged, the
// iterations go on while the residual |condition| is above 1e-11 and decreasing at least
// twofold (CorrectorOptions::condition_tolerance). With it 32 vertices of the box stay above
// 1e-8 (6 above 1e-6, their residual at its floor). Not for the end's bisection
// (settle_condition false): its points only bracket the end, which is solved on its own;
// moved by the extra iterations, one end's last admissible point (0.0953, 0.1776) no longer
// led to its tangent-form solution (bracket 2.3e-6).
bool CurveSystem::Correct(const Vec& y_pred, const Vec& dir, Vec* y, int* iterations, Vec* tangent,
                          bool settle_condition) const {
  PseudoArclengthCorrector corrector = NewCorrector();
  return corrector.Correct(CorrectSettings(settle_condition), y_pred, dir, y, iterations, tangent);
}

CorrectorOptions CurveSystem::CorrectSettings(bool settle_condition) const {
  CorrectorOptions correct;
  correct.max_iterations = options_.steps.max_iterations;
  correct.tolerance = options_.steps.tolerance;
  correct.contraction_test = true;
  if (settle_condition) correct.condition_tolerance = 1e-11;
  return correct;
}

PseudoArclengthCorrector CurveSystem::NewCorrector() const {
  return PseudoArclengthCorrector(
      *this, options_.steps.condensed_solve ? CondensedMode::kAuto : CondensedMode::kDense);
}

bool CurveSystem::CorrectKeeping(PseudoArclengthCorrector* corrector, const Vec& y_pred,
                                 const Vec& dir, Vec* y) const {
  int iterations = 0;
  return corrector->Correct(CorrectSettings(false), y_pred, dir, y, &iterations);
}

bool CurveSystem::ChordCorrect(PseudoArclengthCorrector* corrector, const Vec& y_pred,
                               const Vec& dir, Vec* y) const {
  int iterations = 0;
  return corrector->CorrectChord(CorrectSettings(false), y_pred, dir, y, &iterations);
}

double CurveSystem::ChordSagitta(const Vec& y, const Vec& t, const Vec& y1, const Vec& t1,
                                 double h) const {
  const Eigen::Vector2d chord((y1[m()] - y[m()]) / w1_, (y1[m() + 1] - y[m() + 1]) / w2_);
  const double length = chord.norm();
  if (length == 0.0) return 0.0;
  // The cubic's offset across the chord: h (a0 h10(s) + a1 h11(s)), with the Hermite basis
  // h10 = s^3 - 2 s^2 + s, h11 = s^3 - s^2 and a0, a1 the derivatives' components across it.
  const Eigen::Vector2d across(-chord[1] / length, chord[0] / length);
  const double a0 = across.dot(ParamDirection(t)), a1 = across.dot(ParamDirection(t1));
  double sagitta = 0.0;
  for (const double s : {0.25, 0.5, 0.75}) {
    const double h10 = s * s * s - 2.0 * s * s + s, h11 = s * s * s - s * s;
    sagitta = std::max(sagitta, std::abs(h * (a0 * h10 + a1 * h11)));
  }
  return sagitta;
}

bool CurveSystem::Tangent(const Vec& y, const Vec& prev, Vec* t) const {
  Vec f;
  Mat jac;
  return Evaluate(y, &f, &jac) && UnitTangent(jac, prev, t);
}

bool CurveSystem::Admissible(const PeriodicOrbit& o, std::string* why,
                             Admissibility* violation) const {
  Admissibility a;
  if (AtCorner(o)) {
    PeriodicOrbit p = o;
    p.durations[corner_] = kCornerDuration;
    a = CheckAdmissible(model_, propagator_, p);
  } else {
    a = CheckAdmissible(model_, propagator_, o);
  }
  *why = a.message;
  if (violation && !a.admissible) *violation = a;
  return a.admissible;
}

CurvePoint CurveSystem::MakePoint(const Vec& y) const {
  CurvePoint p = PointFromOrbit(Unpack(y));
  p.value1 = y[m()];
  p.value2 = y[m() + 1];
  return p;
}

CurvePoint CurveSystem::PointFromOrbit(PeriodicOrbit orbit, const Stability* stability) const {
  if (AtCorner(orbit)) orbit.durations[corner_] = kCornerDuration;
  CurvePoint p;
  p.value1 = orbit.params[index1_];
  p.value2 = orbit.params[index2_];
  p.orbit = std::move(orbit);
  // ROP only (bit 0): Pc, 20 times its cost in quadrature, is asked for by no consumer of curves.
  p.measures = OrbitMeasures(model_, propagator_, p.orbit, 1u);
  p.stability = stability != nullptr ? *stability : OrbitStability(model_, propagator_, p.orbit);
  return p;
}

}  // namespace drillbif::internal
