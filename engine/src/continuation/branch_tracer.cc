#include "continuation/branch_tracer.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>

#include "continuation/arclength.h"
#include "continuation/period_doubling.h"
#include "continuation/signature_switch.h"
#include "continuation/tangent_grazing.h"

namespace drillbif::internal {
namespace {

double Sign(double v) { return v > 0.0 ? 1.0 : (v < 0.0 ? -1.0 : 0.0); }

SideStability SideOf(const Stability& stability) {
  SideStability side;
  side.known = true;
  side.stable = stability.stable;
  for (const std::complex<double>& mu : stability.multipliers) {
    side.max_modulus = std::max(side.max_modulus, std::abs(mu));
  }
  return side;
}

// A short decimal form of a small positive number ("1.8e-13").
std::string ShortNumber(double x) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.2g", x);
  return buf;
}

}  // namespace

BranchTracer::BranchTracer(const HybridModel& model, Propagator& propagator,
                           const ContinuationOptions& options, int param)
    : model_(model),
      propagator_(propagator),
      options_(options),
      param_(param),
      corrector_(system_,
                 options.steps.condensed_solve ? CondensedMode::kAuto : CondensedMode::kDense) {}

Params BranchTracer::ParamsAt(double value) const {
  Params p = base_;
  p[param_] = value;
  return p;
}

Status BranchTracer::Init(const PeriodicOrbit& start, int sign, bool record_start,
                          ContinuationResult* result) {
  base_ = start.params;
  bvp_ = std::make_unique<OrbitBvp>(model_, propagator_, start.signature, param_);
  y_.resize(m() + 1);
  y_.head(m()) = bvp_->Pack(start);
  y_[m()] = start.params[param_];
  start_y_ = y_;
  start_signature_ = start.signature;
  halves_meet_ = start.signature.periods % 2 == 0 && !TraversedTwice(model_, propagator_, start);
  Vec prev = Vec::Zero(m() + 1);
  prev[m()] = sign > 0 ? 1.0 : -1.0;
  double det = 0.0;
  if (!Tangent(y_, prev, &t_, &det)) return Internal("no tangent at the start orbit");
  point_ = MakePoint(y_);
  tests_ = Tests(y_, t_, det, point_);
  h_ = options_.steps.initial_step;
  if (propagator_.stopped()) return Cancelled("cancelled at the start orbit");
  if (record_start) result->points.push_back(point_);
  return Status::Ok();
}

bool BranchTracer::System::EvaluateInto(const Vec& y, Vec* f,
                                        Eigen::Ref<Eigen::MatrixXd>* jac) const {
  const int m = tracer_.m();
  const Params prm = tracer_.ParamsAt(y[m]);
  if (!tracer_.model_.ValidateParams(prm).ok()) return false;
  if (!jac) return tracer_.bvp_->Evaluate(y.head(m), prm, f, nullptr, nullptr).ok();
  // G's Jacobian goes straight into jac's left block.
  Vec gp;
  if (!tracer_.bvp_->EvaluateInto(y.head(m), prm, f, jac->leftCols(m), &gp).ok()) return false;
  jac->col(m) = gp;
  return true;
}

bool BranchTracer::System::Valid(const Vec& y) const {
  return tracer_.model_.ValidateParams(tracer_.ParamsAt(y[tracer_.m()])).ok();
}

bool BranchTracer::Correct(const Vec& y_pred, const Vec& dir, Vec* y, int* iterations,
                           bool accept_rounding_residual) {
  CorrectorOptions correct;
  correct.max_iterations = options_.steps.max_iterations;
  correct.tolerance = options_.steps.tolerance;
  correct.accept_rounding_residual = accept_rounding_residual;
  correct.validate_result = true;
  const bool ok = corrector_.Correct(correct, y_pred, dir, y, iterations);
  newton_ += corrector_.steps();
  return ok;
}

bool BranchTracer::Tangent(const Vec& y, const Vec& prev, Vec* t, double* det) {
  Vec g, gp;
  Eigen::MatrixXd gx, a(m() + 1, m() + 1);
  if (!bvp_->Evaluate(y.head(m()), ParamsAt(y[m()]), &g, &gx, &gp).ok()) return false;
  a.topLeftCorner(m(), m()) = gx;
  a.topRightCorner(m(), 1) = gp;
  if (!UnitTangent(a.topRows(m()), prev, t)) return false;
  a.bottomRows(1) = t->transpose();
  *det = Sign(a.partialPivLu().determinant());
  return true;
}

bool BranchTracer::TangentFromCorrector(Vec* t, double* det) const {
  if (!corrector_.Tangent(t)) return false;
  *det = corrector_.lu().DeterminantSign();
  return true;
}

PeriodicOrbit BranchTracer::OrbitAt(const Vec& y) const {
  PeriodicOrbit o;
  bvp_->Unpack(y.head(m()), ParamsAt(y[m()]), &o);
  return o;
}

ContinuationPoint BranchTracer::MakePoint(const Vec& y) const {
  ContinuationPoint p;
  p.value = y[m()];
  p.orbit = OrbitAt(y);
  p.measures = OrbitMeasures(model_, propagator_, p.orbit, options_.point_measures);
  p.stability = OrbitStability(model_, propagator_, p.orbit);
  p.period = kTwoPi * p.orbit.signature.periods / model_.ForcingFrequency(p.orbit.params);
  return p;
}

double BranchTracer::Measure(const Vec& y, int index) const {
  return OrbitMeasures(model_, propagator_, OrbitAt(y), 1u << index)[index];
}

TestValues BranchTracer::Tests(const Vec& y, const Vec& t, double det,
                               const ContinuationPoint& p) const {
  TestValues v;
  v.fold = t[m()];
  v.branch_point = det;
  std::complex<double> pd = 1.0, ns = 1.0;
  const auto& mu = p.stability.multipliers;
  v.nontrivial = static_cast<int>(mu.size());
  for (size_t i = 0; i < mu.size(); ++i) {
    pd *= mu[i] + 1.0;
    if (std::abs(mu[i].imag()) > 1e-12 * std::abs(mu[i])) v.complex_pair = true;
    for (size_t j = i + 1; j < mu.size(); ++j) ns *= mu[i] * mu[j] - 1.0;
  }
  v.period_doubling = pd.real();
  v.neimark_sacker = ns.real();
  if (!options_.locate_measure_maxima) return v;
  // d measure / ds: Richardson-extrapolated central differences along t (truncation ~eps^4, so
  // eps = 1e-3 in the units of Y leaves ~1e-12 of error, rounding ~1e-13). The measure is ROP,
  // or Pc where the orbit never progresses (ROP = 0).
  v.power = (p.measures.empty() || !(options_.point_measures & 1u) ? Measure(y, 0)
                                                                   : p.measures[0]) == 0.0;
  const int index = v.power ? 1 : 0;
  auto central = [&](double eps) {
    return (Measure(y + eps * t, index) - Measure(y - eps * t, index)) / (2.0 * eps);
  };
  constexpr double kEps = 1e-3;
  v.slope = (4.0 * central(0.5 * kEps) - central(kEps)) / 3.0;
  return v;
}

bool BranchTracer::HasUnitMultiplier(const Vec& y) {
  // A smooth fold's multiplier at 1, located to 1e-9 of a step in arclength: within 2.1e-10 of 1
  // at every fold of the a-branch at omega = 0.1, where the fixed-signature system's own folds
  // next to grazing points had none nearer than 0.92.
  constexpr double kUnitTolerance = 1e-6;
  const std::vector<std::complex<double>> mu =
      OrbitStability(model_, propagator_, OrbitAt(y)).multipliers;
  return std::any_of(mu.begin(), mu.end(), [](const std::complex<double>& z) {
    return std::abs(z - 1.0) <= kUnitTolerance;
  });
}

bool BranchTracer::PointAt(double sigma, Vec* y) {
  int iterations = 0;
  return Correct(y_ + sigma * t_, t_, y, &iterations);
}

bool BranchTracer::PointTowards(double a, double* sigma, Vec* y) {
  for (int k = 0; k < 8; ++k) {
    *sigma = 0.5 * (a + *sigma);
    if (propagator_.stopped()) return false;
    if (PointAt(*sigma, y)) return true;
  }
  return false;
}

bool BranchTracer::PointBetween(double sigma, double a, const Vec& y_a, double b, const Vec& y_b,
                                Vec* y) {
  int iterations = 0;
  const Vec y_pred = y_a + (sigma - a) / (b - a) * (y_b - y_a);
  // The branch between two of its points strays from their chord by O(curvature (b - a)^2):
  // farther than b - a, the corrector has found another solution (at a vanishing segment's root,
  // the degenerate family of zero-length solutions: a trial of the period-4 a-branch from
  // omega = 0.6, a = 0.2, 4e-9 of arclength from such a root, landed at a = 2.7e9).
  return Correct(y_pred, t_, y, &iterations) && (*y - y_pred).norm() <= b - a;
}

bool BranchTracer::Locate(double h, const Vec& y_h, double psi0, double psi1,
                          const std::function<double(const Vec&)>& psi, bool stationary,
                          Vec* y_root, double* bracket) {
  // Illinois: regula falsi that halves the stale end's value, superlinear and bracketing.
  double a = 0.0, fa = psi0, b = h, fb = psi1;
  Vec y_a = y_, y_b = y_h;
  *bracket = std::abs(y_h[m()] - y_[m()]);
  int side = 0;
  Vec y;
  bool have = false;
  for (int it = 0; it < 100; ++it) {
    if (propagator_.stopped()) return false;
    double sigma = (fb - fa) != 0.0 ? (a * fb - b * fa) / (fb - fa) : 0.5 * (a + b);
    if (!(sigma > a && sigma < b)) sigma = 0.5 * (a + b);
    if (!PointBetween(sigma, a, y_a, b, y_b, &y)) {
      sigma = 0.5 * (a + b);
      if (!PointBetween(sigma, a, y_a, b, y_b, &y)) {
        // Trial points next to a vanishing segment's root may not correct (at the root its two
        // events' rows coincide; docs/engine.md, "Why the branches stay dense"). With a point
        // already corrected, the bracket so far is the location; with none, points closer to the
        // admissible end are tried before the location is given up (where the first trial and
        // the midpoint failed, the omega-branch at a = 0.15 from omega = 0.1 FAILED with the
        // condensed solve or under rounding-level changes of the flows: "could not locate or
        // cross: segment 1 (NC) has duration -0.0119").
        if (have || !PointTowards(a, &sigma, &y)) return have;
      }
    }
    have = true;
    *y_root = y;
    const double f = psi(y);
    if (f == 0.0) {
      *bracket = 0.0;
      return true;
    }
    if (Sign(f) == Sign(fa)) {
      a = sigma, fa = f, y_a = y;
      if (side == -1) fb *= 0.5;
      side = -1;
    } else {
      b = sigma, fb = f, y_b = y;
      if (side == +1) fa *= 0.5;
      side = +1;
    }
    *bracket = std::abs(y_b[m()] - y_a[m()]);
    // Located: the parameter bracketed to locate_tolerance (or, where it is stationary, the
    // arclength to 1e-9 of the step) and the test function itself below kValueTolerance, so the
    // defining condition holds even where it varies fast (multipliers near a grazing).
    constexpr double kValueTolerance = 1e-10;
    const bool narrow = b - a <= 1e-14 * std::max(1.0, h);
    const bool bracketed =
        stationary ? b - a <= 1e-9 * std::max(1.0, h) : *bracket <= options_.locate_tolerance;
    if (narrow || (bracketed && std::abs(f) <= kValueTolerance)) return true;
  }
  return have;
}

void BranchTracer::AddSpecial(SpecialPointKind kind, const Vec& y, double bracket,
                              std::string detail, ContinuationResult* result) {
  SpecialPoint sp;
  sp.kind = kind;
  sp.point = MakePoint(y);
  sp.bracket = bracket;
  sp.detail = std::move(detail);
  if (propagator_.stopped()) return;  // computed after a stop: not kept
  NoteStop(kind);
  result->special_points.push_back(std::move(sp));
}

void BranchTracer::DetectSpecialPoints(double h, const Vec& y1, const TestValues& t1,
                                       ContinuationResult* result, bool before_grazing) {
  const TestValues& t0 = tests_;
  Vec y;
  double bracket = 0.0;
  auto tests_at = [&](const Vec& yy) {
    Vec t;
    double det = 0.0;
    // Where no tangent is evaluated (a flow stopped: Locate returns at its next poll; or failed),
    // the step's first one stands in, so that no test reads a sign change from it (an empty t
    // would be read out of bounds).
    if (!Tangent(yy, t_, &t, &det)) t = t_, det = t0.branch_point;
    return Tests(yy, t, det, MakePoint(yy));
  };
  const bool at_turn = ReportTurn(h, t1, result);
  if (!at_turn && Sign(t0.fold) != Sign(t1.fold)) {
    if (Locate(
            h, y1, t0.fold, t1.fold, [&](const Vec& yy) { return tests_at(yy).fold; }, true, &y,
            &bracket) &&
        (!before_grazing || HasUnitMultiplier(y))) {
      AddSpecial(SpecialPointKind::kFold, y, bracket, "", result);
    }
  }
  // The multipliers left out of the list (structural zeros, the constraint's unit multiplier)
  // contribute positive factors (1, 2), so the product's sign compares across a change of their
  // count: next to a grazing a multiplier passes the structural-zero threshold, and on the
  // a-branch at omega = 0.1 a step passing the period doubling at a = 0.2098364 ended where it had.
  if (Sign(t0.period_doubling) != Sign(t1.period_doubling)) {
    if (Locate(
            h, y1, t0.period_doubling, t1.period_doubling,
            [&](const Vec& yy) { return tests_at(yy).period_doubling; }, false, &y, &bracket)) {
      AddSpecial(SpecialPointKind::kPeriodDoubling, y, bracket, "", result);
    }
  }
  if (Sign(t0.neimark_sacker) != Sign(t1.neimark_sacker) && t0.nontrivial == t1.nontrivial &&
      t0.nontrivial >= 2 && (t0.complex_pair || t1.complex_pair)) {
    if (Locate(
            h, y1, t0.neimark_sacker, t1.neimark_sacker,
            [&](const Vec& yy) { return tests_at(yy).neimark_sacker; }, false, &y, &bracket) &&
        tests_at(y).complex_pair) {
      AddSpecial(SpecialPointKind::kNeimarkSacker, y, bracket, "", result);
    }
  }
  if (!at_turn && Sign(t0.branch_point) != Sign(t1.branch_point) && t0.branch_point != 0.0) {
    // det changes sign without passing zero continuously: locate on the sign alone.
    if (Locate(
            h, y1, t0.branch_point, t1.branch_point,
            [&](const Vec& yy) { return tests_at(yy).branch_point; }, false, &y, &bracket)) {
      AddSpecial(SpecialPointKind::kBranchPoint, y, bracket, "", result);
    }
  }
  if (options_.locate_measure_maxima && !at_turn && t0.power == t1.power && t0.slope > 0.0 &&
      t1.slope < 0.0) {
    if (Locate(
            h, y1, t0.slope, t1.slope, [&](const Vec& yy) { return tests_at(yy).slope; }, false, &y,
            &bracket)) {
      AddSpecial(t0.power ? SpecialPointKind::kPowerMax : SpecialPointKind::kRopMax, y, bracket, "",
                 result);
    }
  }
}

bool BranchTracer::ReportTurn(double h, const TestValues& t1, ContinuationResult* result) {
  const TestValues& t0 = tests_;
  Vec tip;
  if (!halves_meet_ || Sign(t0.branch_point) == Sign(t1.branch_point) || t0.branch_point == 0.0 ||
      !TipInStep(h, &tip)) {
    return false;
  }
  AddTurn(tip, Sign(t0.fold) != Sign(t1.fold), "", result);
  return true;
}

void BranchTracer::AddTurn(const Vec& tip, bool fold, const std::string& reached,
                           ContinuationResult* result) {
  const int half = start_signature_.periods / 2;
  const std::string detail = "the branch's turn: the orbit of " + std::to_string(half) +
                             (half == 1 ? " period" : " periods") +
                             " traversed twice, at its period doubling" + reached;
  if (fold) AddSpecial(SpecialPointKind::kFold, tip, 0.0, detail, result);
  const size_t before = result->special_points.size();
  AddSpecial(SpecialPointKind::kBranchPoint, tip, 0.0, detail, result);
  if (result->special_points.size() > before) turn_ = result->special_points.back().point;
}

bool BranchTracer::TurnAhead(ContinuationResult* result) {
  Vec tip;
  double sigma = 0.0;
  if (!halves_meet_ || !SolveTip(&tip, &sigma) || !(sigma > 0.0)) return false;
  const bool in_step = sigma < h_ && (tip - y_).norm() <= h_;
  if (!in_step && !OnlyTheTurnAhead(tip, sigma)) return false;
  if (!AdmissibilityViolations(model_, propagator_, OrbitAt(tip)).empty()) return false;
  AddTurn(tip, /*fold=*/true,
          in_step ? std::string()
                  : "; solved " + ShortNumber(sigma) +
                        " of arclength past the last corrected point, where steps stopped "
                        "correcting",
          result);
  return turn_.has_value();
}

bool BranchTracer::OnlyTheTurnAhead(const Vec& tip, double sigma) {
  // Quadratic to 25%: with a cubic term, p = p_tip - A s^2 + B s^3 in the arclength s to the
  // turn, the ratio is 1 + (B/A) s0 / 2 + O(s0^2) at s0 = sigma, and dp/dsigma vanishes before
  // the turn (a second fold) only where (B/A) s0 reaches 2/3, where the ratio has no bound.
  constexpr double kQuadraticTolerance = 0.25;
  const double ratio = (tip[m()] - y_[m()]) / (0.5 * t_[m()] * sigma);
  if (!(sigma <= options_.steps.max_step) || !(std::abs(ratio - 1.0) <= kQuadraticTolerance)) {
    return false;
  }
  const TestValues& t0 = tests_;
  const TestValues t1 = Tests(tip, t_, t0.branch_point, MakePoint(tip));
  const bool pair = t0.complex_pair || t1.complex_pair;
  return Sign(t0.period_doubling) == Sign(t1.period_doubling) &&
         (!pair || Sign(t0.neimark_sacker) == Sign(t1.neimark_sacker));
}

bool BranchTracer::SolveTip(Vec* tip, double* sigma) {
  const StatusOr<PeriodicOrbit> o =
      internal::PitchforkTip(model_, propagator_, OrbitAt(y_), param_);
  if (!o.ok() || !(o->signature == bvp_->signature())) return false;
  tip->resize(m() + 1);
  *tip << bvp_->Pack(*o), o->params[param_];
  *sigma = t_.dot(*tip - y_);
  return true;
}

bool BranchTracer::TipInStep(double h, Vec* tip) {
  double sigma = 0.0;
  return SolveTip(tip, &sigma) && sigma > 0.0 && sigma < h && (*tip - y_).norm() <= h;
}

void BranchTracer::LocateViolations(const std::vector<Admissibility>& violations, double h_end,
                                    const Vec& y_end, double before, GrazingCrossing* crossing) {
  for (const Admissibility& v : violations) {
    auto psi = [&](const Vec& yy) {
      return ViolationTestFunction(model_, propagator_, OrbitAt(yy), v);
    };
    const double psi0 = psi(y_), psi1 = psi(y_end);
    Vec y_v;
    double bracket = 0.0;
    if (!(psi0 > 0.0 && psi1 <= 0.0) ||
        !Locate(h_end, y_end, psi0, psi1, psi, true, &y_v, &bracket)) {
      continue;
    }
    const double sigma = t_.dot(y_v - y_);
    if (!(sigma < before)) continue;
    crossing->located.push_back({sigma, y_v[m()], v});
    if (sigma < crossing->sigma) {
      crossing->sigma = sigma;
      crossing->y = y_v;
      crossing->bracket = bracket;
      crossing->violation = v;
    }
  }
}

void BranchTracer::LocateHiddenGuardCrossing(const std::vector<Admissibility>& violations,
                                             GrazingCrossing* crossing) {
  // Where segments vanish, AdmissibilityViolations lists only those (they explain their
  // neighbours' crossings), so a guard crossing elsewhere reached earlier in the same step goes
  // unseen: a guard crossing at the point just before the earliest located vanishing is located
  // too, and crossed first where it lies clearly earlier (by 1e-3 of the arclength: one at the
  // vanishing itself belongs to that grazing, as where an impact's contact phase vanishes in one
  // copy of a twice-traversed orbit and the free flight of the other copy re-crosses Pi with it).
  // (The omega = 0.05 a-branch of the reference box: a touch inside a 72-long free flight
  // 1.2e-6 in a, 21% of the way, before the first segment vanished; crossing the vanishing first
  // left the touch already violated, and the branch failed.)
  // A crossing in the half of a neighbouring segment next to the vanishing one is that
  // vanishing's own (at the omega-branch's GRAZING_L1 at 0.50884, a = 0.3, the contact phase
  // before a vanishing progression phase touches l1 0.0076 before their common end). One in the
  // other half is not: the period-2 a-branch born at a = 0.298478 (omega = 0.1) touches Pi a
  // quarter of the way into its last free flight, 1.4e-3 in a before the flight after the section
  // vanishes; steps aiming at 4 iterations took both in one, and the branch failed at the next.
  const int k = static_cast<int>(bvp_->signature().segments.size());
  auto explained = [&](const Admissibility& h, const PeriodicOrbit& o) {
    const bool late = h.time > 0.5 * o.durations[h.segment];
    return std::any_of(violations.begin(), violations.end(), [&](const Admissibility& v) {
      if (v.guard >= 0) return false;
      const bool vanishing_next = v.segment == (h.segment + 1) % k;      // at h's end
      const bool vanishing_previous = h.segment == (v.segment + 1) % k;  // at h's start
      return v.segment == h.segment || (vanishing_next && late) || (vanishing_previous && !late);
    });
  };
  const double sigma_star = crossing->sigma;
  Vec y_pre;
  const double sigma_pre = sigma_star * (1.0 - 1e-6);
  if (sigma_pre > 0.0 && PointBetween(sigma_pre, 0.0, y_, sigma_star, crossing->y, &y_pre)) {
    const PeriodicOrbit o = OrbitAt(y_pre);
    std::vector<Admissibility> hidden;
    for (const Admissibility& v : AdmissibilityViolations(model_, propagator_, o)) {
      if (v.guard >= 0 && !explained(v, o)) hidden.push_back(v);
    }
    LocateViolations(hidden, sigma_pre, y_pre, sigma_star * (1.0 - 1e-3), crossing);
  }
}

ContinuationPoint BranchTracer::RefinedGrazingPoint(const ContinuationPoint& at_graze, int segment,
                                                    bool* solved_exactly) {
  // A vanishing segment: the bracket on its duration may close on the degenerate family of
  // zero-length solutions (tangent_grazing.h); the tangency system pins the grazing point.
  // From the located point, else from the last admissible one.
  const int i = segment;
  ContinuationPoint reported = at_graze;
  StatusOr<PeriodicOrbit> solved = Status(StatusCode::kNotFound, "");
  for (const PeriodicOrbit* from :
       {&at_graze.orbit, const_cast<const PeriodicOrbit*>(&point_.orbit)}) {
    const StatusOr<PeriodicOrbit> tangent = TangentForm(*from, i);
    if (!tangent.ok()) break;
    solved = SolveTangentGrazing(model_, propagator_, *tangent, param_);
    // Sound only with every segment of positive duration, next to the bracketed point (Newton
    // can also reach a touching point at a segment's very start).
    if (solved.ok() &&
        *std::min_element(solved->durations.begin(), solved->durations.end()) > 0.0 &&
        std::abs(solved->params[param_] - at_graze.value) <=
            1e-3 * (1.0 + std::abs(at_graze.value))) {
      break;
    }
    solved = Status(StatusCode::kNotFound, "no sound tangency solution");
  }
  *solved_exactly = solved.ok();
  if (solved.ok()) {
    // Back to the old signature, with segment i of zero length at the touching point.
    PeriodicOrbit old = *solved;
    old.signature.segments[i - 1].tangent = false;
    old.signature.segments.insert(old.signature.segments.begin() + i,
                                  at_graze.orbit.signature.segments[i]);
    old.starts.insert(old.starts.begin() + i, old.starts[i]);
    old.durations.insert(old.durations.begin() + i, 0.0);
    reported.value = old.params[param_];
    reported.orbit = old;
    reported.measures = OrbitMeasures(model_, propagator_, old, options_.point_measures);
    reported.stability = OrbitStability(model_, propagator_, old);
    reported.period = kTwoPi * old.signature.periods / model_.ForcingFrequency(old.params);
  }
  return reported;
}

std::optional<ContinuationPoint> BranchTracer::SideBeforeGrazing(
    const Vec& y_star, ContinuationResult* result, std::optional<TestValues>* tests_before) {
  // The old signature's branch just before the grazing point: the side before's stability, and
  // the end of the interval searched for special points. The monodromy at the grazing point
  // itself is degenerate (a zero-length segment, or a guard touching zero inside one) and in
  // general has neither side's multipliers: the period-2 a-branch at omega = 0.4644 has
  // |mu| = 1.67 just before its GRAZING_L1 at a = 0.2048239 and 2.02 just after, and 0.215 at it.
  // Next to a vanishing segment the rows of its two events nearly coincide and a point that
  // close may not correct (the period-2 and period-4 a-branches at omega = 0.07 from a = 0.5: at
  // 12 of their 121 grazing points): the first of 1e-6, 1e-5, .. 1e-2 of the arclength before
  // the grazing that corrects is the side before.
  const double sigma_star = t_.dot(y_star - y_);
  double sigma_before = sigma_star;
  Vec y_before;
  std::optional<ContinuationPoint> before_point;
  for (double back = 1e-6; back <= 1e-2 && !before_point; back *= 10.0) {
    sigma_before = sigma_star * (1.0 - back);
    if (PointBetween(sigma_before, 0.0, y_, sigma_star, y_star, &y_before)) {
      before_point = MakePoint(y_before);
    }
  }
  if (options_.locate && before_point.has_value()) {
    // Up to just before the grazing point.
    const double sigma = sigma_before;
    Vec t_before;
    double det_before = 0.0;
    if (Tangent(y_before, t_, &t_before, &det_before)) {
      TestValues before = Tests(y_before, t_before, det_before, *before_point);
      // The fixed-signature system degenerates at the grazing point (a fold of it, or a sign
      // change of its bordered determinant there): neither belongs to a physical orbit. A fold
      // of the old signature's orbits before the grazing point is reported (the a-branch at
      // omega = 0.1 turns at a = 0.1568849, 9.8e-7 before a grazing that a step of 0.48 from
      // before the turn overran), told from the system's own fold by its multiplier at 1.
      before.branch_point = tests_.branch_point;
      DetectSpecialPoints(sigma, y_before, before, result, /*before_grazing=*/true);
      *tests_before = before;
    }
  }
  return before_point;
}

std::vector<Admissibility> BranchTracer::CrossedTogether(const GrazingCrossing& crossing,
                                                         double h) const {
  // A period-n orbit that is a shorter one traversed several times (a period-2 branch beyond the
  // doubling it met again) reaches the same boundary in each copy at once: the violations of the
  // same kind (guard, at a start or not) located at this same point, to 1e-9 of the step or to
  // 1e-8 in the parameter, are switched together, from the last segment back so that each index
  // still holds, and every zero-length segment inserted is stepped off together below. Crossing
  // one at a time left the next already violated at the step-off point, with no bracket to
  // locate it in. The parameter matters where a segment vanishes: the branch is stationary in it
  // there, and the twin CwP phases of the xi = 0.5 period-2 omega-branch, vanishing at
  // omega = 0.698960961 and 0.698960967 (6e-9 apart), were located 1e-2 of a step apart.
  const Admissibility& violation = crossing.violation;
  const double value_star = crossing.y[m()];
  std::vector<Admissibility> together = {violation};
  for (const GrazingCrossing::Located& twin : crossing.located) {
    const Admissibility& w = twin.violation;
    if (w.segment != violation.segment && w.guard == violation.guard &&
        w.at_start == violation.at_start &&
        (std::abs(twin.sigma - crossing.sigma) <= 1e-9 * h ||
         std::abs(twin.value - value_star) <= 1e-8 * (1.0 + std::abs(value_star)))) {
      together.push_back(w);
    }
  }
  std::sort(together.begin(), together.end(),
            [](const Admissibility& x, const Admissibility& y) { return x.segment > y.segment; });
  return together;
}

SwitchedOrbit BranchTracer::SwitchTogether(const PeriodicOrbit& at_graze,
                                           const std::vector<Admissibility>& together,
                                           std::vector<int>* inserted) {
  SwitchedOrbit sw = SwitchSignature(model_, propagator_, at_graze, together.front());
  if (sw.new_segment >= 0) inserted->push_back(sw.new_segment);
  for (size_t l = 1; l < together.size() && !sw.representation_only; ++l) {
    SwitchedOrbit next = SwitchSignature(model_, propagator_, sw.orbit, together[l]);
    if (next.representation_only) break;
    // Each switch lies before the earlier ones: their segments move by what this one added.
    const int added = static_cast<int>(next.orbit.signature.segments.size()) -
                      static_cast<int>(sw.orbit.signature.segments.size());
    for (int& j : *inserted) j += added;
    if (next.new_segment >= 0) inserted->push_back(next.new_segment);
    next.detail = SignatureString(model_, at_graze.signature) + " -> " +
                  SignatureString(model_, next.orbit.signature);
    sw = std::move(next);
  }
  return sw;
}

BranchTracer::Vec BranchTracer::StepOffGrazing(const Vec& y, const Vec& fix,
                                               const std::vector<int>& inserted) {
  // A segment was inserted with zero duration: its duration grows like sqrt(|lambda -
  // lambda*|), so the new system folds exactly here. Step off the grazing point along that
  // duration: fix it at a small value, 1e-3 (lambda free), then go on where it grows.
  // Where the orbit has another short segment next to the touch, that step can overrun it
  // (the solution then has negative durations): it is retried 10 and 100 times shorter, and
  // the first with every duration positive is solved again below (once per switch); when none
  // is, the shortest. The period-2 a-branch of the reference box at a = 2.18218 is such a case:
  // the l1 touch lies 0.03 before the end of a CwoP phase that ends at l1 too, next to a CwP
  // phase of zero length, and the solved step-off cancels the inserted CwP phase with the CwoP
  // phase after it (-1e-3, -1e-4, -1e-5 at the three lengths). Stepped off at 1e-3 the next
  // step could not bracket that negative duration and the branch FAILED; at 1e-5 it goes on
  // and closes on itself with every point admissible. Why the insertion cancels is not
  // understood (a twin touch 6.4e-6 away in a was switched just before).
  auto step_off_guess = [&](double length) {
    Vec g = y;
    for (const int j : inserted) g[bvp_->DurationIndex(j)] = length;
    return g;
  };
  double graze_step = 1e-3;
  for (const double trial : internal::kStepOffLengths) {
    graze_step = trial;
    Vec y_off;
    int off_iterations = 0;
    if (!Correct(step_off_guess(trial), fix, &y_off, &off_iterations,
                 /*accept_rounding_residual=*/true)) {
      continue;
    }
    bool positive = true;
    for (int j = 0; j < bvp_->segments(); ++j) {
      positive = positive && y_off[bvp_->DurationIndex(j)] > 0.0;
    }
    if (positive) break;
  }
  return step_off_guess(graze_step);
}

bool BranchTracer::StartNewSignature(const SwitchedOrbit& sw, const std::vector<int>& inserted,
                                     double value, double* det) {
  const double direction = Sign(t_[m()]);
  bvp_ = std::make_unique<OrbitBvp>(model_, propagator_, sw.orbit.signature, param_);
  Vec y(m() + 1);
  y.head(m()) = bvp_->Pack(sw.orbit);
  y[m()] = value;
  Vec fix = Vec::Zero(m() + 1), prev = Vec::Zero(m() + 1);
  if (sw.new_segment < 0) {
    // A segment was removed: the new system is regular here (the touch is inside a segment).
    // Solve at the same parameter and keep the parameter direction of the last regular point (at
    // a vanishing segment the tangent at the grazing point is the fake fold's, with an arbitrary
    // parameter component).
    fix[m()] = 1.0;
    prev[m()] = direction;
  } else {
    const int col = bvp_->DurationIndex(sw.new_segment);
    fix[col] = 1.0;
    prev[col] = 1.0;
    y = StepOffGrazing(y, fix, inserted);
  }
  int iterations = 0;
  if (!Correct(y, fix, &y_, &iterations, /*accept_rounding_residual=*/true)) {
    if (sw.orbit.signature.segments.size() == 1) {
      // No event left: the motion beyond never impacts (NC|: no periodic orbit unless the mean
      // force vanishes) or never separates (pure contact, whose p - q offset no jump fixes: this
      // boundary-value formulation does not cover it yet). The branch ends here.
      Finish(Termination::kCompleted,
             "the branch ends at " + std::string(SpecialPointKindName(sw.kind)) + " " +
                 model_.param_names()[param_] + " = " + std::to_string(value) +
                 ": beyond it the orbit would be " + SignatureString(model_, sw.orbit.signature) +
                 ", a motion without events");
      return false;
    }
    Finish(Termination::kFailed, "could not solve the orbit of the new signature " +
                                     SignatureString(model_, sw.orbit.signature));
    return false;
  }
  if (!Tangent(y_, prev, &t_, det)) return false;
  if (sw.new_segment < 0) OrientNewBranch(det);
  return true;
}

void BranchTracer::OrientNewBranch(double* det) {
  // The new signature's branch may lie on either side of the grazing point (it turns back there
  // when the touch that removed the segment reappears at once past it). Flip the direction only
  // when a trial step along it lands on an inadmissible orbit and one against it does not.
  auto admissible_at = [&](double sigma) {
    Vec y_try;
    int trial_iterations = 0;
    if (!Correct(y_ + sigma * t_, t_, &y_try, &trial_iterations)) return false;
    return CheckAdmissible(model_, propagator_, OrbitAt(y_try)).admissible;
  };
  const double trial = std::max(options_.steps.min_step, std::min(h_, options_.steps.initial_step));
  if (!admissible_at(trial) && admissible_at(-trial)) {
    t_ = -t_;
    *det = -*det;
  }
}

bool BranchTracer::CrossGrazing(double h, const std::vector<Admissibility>& violations,
                                ContinuationResult* result) {
  // Locate each violation found at the step's end from the admissible side, and cross at the
  // earliest: several guards may reach a surface within one step (the impacts of a period-2n
  // orbit reaching the progression threshold at nearly the same parameter).
  // The parameter is stationary at a grazing point where a segment vanishes (the fixed-signature
  // branch folds back there, with b - b* ~ tau^2), so roots are bracketed in arclength.
  Vec y1;
  if (!PointAt(h, &y1)) return false;
  GrazingCrossing crossing;
  LocateViolations(violations, h, y1, std::numeric_limits<double>::infinity(), &crossing);
  if (!std::isfinite(crossing.sigma)) return false;
  if (crossing.violation.guard < 0) LocateHiddenGuardCrossing(violations, &crossing);
  // Special points of the old signature before the grazing point.
  const ContinuationPoint at_graze = MakePoint(crossing.y);
  // The point reported: for a vanishing segment, refined by the tangency system.
  bool solved_exactly = false;
  const ContinuationPoint reported =
      crossing.violation.guard < 0
          ? RefinedGrazingPoint(at_graze, crossing.violation.segment, &solved_exactly)
          : at_graze;
  // The side before ends at the solved point where the located one is off it (on the degenerate
  // family of zero-length solutions, which meets the branch at the grazing).
  Vec y_graze = crossing.y;
  if (solved_exactly && std::abs(reported.value - at_graze.value) > options_.locate_tolerance) {
    y_graze.head(m()) = bvp_->Pack(reported.orbit);
    y_graze[m()] = reported.value;
  }
  std::optional<TestValues> tests_before;
  const std::optional<ContinuationPoint> before_point =
      SideBeforeGrazing(y_graze, result, &tests_before);
  std::vector<int> inserted;  // the zero-length segments inserted, in sw.orbit
  const SwitchedOrbit sw = SwitchTogether(at_graze.orbit, CrossedTogether(crossing, h), &inserted);
  if (propagator_.stopped()) return false;  // nothing computed after a stop is kept
  // The grazing point is reported with the side before's multipliers, and stable only once both
  // sides are known stable (the side after is set below, when the new signature's branch starts).
  size_t sp_index = result->special_points.size(), pt_index = result->points.size();
  const bool recorded = !sw.representation_only;
  if (recorded) {
    SpecialPoint sp;
    sp.kind = sw.kind;
    sp.point = reported;
    sp.bracket = solved_exactly ? 0.0 : crossing.bracket;
    if (before_point.has_value()) {
      sp.before = SideOf(before_point->stability);
      sp.point.stability = before_point->stability;
    } else {
      sp.point.stability = Stability();
    }
    sp.point.stability.stable = false;
    sp.detail = sw.detail;
    result->special_points.push_back(sp);
    result->points.push_back(sp.point);
    NoteStop(sw.kind);
  }
  if (!options_.switch_signatures && !sw.representation_only) {
    Finish(Termination::kCompleted, "stopped at " + std::string(SpecialPointKindName(sw.kind)) +
                                        " (signature switching is off)");
    return false;
  }
  // Go on with the new signature from the same point.
  // Go on from the bracketed point (continuing from the refined one is not robust yet: it broke
  // the a = 5 branch).
  double det = 0.0;
  if (!StartNewSignature(sw, inserted, at_graze.value, &det)) return false;
  point_ = MakePoint(y_);
  tests_ = Tests(y_, t_, det, point_);
  h_ = std::max(options_.steps.min_step, std::min(h_, options_.steps.initial_step));
  if (recorded) {
    // The side after: the first point of the new signature's branch (at the grazing point where a
    // segment was removed, a step-off duration past it where one was inserted).
    SpecialPoint& sp = result->special_points[sp_index];
    sp.after = SideOf(point_.stability);
    sp.point.stability.stable = sp.before.known && sp.before.stable && sp.after.stable;
    result->points[pt_index].stability.stable = sp.point.stability.stable;
    if (tests_before.has_value() && crossing.violation.guard >= 0) {
      AddCornerMaximum(*tests_before, sp_index, result);
    }
  }
  return true;
}

void BranchTracer::AddCornerMaximum(const TestValues& before, size_t grazing,
                                    ContinuationResult* result) {
  // The slopes' error: Richardson truncation ~1e-12 and rounding ~1e-13 (Tests); a slope within
  // it has no established sign.
  constexpr double kSlopeError = 1e-11;
  if (!options_.locate || !options_.locate_measure_maxima || before.power != tests_.power ||
      !(before.slope > kSlopeError && tests_.slope < -kSlopeError)) {
    return;
  }
  SpecialPoint sp = result->special_points[grazing];
  const std::string measure = tests_.power ? "Pc" : "ROP";
  sp.detail = "at the " + std::string(SpecialPointKindName(sp.kind)) + ": " + measure +
              " rises into the grazing on the old signature (slope " + ShortNumber(before.slope) +
              " along the branch) and falls beyond it on the new one (" +
              ShortNumber(tests_.slope) + ")";
  sp.kind = tests_.power ? SpecialPointKind::kPowerMax : SpecialPointKind::kRopMax;
  sp.before = sp.after = SideStability();
  sp.near_grazing = NearGrazing();
  if (propagator_.stopped()) return;
  NoteStop(sp.kind);
  result->special_points.push_back(std::move(sp));
}

bool BranchTracer::CollapsedSegment(const Vec& y1) const {
  double period0 = 0.0, period1 = 0.0;
  for (int j = 0; j < bvp_->segments(); ++j) {
    period0 += std::abs(y_[bvp_->DurationIndex(j)]);
    period1 += std::abs(y1[bvp_->DurationIndex(j)]);
  }
  // Rounding level of a duration, and a length clearly above it (a segment inserted at a
  // switch starts at 1e-5 or more).
  constexpr double kRounding = 1e-12, kClear = 1e-9;
  for (int j = 0; j < bvp_->segments(); ++j) {
    if (std::abs(y1[bvp_->DurationIndex(j)]) <= kRounding * period1 &&
        y_[bvp_->DurationIndex(j)] > kClear * period0) {
      return true;
    }
  }
  return false;
}

void BranchTracer::NoteStop(SpecialPointKind kind) {
  if (!stop_kind_.empty()) return;
  const auto& stops = options_.stop_at;
  if (std::find(stops.begin(), stops.end(), kind) != stops.end()) {
    stop_kind_ = SpecialPointKindName(kind);
  } else if (kind == SpecialPointKind::kBranchPoint && halves_meet_) {
    const int periods = bvp_->signature().periods;
    const std::string half = std::to_string(periods / 2);
    stop_kind_ = std::string(SpecialPointKindName(kind)) + " (an orbit of " +
                 std::to_string(periods) + " periods meets one of " + half +
                 " traversed twice; beyond it the same orbits, shifted by " + half +
                 (periods == 2 ? " period)" : " periods)");
  }
}

void BranchTracer::Finish(Termination termination, std::string message) {
  termination_ = termination;
  message_ = std::move(message);
}

bool BranchTracer::Step(ContinuationResult* result) {
  if (propagator_.stopped()) {
    Finish(Termination::kCancelled, "cancelled");
    return false;
  }
  if (!stop_kind_.empty()) {
    Finish(Termination::kCompleted, "stopped at " + stop_kind_);
    return false;
  }
  if (steps_ >= options_.steps.max_steps) {
    Finish(Termination::kCompleted, "reached max_steps");
    return false;
  }
  // A stop seen anywhere in the step ends the branch CANCELLED before anything computed after it
  // is kept.
  auto cancelled = [&] {
    Finish(Termination::kCancelled, "cancelled");
    return false;
  };
  turn_.reset();
  while (true) {
    Vec y1;
    int iterations = 0;
    const bool corrected = Correct(y_ + h_ * t_, t_, &y1, &iterations);
    if (!corrected || CollapsedSegment(y1)) {
      if (propagator_.stopped()) return cancelled();
      if (TurnAhead(result)) {
        if (propagator_.stopped()) return cancelled();
        ++steps_;
        result->points.push_back(std::move(*turn_));
        return true;
      }
      if (propagator_.stopped()) return cancelled();
      ++rejected_;
      h_ *= 0.5;
      if (h_ < options_.steps.min_step) {
        // A branch that runs off to infinity as the parameter tends to a bound (the drifting
        // oscillator's period-1 orbit as b -> 0) stalls next to it: count that as reaching it.
        const double near = 1e-6 * (options_.max - options_.min);
        const double to_bound = t_[m()] < 0.0 ? y_[m()] - options_.min : options_.max - y_[m()];
        if (std::isfinite(near) && to_bound <= near) {
          Finish(Termination::kCompleted,
                 "approached " + model_.param_names()[param_] + " = " +
                     std::to_string(t_[m()] < 0.0 ? options_.min : options_.max) + " to " +
                     ShortNumber(to_bound) +
                     " (the corrector stalls next to the bound: the branch runs off or "
                     "degenerates there)");
          return false;
        }
        Finish(Termination::kFailed, "the corrector failed down to min_step at " +
                                         model_.param_names()[param_] + " = " +
                                         std::to_string(y_[m()]));
        return false;
      }
      continue;
    }
    const double h = h_;
    // Adapt the next step to the corrector's effort.
    h_ = std::clamp(h_ * StepFactor(iterations, options_.steps.target_iterations),
                    options_.steps.min_step, options_.steps.max_step);
    ++steps_;

    const double value = y1[m()];
    const double bound = value > options_.max ? options_.max : options_.min;
    const bool outside = value > options_.max || value < options_.min;
    ContinuationPoint p1 = MakePoint(y1);
    const std::vector<Admissibility> violations =
        AdmissibilityViolations(model_, propagator_, p1.orbit);
    const Admissibility adm = violations.empty() ? Admissibility{} : violations.front();
    if (propagator_.stopped()) return cancelled();
    if (!adm.admissible && !outside) {
      if (!CrossGrazing(h, violations, result)) {
        if (propagator_.stopped()) return cancelled();
        if (termination_ == Termination::kCompleted && message_.empty()) {
          // Next to the bound the branch heads for, a violation whose test function is at
          // rounding level at the step's end is the orbit degenerating at the bound, not a
          // grazing to cross: as b -> 0 the period-n orbits of the drifting oscillator become
          // free flights whose every maximum touches Pi (their heights differ by ~b T^2), so
          // their interior maxima reach Pi to 1e-13 at b ~ 1e-15.
          const double near = 1e-6 * (options_.max - options_.min);
          const double heading = Sign(t_[m()]);
          const double to_bound = heading < 0.0 ? y_[m()] - options_.min : options_.max - y_[m()];
          const double psi1 = ViolationTestFunction(model_, propagator_, p1.orbit, adm);
          constexpr double kRoundingLevel = 1e-9;
          if (std::isfinite(near) && to_bound <= near && std::abs(psi1) <= kRoundingLevel) {
            Finish(Termination::kCompleted,
                   "approached " + model_.param_names()[param_] + " = " +
                       std::to_string(heading < 0.0 ? options_.min : options_.max) + " to " +
                       ShortNumber(to_bound) + ", where the orbit degenerates: " + adm.message +
                       " (within " + ShortNumber(std::abs(psi1)) + " of touching)");
          } else {
            Finish(Termination::kFailed, "could not locate or cross: " + adm.message);
          }
        }
        return false;
      }
      return true;
    }
    if (outside) {
      // Land on the bound exactly (the parameter is monotone over one short step).
      Vec y_b;
      double bracket = 0.0;
      if (Locate(
              h, y1, y_[m()] - bound, value - bound, [&](const Vec& yy) { return yy[m()] - bound; },
              false, &y_b, &bracket)) {
        // The bracket stops at locate_tolerance in the parameter: solve once more with the
        // parameter fixed at the bound (the branch crosses it transversally here), so that the
        // point lies on the bound to rounding whatever the bracket's last iterate was.
        Vec e = Vec::Zero(m() + 1), y_pred = y_b, y_fixed;
        e[m()] = 1.0;
        y_pred[m()] = bound;
        int fixed_iterations = 0;
        if (Correct(y_pred, e, &y_fixed, &fixed_iterations, /*accept_rounding_residual=*/true)) {
          y_b = y_fixed;
        }
        ContinuationPoint at_bound = MakePoint(y_b);
        if (propagator_.stopped()) return cancelled();
        result->points.push_back(std::move(at_bound));
      }
      if (propagator_.stopped()) return cancelled();
      Finish(Termination::kCompleted,
             "reached " + model_.param_names()[param_] + " = " + std::to_string(bound));
      return false;
    }
    Vec t1;
    double det = 0.0;
    if (!TangentFromCorrector(&t1, &det)) {
      Finish(Termination::kFailed, "no tangent");
      return false;
    }
    const TestValues tests1 = Tests(y1, t1, det, p1);
    if (options_.locate) DetectSpecialPoints(h, y1, tests1, result);
    if (propagator_.stopped()) return cancelled();
    if (turn_) {
      // Beyond the turn run the same orbits, shifted: the branch ends there (NoteStop has set
      // its stop, which the next call reports).
      result->points.push_back(std::move(*turn_));
      return true;
    }
    // Back within one step of the start, in its signature, after going round: a closed branch
    // (an isola, or a period-2n branch that joins two period doublings of its parent). Going on
    // would retrace it until max_steps.
    constexpr int kMinLoopSteps = 10;
    if (steps_ > kMinLoopSteps && y1.size() == start_y_.size() &&
        p1.orbit.signature == start_signature_ && (y1 - start_y_).norm() < h) {
      result->points.push_back(std::move(p1));
      closed_ = true;
      Finish(Termination::kCompleted, "returned to its start (a closed branch)");
      return false;
    }
    y_ = y1;
    t_ = t1;
    point_ = std::move(p1);
    tests_ = tests1;
    result->points.push_back(point_);
    return true;
  }
}

}  // namespace drillbif::internal
