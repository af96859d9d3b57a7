#include "continuation/curve_codim2.h"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <cmath>
#include <complex>
#include <limits>
#include <utility>

namespace drillbif::internal {
namespace {

using Vec = Eigen::VectorXd;
using Mat = Eigen::MatrixXd;

// det(M - I) (shift -1) or det(M + I) (shift +1).
double ShiftedDet(const Mat& mono, double shift) {
  return (mono + shift * Mat::Identity(mono.rows(), mono.cols())).determinant();
}

// On a Neimark-Sacker curve, kappa = Re(mu1 + mu2) / 2 of the critical pair (the two multipliers
// whose product is nearest 1; on the curve a complex pair on the unit circle, kappa = cos theta):
// kappa = 1, -1, -1/2, 0 at the strong resonances 1:1, 1:2, 1:3, 1:4 (Kuznetsov 2004,
// sec. 9.5). Beyond a 1:1 or 1:2 point the pair is real with product 1 and kappa passes +-1.
double Kappa(const Mat& mono) {
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

// The distance of the nontrivial multiplier nearest 1 from it.
double NearestToOne(const Stability& stability) {
  double nearest = std::numeric_limits<double>::infinity();
  for (const std::complex<double>& mu : stability.multipliers) {
    nearest = std::min(nearest, std::abs(mu - 1.0));
  }
  return nearest;
}

// The farthest a fold curve's point resolved as one has its multiplier from 1, for a cusp. Next
// to a segment vanishing between two of one mode the saltations grow like 1 / tau, and the
// condition sigma(M - I), settled to its rounding floor there, holds points whose multiplier is
// up to 5e-5 off 1 (CurveSystem::Correct): within that band the curve's tangent in the parameter
// plane is noise, and it reversed on the first step of a fold curve started 1e-6 off its
// fold-grazing root (a "cusp" with its multiplier 1.5e-5 off 1 with dense solves, 8.5e-6 with
// condensed ones; the first 3e-10 from the root, dropped as the curve's end, the second 8e-9).
// Every other cusp located in the reference box has it within 2.4e-10 of 1; 1e-8 is the bound
// past which the corrector calls a vertex's condition unsettled.
constexpr double kResolvedFold = 1e-8;

}  // namespace

std::vector<Codim2TestFunction> CurveCodim2::Tests() const {
  auto det = [](double shift) { return [shift](const Mat& m) { return ShiftedDet(m, shift); }; };
  auto kappa = [](double at) { return [at](const Mat& m) { return Kappa(m) - at; }; };
  switch (system_.kind()) {
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

double CurveCodim2::TestValue(const Codim2TestFunction& test, const Vec& y) const {
  return test.f(OrbitStability(system_.model(), system_.propagator(), system_.Unpack(y)).monodromy);
}

bool CurveCodim2::SameSigns(const std::vector<Codim2TestFunction>& tests, const Mat& a,
                            const Mat& b) {
  return std::all_of(tests.begin(), tests.end(), [&](const Codim2TestFunction& test) {
    return (test.f(a) > 0.0) == (test.f(b) > 0.0);
  });
}

// With y_end, a trial is predicted on the chord between the corrected points that bracket it
// (both in their hyperplanes normal to t, so the chord's point at sigma is in sigma's): as the
// bracket closes in, that chord's distance from the curve shrinks with the bracket's square,
// where y + sigma t's stays the whole step's, and the corrections take fewer Newton iterations.
bool CurveCodim2::LocateOnStep(const Vec& y, const Vec& t, double h, double f0, double f1,
                               double tol, const Value& value, Vec* root, const Vec* y_end,
                               bool tangents) const {
  double a = 0.0, fa = f0, b = h, fb = f1;
  Vec ya = y, yb = y_end != nullptr ? *y_end : Vec();
  int side = 0;
  for (int it = 0; it < 100; ++it) {
    if (system_.Stopped()) return false;
    double sigma = (fb - fa) != 0.0 ? (a * fb - b * fa) / (fb - fa) : 0.5 * (a + b);
    if (!(sigma > a && sigma < b)) sigma = 0.5 * (a + b);
    const Vec prediction =
        y_end != nullptr ? Vec(ya + (sigma - a) / (b - a) * (yb - ya)) : Vec(y + sigma * t);
    int iterations = 0;
    Vec tangent;
    double f = 0.0;
    if (!system_.Correct(prediction, t, root, &iterations, tangents ? &tangent : nullptr) ||
        !value(*root, tangent, &f)) {
      return false;
    }
    if (std::abs(f) <= tol || b - a <= 1e-14 * std::max(1.0, h)) return true;
    if ((f > 0.0) == (fa > 0.0)) {
      a = sigma, fa = f, ya = *root;
      if (side == -1) fb *= 0.5;
      side = -1;
    } else {
      b = sigma, fb = f, yb = *root;
      if (side == +1) fa *= 0.5;
      side = +1;
    }
  }
  return false;
}

bool CurveCodim2::LocateCodim2(const Vec& y, const Vec& t, double h, const Codim2TestFunction& test,
                               double d0, double d1, Vec* root) const {
  return LocateOnStep(
      y, t, h, d0, d1, 1e-10,
      [&](const Vec& p, const Vec&, double* f) {
        *f = TestValue(test, p);
        return true;
      },
      root);
}

void CurveCodim2::RootsOnStep(const Vec& y, const Vec& t, const Vec& y1, const Mat& mono1,
                              const std::vector<Codim2TestFunction>& tests,
                              std::vector<double>* dets, std::vector<Codim2Point>* codim2) const {
  for (size_t k = 0; k < tests.size(); ++k) {
    const double d1 = tests[k].f(mono1);
    Vec root;
    if (((*dets)[k] > 0.0) != (d1 > 0.0) &&
        LocateCodim2(y, t, t.dot(y1 - y), tests[k], (*dets)[k], d1, &root)) {
      CurvePoint point = system_.MakePoint(root);
      if (!system_.Stopped()) codim2->push_back({tests[k].kind, std::move(point), "", 0.0, {}});
    }
    (*dets)[k] = d1;
  }
}

bool CurveCodim2::LocateCusp(const Vec& y, const Vec& t, const Vec& y1, double h, double psi1,
                             double tol, Vec* root) const {
  const Eigen::Vector2d u = system_.ParamDirection(t);
  return LocateOnStep(
      y, t, h, u.squaredNorm(), psi1, tol * u.norm(),
      [&](const Vec&, const Vec& tangent, double* f) {
        *f = u.dot(system_.ParamDirection(tangent));
        return true;
      },
      root, &y1, true);
}

void CurveCodim2::CuspOnStep(const Vec& y, const Vec& t, const Vec& y1, const Vec& t1,
                             std::vector<Codim2Point>* codim2, double tol, int probes) const {
  if (system_.kind() != CurveKind::kFold) return;
  const double h = t.dot(y1 - y);
  Vec y_reach = y1;
  double reach = h, psi_reach = system_.ParamDirection(t).dot(system_.ParamDirection(t1));
  // A probe is predicted on the chord from y to y1 (in its hyperplane normal to t, as y + s t):
  // the probes close in on y1, where the chord's distance from the curve goes to zero and
  // y + s t's is the whole step's. Its tangent is its corrector's, from the last factorization
  // (Correct), rather than a new evaluation's (Tangent: a Jacobian evaluated and factorized
  // again).
  for (int k = 1; k <= probes; ++k) {
    const double s = h * (1.0 - std::ldexp(1.0, -k));
    Vec p, tp;
    int iterations = 0;
    if (!system_.Correct(y + (s / h) * (y1 - y), t, &p, &iterations, &tp)) continue;
    const double psi = system_.ParamDirection(t).dot(system_.ParamDirection(tp));
    if (psi < 0.0) {
      reach = s, psi_reach = psi, y_reach = p;
      break;
    }
  }
  Vec root, tr;
  if (!(psi_reach < 0.0 && LocateCusp(y, t, y_reach, reach, psi_reach, tol, &root))) return;
  // A cusp, not a turn: psi = 0 also where the direction has turned through a right angle
  // within the step (a hairpin, |parameter part| ~ |u| there); at a cusp the parameter part
  // itself vanishes (measured at the box's cusps: at most 2.5e-4 |u|, against 0.07 |u| at the
  // one hairpin seen, with target_iterations 4). And not one already found on this curve (a
  // curve passing a cusp twice, or the search reaching it from two steps).
  if (!system_.Tangent(root, t, &tr) ||
      system_.ParamDirection(tr).norm() > 1e-2 * system_.ParamDirection(t).norm()) {
    return;
  }
  // And on the fold curve: a located point whose multiplier is not 1 lies in the band where the
  // condition sits at its rounding floor, not on the curve, and its direction is that band's
  // noise (NearestToOne).
  CurvePoint point = system_.MakePoint(root);
  if (NearestToOne(point.stability) > kResolvedFold) return;
  for (const Codim2Point& q : *codim2) {
    if (q.kind == Codim2Kind::kCusp && system_.BoxDistance(q.point, point) <= 1e-9) {
      return;
    }
  }
  if (!system_.Stopped()) codim2->push_back({Codim2Kind::kCusp, std::move(point), "", 0.0, {}});
}

}  // namespace drillbif::internal
