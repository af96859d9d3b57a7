// Two-parameter curve continuation (see continuation/curve.h).
#include "drillbif/continuation/curve.h"

#include <Eigen/Dense>
#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <complex>
#include <cstdio>
#include <functional>
#include <limits>
#include <memory>
#include <optional>

#include "common/phase_progress.h"
#include "continuation/arclength.h"
#include "continuation/bordered_sigma.h"
#include "continuation/corrector.h"
#include "continuation/grazing_end.h"
#include "continuation/signature_switch.h"
#include "continuation/tangent_grazing.h"
#include "orbit/condensed.h"
#include "orbit/monodromy.h"
#include "orbit/orbit_bvp.h"

namespace drillbif {

const char* CurveKindName(CurveKind kind) {
  switch (kind) {
    case CurveKind::kFold:
      return "FOLD";
    case CurveKind::kPeriodDoubling:
      return "PERIOD_DOUBLING";
    case CurveKind::kGrazing:
      return "GRAZING";
    case CurveKind::kNeimarkSacker:
      return "NEIMARK_SACKER";
  }
  return "?";
}

const char* Codim2KindName(Codim2Kind kind) {
  switch (kind) {
    case Codim2Kind::kFoldGrazing:
      return "FOLD_GRAZING";
    case Codim2Kind::kFlipGrazing:
      return "FLIP_GRAZING";
    case Codim2Kind::kFoldFlip:
      return "FOLD_FLIP";
    case Codim2Kind::kDoubleGrazing:
      return "DOUBLE_GRAZING";
    case Codim2Kind::kNsGrazing:
      return "NS_GRAZING";
    case Codim2Kind::kResonance11:
      return "RESONANCE_1_1";
    case Codim2Kind::kResonance12:
      return "RESONANCE_1_2";
    case Codim2Kind::kResonance13:
      return "RESONANCE_1_3";
    case Codim2Kind::kResonance14:
      return "RESONANCE_1_4";
    case Codim2Kind::kCusp:
      return "CUSP";
  }
  return "?";
}

Status CurveOptions::Validate() const {
  if (param1.empty() || param2.empty() || param1 == param2) {
    return InvalidArgument("param1 and param2 must name two different parameters");
  }
  if (std::isnan(min1) || std::isnan(max1) || !(max1 > min1) || std::isnan(min2) ||
      std::isnan(max2) || !(max2 > min2)) {
    return InvalidArgument("the box is empty: need min1 < max1 and min2 < max2");
  }
  return steps.Validate();
}

namespace {

using Vec = Eigen::VectorXd;
using Mat = Eigen::MatrixXd;

// How a curve's message names an unverified end (CurveResult::unverified_ends) `end`, whose
// prediction beyond was inadmissible for `why`: "next to (param1, param2) = (.., ..), where
// ...: no FOLD_GRAZING point claimed".
std::string UnverifiedEndText(const CurveOptions& options, const Codim2Point& end,
                              const std::string& why) {
  return "next to (" + options.param1 + ", " + options.param2 + ") = (" +
         std::to_string(end.point.value1) + ", " + std::to_string(end.point.value2) +
         "), where only a prediction beyond, not a corrected orbit, is inadmissible (" + why +
         "): no " + Codim2KindName(end.kind) + " point claimed";
}

// Where a traced direction met the Poincare section (CurveTracer::Trace).
struct SectionCrossing {
  bool happened = false;
  PeriodicOrbit orbit;        // the last point's orbit, its first or last segment ~0 long
  Admissibility violation;    // that segment's vanishing, just beyond
  Eigen::Vector2d direction;  // the curve's parameter direction there (box-scaled, unit)
  // The curve's end as it is reported when the rotated signature cannot be taken up there; as an
  // unverified end (CurveResult::unverified_ends) where only a prediction brackets the crossing.
  Codim2Point end;
  bool unverified = false;
};

class CurveTracer : public internal::CorrectorSystem {
 public:
  CurveTracer(const HybridModel& model, Propagator& propagator, const CurveOptions& options,
              CurveKind kind, int index1, int index2, const PeriodicOrbit& start)
      : model_(model),
        propagator_(propagator),
        options_(options),
        kind_(kind),
        index1_(index1),
        index2_(index2),
        base_(start.params),
        bvp1_(model, propagator, start.signature, index1, index2) {
    start_.resize(n());
    start_.head(m()) = bvp1_.Pack(start);
    start_[m()] = start.params[index1];
    start_[m() + 1] = start.params[index2];
    if (std::isfinite(options.width1())) w1_ = options.width1();
    if (std::isfinite(options.width2())) w2_ = options.width2();
    if (kind_ == CurveKind::kGrazing) {
      corner_ = internal::CornerSegment(model_, start);
      return;
    }
    SetBorders(OrbitStability(model_, propagator_, Unpack(start_)).monodromy);
  }

  // Bordering vectors (bordered_sigma.h) from the shifted monodromy. Fixed ones serve only near
  // where they were taken: far along a curve the bordered matrix can turn singular (sigma then
  // blows up and the corrector fails in ever shorter steps: the a-branch fold curve from
  // a = 0.2718 stalled so in the reference box), so they are renewed at every accepted point.
  // sigma's zero set, the curve, does not depend on them.
  void SetBorders(const Mat& monodromy) const {
    if (kind_ == CurveKind::kGrazing) return;
    sigma_ = internal::BorderedSigma(internal::ShiftedMonodromy(kind_, monodromy));
  }

  // Puts the start exactly on the curve: Newton on the extended system with lambda2 fixed (the
  // located point satisfies the defining condition only to the location's accuracy, and a grazing
  // point re-expressed with a tangent end is slightly off the touch). Where the curve's tangent
  // has next to no parameter part (a fold curve at a fold-grazing, its parameters moving as the
  // square of the vanishing duration), holding either parameter leaves Newton's matrix singular
  // (condition ~1e14 measured, steps ~1e-8 that never settle): corrected then across the curve,
  // orthogonal to its tangent there.
  bool CorrectStart() {
    Vec fixed = Vec::Zero(n()), y;
    fixed[m() + 1] = 1.0;
    int iterations = 0;
    if (!Correct(start_, fixed, &y, &iterations)) {
      Vec f;
      Mat jac;
      if (!Evaluate(start_, &f, &jac)) return false;
      // The null vector of the (n - 1) x n Jacobian: the last column of Q in jac^T = Q R.
      const Mat q = Eigen::HouseholderQR<Mat>(jac.transpose()).householderQ();
      if (!Correct(start_, q.col(n() - 1), &y, &iterations)) return false;
    }
    start_ = y;
    return true;
  }

  int m() const { return bvp1_.size(); }
  int Segments() const override { return bvp1_.segments(); }
  int Block() const override { return m() / bvp1_.segments(); }
  int n() const { return m() + 2; }
  const Vec& start() const { return start_; }

  // Whether the propagator's throttle has seen a stop: nothing computed since is kept, and
  // Trace returns kCancelledEnd.
  bool Stopped() const override { return propagator_.stopped(); }
  static constexpr const char* kCancelledEnd = "cancelled";

  Params ParamsAt(const Vec& y) const {
    Params p = base_;
    p[index1_] = y[m()];
    p[index2_] = y[m() + 1];
    return p;
  }

  PeriodicOrbit Unpack(const Vec& y) const {
    PeriodicOrbit o;
    bvp1_.Unpack(y.head(m()), ParamsAt(y), &o);
    return o;
  }

  // The defining condition: sigma(M -+ I) for folds and period doublings; for grazing, h' at the
  // tangent end (the guard's rate where it touches zero).
  double Condition(const Vec& y) const { return ConditionAt(Unpack(y)); }
  // The same for an unpacked orbit; for fold / PD / NS curves its monodromy factors, and the
  // segments' flows they were made from, are kept in *factors / *flows when asked (the
  // condition's row of the Jacobian reuses them).
  double ConditionAt(const PeriodicOrbit& o, std::vector<StateMatrix>* factors = nullptr,
                     std::vector<FlowResult>* flows = nullptr) const {
    if (kind_ == CurveKind::kGrazing) {
      return corner_ >= 0 ? o.durations[corner_] : internal::TangentEndRate(model_, propagator_, o);
    }
    std::vector<StateMatrix> f = internal::MonodromyFactors(model_, propagator_, o, flows);
    const double sigma = Sigma(internal::ReducedMonodromy(model_, f));
    if (factors) *factors = std::move(f);
    return sigma;
  }

  // sigma of the shifted monodromy (without its phase).
  double Sigma(const Eigen::Ref<const Mat>& monodromy) const {
    return sigma_(internal::ShiftedMonodromy(kind_, monodromy));
  }

  // F(y) = (G, condition) and its Jacobian (n - 1 rows, n columns).
  bool Evaluate(const Vec& y, Vec* f, Mat* jac) const override {
    const Params prm = ParamsAt(y);
    if (!model_.ValidateParams(prm).ok()) return false;
    Vec g, gp1, gp2;
    Mat gx;
    if (!bvp1_
             .Evaluate(y.head(m()), prm, &g, jac ? &gx : nullptr, jac ? &gp1 : nullptr,
                       jac ? &gp2 : nullptr)
             .ok()) {
      return false;
    }
    f->resize(m() + 1);
    f->head(m()) = g;
    const PeriodicOrbit o = Unpack(y);
    std::vector<StateMatrix> factors;
    std::vector<FlowResult> flows;
    (*f)[m()] = ConditionAt(o, &factors, jac ? &flows : nullptr);
    if (!jac) return f->allFinite();
    jac->setZero(m() + 1, n());
    jac->topLeftCorner(m(), m()) = gx;
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
      for (int j = 0; j < n(); ++j) {
        const double h = internal::ForwardStep(y[j]);
        Vec yp = y;
        yp[j] += h;
        (*jac)(m(), j) = (Condition(yp) - sigma0) / h;
      }
    } else {
      SigmaRow(y, o, factors, flows, sigma0, jac);
    }
    return f->allFinite() && jac->allFinite();
  }

  // The same forward differences of sigma: over the orbit's unknowns by internal::MonodromyRow
  // (only the monodromy factors an unknown moves are recomputed), over the parameters by whole
  // evaluations (every factor moves with them). `o` is Unpack(y), `base` its factors, `flows` the
  // segments' flows they were made from.
  void SigmaRow(const Vec& y, const PeriodicOrbit& o, const std::vector<StateMatrix>& base,
                const std::vector<FlowResult>& flows, double sigma0, Mat* jac) const {
    internal::MonodromyRow(
        model_, propagator_, o, base, flows, [this](const Eigen::MatrixXd& m) { return Sigma(m); },
        internal::RowDifferences::kForward, sigma0, jac->row(m()).head(m()));
    for (int j = m(); j < n(); ++j) {
      const double h = internal::ForwardStep(y[j]);
      Vec yp = y;
      yp[j] += h;
      (*jac)(m(), j) = (Condition(yp) - sigma0) / h;
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
  bool Correct(const Vec& y_pred, const Vec& dir, Vec* y, int* iterations, Vec* tangent = nullptr,
               bool settle_condition = true) const {
    internal::CorrectorOptions correct;
    correct.max_iterations = options_.steps.max_iterations;
    correct.tolerance = options_.steps.tolerance;
    correct.contraction_test = true;
    if (settle_condition) correct.condition_tolerance = 1e-11;
    internal::PseudoArclengthCorrector corrector(*this, options_.steps.condensed_solve
                                                            ? internal::CondensedMode::kAuto
                                                            : internal::CondensedMode::kDense);
    return corrector.Correct(correct, y_pred, dir, y, iterations, tangent);
  }

  bool Tangent(const Vec& y, const Vec& prev, Vec* t) const {
    Vec f;
    Mat jac;
    return Evaluate(y, &f, &jac) && internal::UnitTangent(jac, prev, t);
  }

  // Whether the orbit holds the corner's segment at zero length to rounding (Newton leaves it at
  // ~1e-20 either side of zero); it then stands for the smallest positive duration: its two
  // events at one point, an orbit CheckAdmissible takes as it is.
  bool AtCorner(const PeriodicOrbit& o) const {
    return corner_ >= 0 && std::abs(o.durations[corner_]) <= 1e-9;
  }
  static constexpr double kCornerDuration = std::numeric_limits<double>::min();

  // Admissibility; on a corner's curve the corner's own duration, zero to rounding, counts as
  // kCornerDuration (as PointFromOrbit reports it), and the rest is checked as usual.
  bool Admissible(const PeriodicOrbit& o, std::string* why,
                  Admissibility* violation = nullptr) const {
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

  CurvePoint MakePoint(const Vec& y) const {
    CurvePoint p = PointFromOrbit(Unpack(y));
    p.value1 = y[m()];
    p.value2 = y[m() + 1];
    return p;
  }

  // `stability` given: that one (an extrapolated end's), else the orbit's own.
  CurvePoint PointFromOrbit(PeriodicOrbit orbit, const Stability* stability = nullptr) const {
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

  // A codimension-2 test function of the monodromy and the point it marks where it changes sign.
  struct Codim2Test {
    std::function<double(const Mat&)> f;
    Codim2Kind kind;
  };
  double TestValue(const Codim2Test& test, const Vec& y) const {
    return test.f(OrbitStability(model_, propagator_, Unpack(y)).monodromy);
  }

  // det(M - I) (shift -1) or det(M + I) (shift +1).
  static double ShiftedDet(const Mat& mono, double shift) {
    return (mono + shift * Mat::Identity(mono.rows(), mono.cols())).determinant();
  }

  // On a Neimark-Sacker curve, kappa = Re(mu1 + mu2) / 2 of the critical pair (the two multipliers
  // whose product is nearest 1; on the curve a complex pair on the unit circle, kappa = cos theta):
  // kappa = 1, -1, -1/2, 0 at the strong resonances 1:1, 1:2, 1:3, 1:4 (Kuznetsov 2004,
  // sec. 9.5). Beyond a 1:1 or 1:2 point the pair is real with product 1 and kappa passes +-1.
  static double Kappa(const Mat& mono) {
    const Eigen::VectorXcd mu = Eigen::EigenSolver<Mat>(mono, false).eigenvalues();
    double best = std::numeric_limits<double>::infinity(), kappa = 0.0;
    for (int i = 0; i < mu.size(); ++i) {
      for (int j = i + 1; j < mu.size(); ++j) {
        const double gap = std::abs(mu[i] * mu[j] - 1.0);
        if (gap < best) best = gap, kappa = 0.5 * (mu[i] + mu[j]).real();
      }
    }
    return kappa;
  }

  // The codimension-2 test functions this curve carries.
  std::vector<Codim2Test> Codim2Tests() const {
    auto det = [](double shift) { return [shift](const Mat& m) { return ShiftedDet(m, shift); }; };
    auto kappa = [](double at) { return [at](const Mat& m) { return Kappa(m) - at; }; };
    switch (kind_) {
      case CurveKind::kGrazing:
        return {{det(-1.0), Codim2Kind::kFoldGrazing}, {det(+1.0), Codim2Kind::kFlipGrazing}};
      case CurveKind::kFold:
        return {{det(+1.0), Codim2Kind::kFoldFlip}};
      case CurveKind::kPeriodDoubling:
        return {{det(-1.0), Codim2Kind::kFoldFlip}};
      case CurveKind::kNeimarkSacker:
        return {{kappa(1.0), Codim2Kind::kResonance11},
                {kappa(-1.0), Codim2Kind::kResonance12},
                {kappa(-0.5), Codim2Kind::kResonance13},
                {kappa(0.0), Codim2Kind::kResonance14}};
    }
    return {};
  }

  // The root on the step from y along t of length h of a function of the curve point (values f0,
  // f1 at the step's ends): Illinois on the arclength, each trial point corrected onto the curve,
  // until |value| <= tol or the bracket is below 1e-14 of the step. `value` returns false where
  // it cannot be evaluated (the root is then not located).
  bool LocateOnStep(const Vec& y, const Vec& t, double h, double f0, double f1, double tol,
                    const std::function<bool(const Vec&, double*)>& value, Vec* root) const {
    double a = 0.0, fa = f0, b = h, fb = f1;
    int side = 0;
    for (int it = 0; it < 100; ++it) {
      if (Stopped()) return false;
      double sigma = (fb - fa) != 0.0 ? (a * fb - b * fa) / (fb - fa) : 0.5 * (a + b);
      if (!(sigma > a && sigma < b)) sigma = 0.5 * (a + b);
      int iterations = 0;
      double f = 0.0;
      if (!Correct(y + sigma * t, t, root, &iterations) || !value(*root, &f)) return false;
      if (std::abs(f) <= tol || b - a <= 1e-14 * std::max(1.0, h)) return true;
      if ((f > 0.0) == (fa > 0.0)) {
        a = sigma, fa = f;
        if (side == -1) fb *= 0.5;
        side = -1;
      } else {
        b = sigma, fb = f;
        if (side == +1) fa *= 0.5;
        side = +1;
      }
    }
    return false;
  }

  // The root of a codimension-2 test function on the step (values d0, d1 at its ends), to
  // |value| <= 1e-10.
  bool LocateCodim2(const Vec& y, const Vec& t, double h, const Codim2Test& test, double d0,
                    double d1, Vec* root) const {
    return LocateOnStep(
        y, t, h, d0, d1, 1e-10,
        [&](const Vec& p, double* f) {
          *f = TestValue(test, p);
          return true;
        },
        root);
  }

  // Codimension-2 points on the step from y (tangent t) to y1 (monodromy mono1): sign changes
  // of the test functions from their values at y (*dets, updated to those at y1), located and
  // appended.
  void RootsOnStep(const Vec& y, const Vec& t, const Vec& y1, const Mat& mono1,
                   const std::vector<Codim2Test>& tests, std::vector<double>* dets,
                   std::vector<Codim2Point>* codim2) const {
    for (size_t k = 0; k < tests.size(); ++k) {
      const double d1 = tests[k].f(mono1);
      Vec root;
      if (((*dets)[k] > 0.0) != (d1 > 0.0) &&
          LocateCodim2(y, t, t.dot(y1 - y), tests[k], (*dets)[k], d1, &root)) {
        CurvePoint point = MakePoint(root);
        if (!Stopped()) codim2->push_back({tests[k].kind, std::move(point), "", 0.0, {}});
      }
      (*dets)[k] = d1;
    }
  }

  // The parameter part of the unit tangent, in the box's scaled coordinates.
  Eigen::Vector2d ParamDirection(const Vec& t) const { return {t[m()] / w1_, t[m() + 1] / w2_}; }
  // Distance of two curve points' parameters, scaled by the box's widths.
  double BoxDistance(const CurvePoint& a, const CurvePoint& b) const {
    return std::hypot((a.value1 - b.value1) / w1_, (a.value2 - b.value2) / w2_);
  }

  // A cusp on the step from y (tangent t) of length h, where the tangent's parameter part turns
  // against its direction u at y: the root of psi = u . (parameter part of the tangent at the
  // corrected point), psi1 at the step's end, to |psi| <= tol |u| (tol 0: until the sign change
  // is bracketed to rounding).
  bool LocateCusp(const Vec& y, const Vec& t, double h, double psi1, double tol, Vec* root) const {
    const Eigen::Vector2d u = ParamDirection(t);
    return LocateOnStep(
        y, t, h, u.squaredNorm(), psi1, tol * u.norm(),
        [&](const Vec& p, double* f) {
          Vec tp;
          if (!Tangent(p, t, &tp)) return false;
          *f = u.dot(ParamDirection(tp));
          return true;
        },
        root);
  }

  // A fold curve whose direction in the parameter plane reverses on the step from y (tangent t)
  // to y1 (tangent t1): a cusp, located (to |psi| <= tol |u|, LocateCusp) and appended. With
  // `probes`, that many points inside the step, at 1/2, 3/4, 7/8, ... of it (closing in on y1:
  // the step that ends a curve, see EndAtBoundary, where a cusp lies in a hook just before the
  // end and the direction stays reversed from it to the end), are looked at first, and the
  // first of them past a reversal ends the search interval instead of y1.
  void CuspOnStep(const Vec& y, const Vec& t, const Vec& y1, const Vec& t1,
                  std::vector<Codim2Point>* codim2, double tol = 1e-10, int probes = 0) const {
    if (kind_ != CurveKind::kFold) return;
    const double h = t.dot(y1 - y);
    double reach = h, psi_reach = ParamDirection(t).dot(ParamDirection(t1));
    for (int k = 1; k <= probes; ++k) {
      const double s = h * (1.0 - std::ldexp(1.0, -k));
      Vec p, tp;
      int iterations = 0;
      if (!Correct(y + s * t, t, &p, &iterations) || !Tangent(p, t, &tp)) continue;
      const double psi = ParamDirection(t).dot(ParamDirection(tp));
      if (psi < 0.0) {
        reach = s, psi_reach = psi;
        break;
      }
    }
    Vec root, tr;
    if (!(psi_reach < 0.0 && LocateCusp(y, t, reach, psi_reach, tol, &root))) return;
    // A cusp, not a turn: psi = 0 also where the direction has turned through a right angle
    // within the step (a hairpin, |parameter part| ~ |u| there); at a cusp the parameter part
    // itself vanishes (measured at the box's cusps: at most 2.5e-4 |u|, against 0.07 |u| at the
    // one hairpin seen, with target_iterations 4). And not one already found on this curve (a
    // curve passing a cusp twice, or the search reaching it from two steps).
    if (!Tangent(root, t, &tr) || ParamDirection(tr).norm() > 1e-2 * ParamDirection(t).norm()) {
      return;
    }
    CurvePoint point = MakePoint(root);
    for (const Codim2Point& q : *codim2) {
      if (q.kind == Codim2Kind::kCusp && BoxDistance(q.point, point) <= 1e-9) {
        return;
      }
    }
    if (!Stopped()) codim2->push_back({Codim2Kind::kCusp, std::move(point), "", 0.0, {}});
  }

  // Whether a violation is an event reaching the Poincare section rather than a grazing: the
  // first or the last segment vanishes, or the first segment's own ending guard fires at its
  // start (the same, seen by the event locator before the duration turns negative), or, on a
  // grazing curve whose first segment ends in its touch, that guard fires in the last segment
  // (of the same mode, running on across the section into the first): the touch reaching the
  // section, its guard within rounding of zero at the last segment's end. (In the reference box: a
  // grazing curve ended so at (0.1318, 0.1577) as a DOUBLE_GRAZING, and its part beyond the
  // section, crossed by the omega-branch at a = 0.17, was never traced.)
  // `end` is the last admissible orbit: its first segment must be of zero length to rounding
  // (the guard firing anywhere else inside it is a grazing, not a crossing); for a touch seen in
  // the last segment, up to 1e-6: the guard is quadratic about the touch, its value at the
  // section ~h'' d^2 / 2 for the first segment d long, and rounding makes it fire while d is
  // still ~sqrt(2 eps / h'') (4e-9 .. 1.9e-8 measured at three of the box's four such ends, the
  // fourth below 1e-9).
  bool IsSectionCrossing(const Admissibility& v, const PeriodicOrbit& end) const {
    const double first_max = v.guard >= 0 && v.segment != 0 ? 1e-6 : 1e-9;
    return MayBeSectionCrossing(v) && (v.guard < 0 || std::abs(end.durations[0]) <= first_max);
  }

  // IsSectionCrossing without the end's first-segment duration (which needs the boundary
  // bisected to rounding).
  bool MayBeSectionCrossing(const Admissibility& v) const {
    const std::vector<SegmentSpec>& segs = bvp1_.signature().segments;
    const int k = static_cast<int>(segs.size());
    if (v.admissible || k < 3) return false;
    if (v.guard < 0) return v.segment == 0 || v.segment == k - 1;
    if (v.segment == k - 1) {
      return !v.at_start && segs[0].tangent && v.guard == segs[0].guard &&
             segs[k - 1].mode == segs[0].mode;
    }
    return v.segment == 0 && v.guard == segs[0].guard && !segs[0].tangent;
  }

  // Whether every codimension-2 test function has the same sign at two monodromies.
  static bool SameSigns(const std::vector<Codim2Test>& tests, const Mat& a, const Mat& b) {
    return std::all_of(tests.begin(), tests.end(), [&](const Codim2Test& test) {
      return (test.f(a) > 0.0) == (test.f(b) > 0.0);
    });
  }

  // The admissibility boundary between curve points ya (admissible) and yb (not): bisection in
  // the arclength along t, each midpoint of the chord corrected onto the curve in the hyperplane
  // normal to t, until the bracket is below tol (1 + |y|). Beyond the boundary the extended
  // system need not be smooth (a segment of negative duration may cross a guard) and Newton can
  // stall there: a midpoint that does not correct counts as beyond, but then the boundary is
  // only known to lie between ya and the nearest corrected inadmissible point `beyond`. ya is
  // always a corrected admissible point; `why` / `violation` name the violation at `beyond`.
  // `beyond_corrected`: whether `beyond` is a corrected point (not where the end came from a
  // prediction, end_ahead's, and no midpoint beyond the boundary corrected since). From a
  // prediction, a midpoint beyond counts so only where it lands within kMaxDrift of its distance
  // from ya (as a step's, below): period-2 curves next to slow lift-offs brought
  // predictions ~65 ahead (where the tangent said a flight vanishes), whose first midpoints
  // corrected ~50 away onto orbits with that flight -24 long, and the end was reported with a
  // bracket of ~100 though the curve had stopped for its corrector failing at the last point (8
  // of the 12 entries above 1e-8 in omega [0.09, 0.11], a [0.25, 0.75]). The bisection's course
  // is the same either way (refusing such midpoints moved a period-1 curve's end of the
  // reference box, whose bisection had jumped 7e-4 along it, to a FOLD_GRAZING 4e-5 before the
  // jump, and left a 3-point piece of it at the box's edge untraced).
  struct Boundary {
    Vec ya, yb, beyond;
    std::string why;
    Admissibility violation;
    bool beyond_corrected = true;
    bool from_prediction = false;
    double Width(const Vec& t) const { return t.dot(beyond - ya); }
  };
  // A step is refused (and retried shorter, as when Newton fails) when the corrected point lies
  // farther than kMaxDrift times the step from the prediction: along a smooth curve of curvature
  // kappa the distance is about kappa h^2 / 2, so beyond h / 4 the tangent turns by ~0.5 rad
  // within the step, or the corrector has landed on another branch of solutions. With
  // target_iterations 4 a step of 0.86 on the PD curve from the flip-grazing at
  // (omega, a) = (0.35, 0.2446) landed 0.44 h away, with the CwoP phase that vanishes at
  // a = 0.17943 (the flip-grazing the default steps find) 0.81 long instead of crossing zero, and
  // the curve went on to another flip-grazing 1e-2 further.
  static constexpr double kMaxDrift = 0.25;

  void Bisect(const Vec& t, double tol, Boundary* b) const {
    tol *= 1.0 + b->ya.lpNorm<Eigen::Infinity>();
    for (int it = 0; it < 80 && t.dot(b->yb - b->ya) > tol && !Stopped(); ++it) {
      const Vec mid = 0.5 * (b->ya + b->yb);
      Vec yc;
      int iterations = 0;
      std::string reason;
      Admissibility violation;
      if (!Correct(mid, t, &yc, &iterations, nullptr, false)) {
        b->yb = mid;
      } else if (Admissible(Unpack(yc), &reason, &violation)) {
        b->ya = yc;
      } else {
        b->yb = b->beyond = yc, b->why = reason, b->violation = violation;
        b->beyond_corrected =
            !b->from_prediction || (yc - mid).norm() <= kMaxDrift * (mid - b->ya).norm();
      }
    }
  }

  // The end solved in tangent form (grazing_end.h): where the violation beyond it is a segment
  // vanishing between two segments of one mode (TangentForm; seen in the ways `vanishing` lists),
  // or a guard touching zero inside a segment (TouchForm at that segment and guard; at the
  // admissible end the touch is within the bracket of zero). Kept when the solution lies within
  // the bisection's bracket of the end (else
  // it is another root: where the vanishing segment's events leave the monodromy discontinuous,
  // the tangent form's fold or PD condition is not the curve's) and is admissible; the end is then
  // that point, in tangent form, with bracket 0. Failing that: held at zero length (events of two
  // surfaces), and on a grazing curve the touch merged into the event next to it
  // (SolveMergedTouchEnd; admissible but for the next mode's guard touching zero to third order
  // at its start, which rounding may show as firing there). Last, where none of these solves (a
  // contact phase vanishing between two flights: the zero-length system is singular, the
  // tangent form's root another point), the limit of the curve's points as the segment's length
  // goes to zero (ExtrapolateZeroLength), kept under the same checks (the flight after the
  // zero-length segment starts on the impact surface at zero speed, its guard touching zero
  // there to third order, as above) and when its estimated error is below the bisection's
  // bracket; that error is then the end's bracket.
  bool SolveEnd(Codim2Point* end) const {
    const Admissibility& v = end->violation;
    const std::vector<SegmentSpec>& segs = end->point.orbit.signature.segments;
    const int i = v.segment;
    if (v.admissible || i < 0 || i >= static_cast<int>(segs.size())) return false;
    const PeriodicOrbit& o = end->point.orbit;
    const int k = static_cast<int>(segs.size());
    // Segment j vanishing, seen (v) as its duration turning negative, or as a guard firing
    // before the duration does (the duration goes like the square root of the distance to the
    // grazing, and its end guard's rate h' with it): j's own guard inside j while j is at most
    // 1e-5 long (1e-3 where it fires at j's start: j wants to end at once; a PD curve of issue
    // 4's box stopped with a progression phase 2e-5 long whose l1 fired at its start), or, at the
    // very start of the next segment, the guard that led into j from the segment before it (j would
    // start again at once), or, before the end of the segment before it, that segment's own guard
    // (the one that starts j) firing early: the flow of that mode touches the guard where j shrinks
    // away, as a contact phase's force reaching the progression threshold just before a short
    // progression phase between two contact phases vanishes (a PD curve of the reference box with
    // longer steps: l1 inside CwoP 6e-3 before its end, CwP 3e-3 long, bracket 6e-3 as Newton fails
    // next to the end); j at most 1e-2 long (a touch inside a segment followed by a long one is an
    // interior grazing, the touch form's). A solution is kept only within the bracket (below), so a
    // wrong guess costs a Newton run.
    int j = -1;
    if (v.guard < 0) {
      j = i;
    } else if (v.guard == segs[i].guard && std::abs(o.durations[i]) <= (v.at_start ? 1e-3 : 1e-5)) {
      j = i;
    } else if (i >= 2 && v.at_start && segs[i - 2].mode == segs[i].mode &&
               v.guard == segs[i - 2].guard) {
      j = i - 1;
    } else if (!v.at_start && v.guard == segs[i].guard && i + 2 < k &&
               segs[i + 2].mode == segs[i].mode && o.durations[i + 1] <= 1e-2) {
      j = i + 1;
    }
    // Kept when within the bracket of the end, admissible (for a zero-length segment: but for
    // that segment's own duration, zero to rounding) and, on a fold / PD curve, with the
    // multiplier +1 / -1 among the eigenvalues to 1e-8 (independent of sigma and its borders:
    // where a zero-length segment's saltation degenerates, sigma = 0 was met without it).
    // `point` receives the accepted end (its stability is the one checked).
    CurvePoint point;
    auto accept = [&](const StatusOr<PeriodicOrbit>& solved, int zero_length, int touch_start = -1,
                      const Stability* stability = nullptr) {
      if (!solved.ok()) return false;
      const double moved = std::hypot(solved->params[index1_] - end->point.value1,
                                      solved->params[index2_] - end->point.value2);
      if (moved > 2.0 * end->bracket + 1e-9) return false;
      for (const Admissibility& w : AdmissibilityViolations(model_, propagator_, *solved)) {
        if (w.segment == touch_start && w.at_start &&
            internal::TouchesAtStart(model_, *solved, w.segment, w.guard)) {
          continue;
        }
        if (w.segment != zero_length || w.guard >= 0) return false;
      }
      point = PointFromOrbit(*solved, stability);
      if (kind_ == CurveKind::kFold || kind_ == CurveKind::kPeriodDoubling) {
        const double target = kind_ == CurveKind::kFold ? 1.0 : -1.0;
        const std::vector<std::complex<double>>& mu = point.stability.multipliers;
        return std::any_of(mu.begin(), mu.end(), [&](const std::complex<double>& z) {
          return std::abs(z - target) <= 1e-8;
        });
      }
      return true;
    };
    const bool same_mode = j > 0 && j + 1 < k && segs[j - 1].mode == segs[j + 1].mode;
    StatusOr<PeriodicOrbit> solved = Status(StatusCode::kUnimplemented, "");
    std::string how = " (solved in tangent form)";
    if (same_mode) {
      const StatusOr<PeriodicOrbit> form = internal::TangentForm(o, j);
      if (form.ok()) {
        solved = internal::SolveGrazingEnd(model_, propagator_, *form, kind_, index1_, index2_);
      }
    } else if (j < 0 && v.guard >= 0) {
      const StatusOr<PeriodicOrbit> form =
          internal::TouchForm(model_, propagator_, o, 1e-6, i, v.guard);
      if (form.ok()) {
        solved = internal::SolveGrazingEnd(model_, propagator_, *form, kind_, index1_, index2_);
      }
    }
    bool ok = accept(solved, -1);
    // Held at zero length only where the two events are of different surfaces (the same surface
    // twice, as l1 into and out of progression, is the degenerate case of tangent_grazing.h).
    if (!ok && internal::EventsOfTwoSurfaces(model_, o.signature, j)) {
      solved = internal::SolveZeroLengthEnd(model_, propagator_, o, j, kind_, index1_, index2_);
      how = " (solved with segment " + std::to_string(j) + " of zero length)";
      ok = accept(solved, j);
    }
    if (!ok && kind_ == CurveKind::kGrazing) {
      solved = internal::SolveMergedTouchEnd(model_, propagator_, o, j, index1_, index2_);
      how = " (solved with the touch merged into the event next to it)";
      ok = accept(solved, -1, j);
    }
    double error = 0.0;
    if (!ok && j >= 0) {
      const StatusOr<internal::ExtrapolatedEnd> limit =
          internal::ExtrapolateZeroLength(model_, propagator_, o, j, kind_, index1_, index2_);
      if (limit.ok() && limit->error < end->bracket) {
        ok = accept(limit->orbit, j, j + 1, &limit->stability);
        error = limit->error;
        how = " (extrapolated to segment " + std::to_string(j) + " of zero length)";
      }
    }
    if (!ok) return false;
    end->point = std::move(point);
    end->bracket = error;
    end->detail += how;
    return true;
  }

  // The step y -> y1 left the box: the point where it crosses the edge it meets first is solved
  // with that parameter fixed at the bound and appended, so that a curve ends on the box (the
  // stability region's polygons need its crossing there). Skipped when the corrector fails or
  // the orbit there is not admissible.
  void EndOnBox(const Vec& y, const Vec& y1, std::vector<CurvePoint>* points) const {
    double first = 2.0, bound = 0.0;
    int index = -1;
    for (const int j : {m(), m() + 1}) {
      const double lo = j == m() ? options_.min1 : options_.min2;
      const double hi = j == m() ? options_.max1 : options_.max2;
      for (const double c : {lo, hi}) {
        if (!std::isfinite(c) || (y1[j] - c) * (y[j] - c) >= 0.0) continue;
        const double w = (c - y[j]) / (y1[j] - y[j]);
        if (w < first) first = w, bound = c, index = j;
      }
    }
    if (index < 0) return;
    Vec guess = y + first * (y1 - y), fixed = Vec::Zero(n()), yc;
    guess[index] = bound;
    fixed[index] = 1.0;
    int iterations = 0;
    if (!Correct(guess, fixed, &yc, &iterations)) return;
    yc[index] = bound;  // exactly: the corrector keeps it to rounding
    CurvePoint p = MakePoint(yc);
    std::string why;
    if (yc[m()] >= options_.min1 && yc[m()] <= options_.max1 && yc[m() + 1] >= options_.min2 &&
        yc[m() + 1] <= options_.max2 && Admissible(p.orbit, &why) && !Stopped()) {
      points->push_back(std::move(p));
    }
  }

  // The requested lambda1 / lambda2 values crossed on the step y -> y1, each solved with that
  // parameter fixed and appended to *crossings.
  void CrossingsOnStep(const Vec& y, const Vec& y1, std::vector<CurvePoint>* crossings) const {
    for (const int j : {m(), m() + 1}) {
      for (double c : j == m() ? options_.crossings1 : options_.crossings2) {
        if ((y[j] - c) * (y1[j] - c) > 0.0 || y[j] == y1[j]) continue;
        const double w = (c - y[j]) / (y1[j] - y[j]);
        Vec guess = y + w * (y1 - y), fixed = Vec::Zero(n()), yc;
        guess[j] = c;
        fixed[j] = 1.0;
        int it = 0;
        if (!Correct(guess, fixed, &yc, &it)) continue;
        CurvePoint point = MakePoint(yc);
        if (!Stopped()) crossings->push_back(std::move(point));
      }
    }
  }

  // The curve's end on the step from y (tangent t) towards yb, where the orbit is not admissible
  // (`why`, `violation`): a codimension-2 point appended to *codim2, or a Poincare-section
  // crossing (*crossing filled, the end appended to *points). Roots of the test functions on the
  // way are appended too, and the requested crossings before the end (*crossings). Returns how
  // the direction ended. `unverified`, given where yb is a prediction (not corrected): an end
  // only that prediction brackets goes there instead (below).
  std::string EndAtBoundary(const Vec& y, const Vec& t, const Vec& yb, const std::string& why,
                            const Admissibility& violation, const std::vector<Codim2Test>& tests,
                            std::vector<double>* dets, std::vector<CurvePoint>* points,
                            std::vector<CurvePoint>* crossings, std::vector<Codim2Point>* codim2,
                            SectionCrossing* crossing,
                            std::vector<Codim2Point>* unverified = nullptr) const {
    // A curve ends where its orbit grazes (a segment vanishes or a guard is touched inside
    // one): on a fold or PD curve a fold- or flip-grazing, on a grazing curve a double
    // grazing (a second boundary touched at once).
    // Bisected first to 1e-8 (relative): where the end is then solved in tangent form (and no
    // test function changes sign between the bisected and the solved end) that is all it
    // needs; else (and where the violation may be a section crossing, told apart by a
    // first segment of zero length to rounding) on to 1e-12.
    Boundary b{y, yb, yb, why, violation, unverified == nullptr, unverified != nullptr};
    Bisect(t, 1e-8, &b);
    if (MayBeSectionCrossing(b.violation)) Bisect(t, 1e-12, &b);
    const Codim2Kind k = kind_ == CurveKind::kFold            ? Codim2Kind::kFoldGrazing
                         : kind_ == CurveKind::kGrazing       ? Codim2Kind::kDoubleGrazing
                         : kind_ == CurveKind::kNeimarkSacker ? Codim2Kind::kNsGrazing
                                                              : Codim2Kind::kFlipGrazing;
    CurvePoint end = MakePoint(b.ya);
    Codim2Point point{k, end, b.why, b.Width(t), b.violation};
    const bool crossing_first = IsSectionCrossing(b.violation, end.orbit);
    bool solved = !crossing_first && SolveEnd(&point) &&
                  SameSigns(tests, end.stability.monodromy, point.point.stability.monodromy);
    if (!crossing_first && !solved) {
      Bisect(t, 1e-12, &b);
      end = MakePoint(b.ya);
      point = {k, end, b.why, b.Width(t), b.violation};
      solved = SolveEnd(&point);
    }
    // Roots of the test functions between the last point and the boundary (a fold- or
    // flip-grazing root can lie next to a double grazing end), and requested values crossed
    // there (at a section crossing the curve goes on from b.ya in the rotated signature: a
    // crossing of omega = 0.065 by a PD curve of the reference box, within such a step, was lost).
    RootsOnStep(y, t, b.ya, end.stability.monodromy, tests, dets, codim2);
    CrossingsOnStep(y, b.ya, crossings);
    // And a cusp: a fold curve approaching a fold-grazing nearly at rest in the parameter plane
    // (its orbit changing while the parameters barely move) can turn just before its end. The
    // direction at the end itself is not to be trusted (below), and next to it Newton may fail
    // (the fixed-signature system meets its zero-length solutions there), so the step is probed
    // at 7 inner points closing in on the end and the cusp located before the first one past a
    // reversal, until the sign change is bracketed to rounding (psi is 1e-13 .. 1e-9 there). In
    // the reference box this found 2 more cusps with the default steps (4e-9 and 5e-9, box-scaled,
    // before their curve's end, where psi was 4e-13 of the wrong sign) and 3 more with
    // target_iterations 4 (where the search's trial points next to the end did not correct):
    // 21 -> 23 and 20 -> 23 cusps, the same 23 (evenly spaced probes found 22 with the longer
    // steps: their hooks are shorter than an eighth of the step).
    if (Vec ta; kind_ == CurveKind::kFold && Tangent(b.ya, t, &ta)) {
      const size_t found = codim2->size();
      CuspOnStep(y, t, b.ya, ta, codim2, 0.0, 7);
      // Not the end's own: there the fixed-signature curve meets the family of zero-length
      // solutions and its parameters are stationary (they move as the square of the vanishing
      // duration), so the direction's sign at b.ya is noise and a reversal is "located" at the
      // end itself (five of the box's ends, within 1e-10 of it; the cusp this check adds in the
      // box lies 1e-8 before its end, with the direction resolved on both sides: |u| 1.8e-6 at
      // the step's start, 3.3e-7 at its end).
      if (codim2->size() > found &&
          std::hypot((codim2->back().point.value1 - b.ya[m()]) / w1_,
                     (codim2->back().point.value2 - b.ya[m() + 1]) / w2_) <= 1e-9) {
        codim2->pop_back();
      }
    }
    if (Stopped()) return kCancelledEnd;  // nothing computed after a stop is kept
    if (IsSectionCrossing(b.violation, end.orbit)) {
      crossing->happened = true;
      crossing->orbit = end.orbit;
      crossing->violation = b.violation;
      // As the vanishing of that segment (SwitchSignature); seen as a guard firing, the first
      // segment, which ends on it.
      if (b.violation.guard >= 0) crossing->violation.segment = 0;
      crossing->violation.guard = -1;
      crossing->direction = ParamDirection(t).normalized();
      crossing->end = point;
      crossing->unverified = !b.beyond_corrected;
      points->push_back(end);
      return "crossed the Poincare section";
    }
    // Bracketed only by a prediction and not solved: no orbit beyond the last point is known to
    // violate anything. A prediction off the curve is not admissible for reasons of its own: next
    // to a slow lift-off (the contact force's rate ~2e-3) the guard row's residual at a prediction
    // (~2e-7) moves that event ~1e-4 earlier, which reads as the guard crossed inside the segment
    // (period-2 curves next to a = 0.689, omega = 0.1, in the box omega [0.09, 0.11],
    // a [0.25, 0.75]: such ends were reported as codimension-2 points with brackets up to 345;
    // and section crossings only a prediction brackets are taken up as any other, but where the
    // rotated signature does not correct they are unverified ends too (ContinueCurve): the last
    // flight vanishing in a prediction ~65 ahead while it was 24 long at the last point, 8 ends
    // with brackets of ~100. Of the box's 64 entries bracketed above 1e-8, 4 are left).
    // The direction ends there, and the codimension-2 point it may be heading for is not claimed:
    // kept apart (CurveResult::unverified_ends), for switching to try the curves that may leave
    // it.
    if (!b.beyond_corrected && !solved) {
      unverified->push_back(point);
      return UnverifiedEndText(options_, point, b.why);
    }
    codim2->push_back(point);
    return std::string("ended at a ") + Codim2KindName(k) + " point: " + point.detail;
  }

  // Traces one direction from the start, leaving it along the parameter direction `dir`
  // (box-scaled; (0, +-1): across the one-parameter branch the start was located on); returns
  // why it ended. At a Poincare-section crossing (an event reaching s = 0: the first or last
  // segment vanishes) the orbit goes on and only its representation changes: the last point is
  // appended, *crossing filled, and ContinueCurve goes on in the rotated signature.
  std::string Trace(const Eigen::Vector2d& dir, std::vector<CurvePoint>* points,
                    std::vector<CurvePoint>* crossings, std::vector<Codim2Point>* codim2,
                    std::vector<Codim2Point>* unverified, ContinuationSummary* sum,
                    SectionCrossing* crossing) const {
    Vec y = start_, t, prev = Vec::Zero(n());
    SetBorders(OrbitStability(model_, propagator_, Unpack(y)).monodromy);
    prev[m()] = dir[0] * w1_;
    prev[m() + 1] = dir[1] * w2_;
    if (!Tangent(y, prev, &t)) return "no tangent at the start point";
    double h = options_.steps.initial_step;
    const auto tests = Codim2Tests();
    std::vector<double> dets;
    for (const Codim2Test& test : tests) dets.push_back(TestValue(test, y));
    // Stall watch: parameters (scaled by the box where it is finite) 50 accepted steps back.
    constexpr int kStallWindow = 50;
    std::vector<Eigen::Vector2d> recent;
    double h_first = h;  // the first step tried from y
    // Where the steps from y fail or collapse next to a boundary: a prediction beyond it (the
    // first step tried, or 1.5 times the step at which the tangent says the first shrinking
    // segment vanishes), when not admissible, brackets that boundary with y.
    // `failed`: what happened, e.g. "the corrector failed"; the returned reason begins with it.
    auto end_ahead = [&](const std::string& failed) -> std::optional<std::string> {
      double vanish = std::numeric_limits<double>::infinity();
      for (int i = 0; i < bvp1_.segments(); ++i) {
        const double tau = y[bvp1_.DurationIndex(i)], rate = t[bvp1_.DurationIndex(i)];
        if (rate < 0.0) vanish = std::min(vanish, -tau / rate);
      }
      for (const double ahead_by : {h_first, 1.5 * vanish}) {
        if (!std::isfinite(ahead_by)) continue;
        const Vec ahead = y + ahead_by * t;
        std::string why;
        Admissibility violation;
        if (!Admissible(Unpack(ahead), &why, &violation)) {
          const size_t before = unverified->size();
          const std::string end = EndAtBoundary(y, t, ahead, why, violation, tests, &dets, points,
                                                crossings, codim2, crossing, unverified);
          return failed + (unverified->size() == before ? " short of a boundary, " : " ") + end;
        }
      }
      return std::nullopt;
    };
    for (int step = 0; step < options_.steps.max_steps; ++step) {
      if (Stopped()) return kCancelledEnd;
      Vec y1;
      int iterations = 0;
      Vec t1;
      // A step is refused (and retried shorter, as when Newton fails) when the corrected point
      // drifted (kMaxDrift).
      if (!Correct(y + h * t, t, &y1, &iterations, &t1) ||
          (y1 - (y + h * t)).norm() > kMaxDrift * h) {
        ++sum->rejected_steps;
        h *= 0.5;
        if (Stopped()) return kCancelledEnd;
        if (h < options_.steps.min_step) {
          // Newton failed on every step from y down to min_step: next to a boundary where the
          // curve's own system degenerates (a segment vanishing like a square root) no
          // prediction beyond it corrects.
          if (std::optional<std::string> end = end_ahead("the corrector failed")) return *end;
          return "the corrector failed down to min_step";
        }
        --step;
        continue;
      }
      sum->newton_iterations += iterations;
      ++sum->steps;
      h = std::clamp(h * internal::StepFactor(iterations, options_.steps.target_iterations),
                     options_.steps.min_step, options_.steps.max_step);
      const double v1 = y1[m()], v2 = y1[m() + 1];
      if (v1 < options_.min1 || v1 > options_.max1 || v2 < options_.min2 || v2 > options_.max2) {
        EndOnBox(y, y1, points);
        return Stopped() ? kCancelledEnd : "left the box";
      }
      // A curve that creeps (the step collapsed while Newton still converges, as next to a
      // fold-grazing where a segment's duration goes to zero like a square root) is ended rather
      // than left to spend max_steps: at the boundary ahead where there is one (three PD curves
      // stepped off flip-grazings in the reference box crept, their parameters moving ~1e-9 per
      // step, towards a progression phase between two contact phases vanishing 4e-4 ahead), else as
      // stalled.
      recent.emplace_back(v1 / w1_, v2 / w2_);
      if (static_cast<int>(recent.size()) > kStallWindow) {
        const double moved = (recent.back() - recent.front()).norm();
        recent.erase(recent.begin());
        if (moved < 1e-6) {
          if (std::optional<std::string> end = end_ahead("the steps collapsed")) return *end;
          char where[160];
          std::snprintf(where, sizeof where,
                        "stalled: the parameters moved %.1e (of the box) in %d steps, near "
                        "(%.9g, %.9g)",
                        moved, kStallWindow, v1, v2);
          return where;
        }
      }
      CurvePoint p = MakePoint(y1);
      std::string why;
      Admissibility violation;
      const bool admissible = Admissible(p.orbit, &why, &violation);
      if (Stopped()) return kCancelledEnd;
      if (!admissible) {
        // A curve ends where its orbit grazes (a segment vanishes or a guard is touched inside
        // one): on a fold or PD curve a fold- or flip-grazing, on a grazing curve a double
        // grazing (a second boundary touched at once).
        return EndAtBoundary(y, t, y1, why, violation, tests, &dets, points, crossings, codim2,
                             crossing);
      }
      CrossingsOnStep(y, y1, crossings);
      RootsOnStep(y, t, y1, p.stability.monodromy, tests, &dets, codim2);
      SetBorders(p.stability.monodromy);
      points->push_back(std::move(p));
      CuspOnStep(y, t, y1, t1, codim2);
      y = y1;
      t = t1;
      h_first = h;
    }
    return "reached max_steps";
  }

 private:
  const HybridModel& model_;
  Propagator& propagator_;
  const CurveOptions& options_;
  CurveKind kind_;
  int index1_, index2_;
  Params base_;
  double w1_ = 1.0, w2_ = 1.0;  // the box's widths where finite: parameter scales
  internal::OrbitBvp bvp1_;     // derivatives in both parameters
  Vec start_;
  mutable internal::BorderedSigma sigma_;  // SetBorders
  // A grazing curve of a corner (internal::CornerSegment): the segment held at zero length, its
  // duration the curve's condition; -1 for a grazing curve of a touch (a tangent end).
  int corner_ = -1;
};

}  // namespace

CurveResult ContinueCurve(const HybridModel& model, Propagator& propagator,
                          const SpecialPoint& start, const CurveOptions& options,
                          const ProgressCallback& progress) {
  CurveResult result;
  ContinuationSummary& sum = result.summary;
  internal::PhaseProgress phase(propagator, progress);
  auto cancelled = [&] {
    sum.termination = Termination::kCancelled;
    sum.status = Cancelled("curve cancelled");
    sum.message = sum.message.empty() ? "cancelled" : sum.message;
    return result;
  };
  auto fail = [&](Status s) {
    sum.termination = Termination::kFailed;
    sum.status = s;
    sum.message = s.message();
    return result;
  };
  if (Status s = options.Validate(); !s.ok()) return fail(s);
  StatusOr<int> i1 = model.ParamIndex(options.param1);
  if (!i1.ok()) return fail(Status(StatusCode::kInvalidArgument, i1.status().message()));
  StatusOr<int> i2 = model.ParamIndex(options.param2);
  if (!i2.ok()) return fail(Status(StatusCode::kInvalidArgument, i2.status().message()));
  const PeriodicOrbit& orbit = start.point.orbit;
  PeriodicOrbit tangent_orbit;
  switch (start.kind) {
    case SpecialPointKind::kFold:
      result.kind = CurveKind::kFold;
      break;
    case SpecialPointKind::kPeriodDoubling:
      result.kind = CurveKind::kPeriodDoubling;
      break;
    case SpecialPointKind::kNeimarkSacker:
      result.kind = CurveKind::kNeimarkSacker;
      break;
    case SpecialPointKind::kGrazingL1:
    case SpecialPointKind::kGrazingL2:
    case SpecialPointKind::kGrazingPi: {
      // The touching point: the vanishing segment i (zero length at the located point) goes, and
      // segment i - 1, in the same mode as i + 1, ends tangentially on its guard instead. Without
      // a vanishing segment (the grazing seen from the side where the guard is not reached, e.g.
      // a free flight touching Pi), the segment where a guard touches zero is split there.
      // A corner (a segment of zero length between events of two surfaces) without a tangent
      // form at that segment is traced as it is, the segment held at zero length.
      result.kind = CurveKind::kGrazing;
      const bool tangent_given =
          std::any_of(orbit.signature.segments.begin(), orbit.signature.segments.end(),
                      [](const SegmentSpec& seg) { return seg.tangent; });
      const int corner = internal::CornerSegment(model, orbit);
      const bool corner_given = corner >= 0 && !internal::TangentForm(orbit, corner).ok();
      StatusOr<PeriodicOrbit> tangent =
          tangent_given || corner_given ? StatusOr<PeriodicOrbit>(orbit)
                                        : internal::GrazingTangentForm(model, propagator, orbit);
      if (phase.stopped()) return cancelled();
      if (!tangent.ok()) return fail(tangent.status());
      tangent_orbit = *std::move(tangent);
      break;
    }
    default:
      return fail(InvalidArgument(std::string("a curve starts at a FOLD, PERIOD_DOUBLING, "
                                              "NEIMARK_SACKER or GRAZING point, not at ") +
                                  SpecialPointKindName(start.kind)));
  }
  CurveTracer tracer(model, propagator, options, result.kind, *i1, *i2,
                     result.kind == CurveKind::kGrazing ? tangent_orbit : orbit);
  if (!tracer.CorrectStart()) {
    if (phase.stopped()) return cancelled();
    return fail(Internal("could not put the start point on the curve"));
  }
  CurvePoint start_point = tracer.MakePoint(tracer.start());
  if (phase.stopped()) return cancelled();
  // One direction, through Poincare-section crossings: each goes on with a tracer in the rotated
  // signature (internal::SwitchSignature), leaving along the direction the curve arrived with.
  constexpr int kMaxSectionCrossings = 32;
  auto run = [&](double sign, std::vector<CurvePoint>* points) {
    std::vector<std::unique_ptr<CurveTracer>> rotated;
    const CurveTracer* current = &tracer;
    Eigen::Vector2d dir(0.0, sign);
    for (int crossed = 0;; ++crossed) {
      SectionCrossing cross;
      const std::string end = current->Trace(dir, points, &result.crossings, &result.codim2,
                                             &result.unverified_ends, &sum, &cross);
      const std::string through =
          crossed == 0 ? "" : "through " + std::to_string(crossed) + " section crossings, ";
      if (!cross.happened || phase.stopped()) return through + end;
      if (crossed == kMaxSectionCrossings) return through + "stopped at the next one";
      const internal::SwitchedOrbit sw =
          internal::SwitchSignature(model, propagator, cross.orbit, cross.violation);
      rotated.push_back(std::make_unique<CurveTracer>(model, propagator, options, result.kind, *i1,
                                                      *i2, sw.orbit));
      if (!rotated.back()->CorrectStart()) {
        if (phase.stopped()) return through + "cancelled";
        // Not taken up there (seen where the first segment's guard fires at its start, after
        // contact phases): the curve ends there, reported as before, with the reason; not as a
        // point where only a prediction brackets the crossing (EndAtBoundary).
        const std::string why = "a Poincare-section crossing whose rotated signature " + sw.detail +
                                " could not be corrected";
        if (cross.unverified) {
          result.unverified_ends.push_back(cross.end);
          return through + "stopped " +
                 UnverifiedEndText(options, cross.end, cross.end.detail + "; " + why);
        }
        result.codim2.push_back(cross.end);
        return through + "ended at a " + Codim2KindName(cross.end.kind) +
               " point: " + cross.end.detail + " (" + why + ")";
      }
      current = rotated.back().get();
      dir = cross.direction;
    }
  };
  std::vector<CurvePoint> backward, forward;
  const std::string end_forward = run(+1.0, &forward);
  phase.Continue(0.5);
  const std::string end_backward = phase.stopped() ? "cancelled" : run(-1.0, &backward);
  std::reverse(backward.begin(), backward.end());
  result.points = std::move(backward);
  result.points.push_back(std::move(start_point));
  result.points.insert(result.points.end(), forward.begin(), forward.end());
  // A cusp next to one of the curve's ends is that end: at a fold-grazing end the parameters move
  // as the square of the vanishing duration, so the direction test sees a reversal there, and a
  // curve started just off its end (stepped off a codimension-2 root, trace.cc) begins inside
  // that hook, where the cusp test's tangent ratio is relative to an already stationary tangent.
  // Measured in the reference box: such points 7e-10 from the end (box-scaled), real cusps in a
  // hook before an end 4e-9 .. 5e-9 from it; 1e-9 lies between.
  auto at_an_end = [&](const Codim2Point& cusp) {
    return cusp.kind == Codim2Kind::kCusp &&
           std::any_of(result.codim2.begin(), result.codim2.end(), [&](const Codim2Point& e) {
             return e.kind != Codim2Kind::kCusp && !e.detail.empty() &&
                    tracer.BoxDistance(e.point, cusp.point) <= 1e-9;
           });
  };
  result.codim2.erase(std::remove_if(result.codim2.begin(), result.codim2.end(), at_an_end),
                      result.codim2.end());
  sum.message = "increasing " + options.param2 + ": " + end_forward + "; decreasing " +
                options.param2 + ": " + end_backward;
  if (phase.stopped()) return cancelled();
  // Not a single step either way (and no codimension-2 end next to the start, claimed or not):
  // no curve.
  sum.termination =
      forward.empty() && backward.empty() && result.codim2.empty() && result.unverified_ends.empty()
          ? Termination::kFailed
          : Termination::kCompleted;
  if (sum.termination == Termination::kFailed) {
    sum.status = Internal("no step from the start point: " + sum.message);
    sum.message = sum.status.message();
  }
  return result;
}

}  // namespace drillbif
