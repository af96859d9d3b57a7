// Codimension-2 points on a step of a two-parameter curve (continuation/curve.h): sign changes
// of test functions of the monodromy (FOLD_FLIP, FOLD_GRAZING and FLIP_GRAZING along grazing
// curves, the strong resonances along Neimark-Sacker curves) and cusps of fold curves (the
// curve's direction in the parameter plane reversing), each located by Illinois on the step's
// arclength with every trial point corrected onto the curve.
#ifndef DRILLBIF_CONTINUATION_CURVE_CODIM2_H_
#define DRILLBIF_CONTINUATION_CURVE_CODIM2_H_

#include <Eigen/Dense>
#include <functional>
#include <vector>

#include "continuation/curve_system.h"
#include "drillbif/continuation/curve.h"

namespace drillbif::internal {

// A codimension-2 test function of the monodromy and the point it marks where it changes sign.
struct Codim2TestFunction {
  std::function<double(const Eigen::MatrixXd&)> f;
  Codim2Kind kind;
};

// Locates a curve's codimension-2 points on its steps.
class CurveCodim2 {
 public:
  using Vec = Eigen::VectorXd;
  using Mat = Eigen::MatrixXd;

  // `system` must outlive this.
  explicit CurveCodim2(const CurveSystem& system) : system_(system) {}

  // The codimension-2 test functions this curve carries.
  std::vector<Codim2TestFunction> Tests() const;
  // A test function's value at the curve point y.
  double TestValue(const Codim2TestFunction& test, const Vec& y) const;
  // Whether every codimension-2 test function has the same sign at two monodromies.
  static bool SameSigns(const std::vector<Codim2TestFunction>& tests, const Mat& a, const Mat& b);

  // Codimension-2 points on the step from y (tangent t) to y1 (monodromy mono1): sign changes
  // of the test functions from their values at y (*dets, updated to those at y1), located and
  // appended.
  void RootsOnStep(const Vec& y, const Vec& t, const Vec& y1, const Mat& mono1,
                   const std::vector<Codim2TestFunction>& tests, std::vector<double>* dets,
                   std::vector<Codim2Point>* codim2) const;

  // A fold curve whose direction in the parameter plane reverses on the step from y (tangent t)
  // to y1 (tangent t1): a cusp, located (to |psi| <= tol |u|, LocateCusp) and appended. With
  // `probes`, that many points inside the step, at 1/2, 3/4, 7/8, ... of it (closing in on y1:
  // the step that ends a curve, see CurveEnds::EndAtBoundary, where a cusp lies in a hook just
  // before the end and the direction stays reversed from it to the end), are looked at first,
  // and the first of them past a reversal ends the search interval instead of y1.
  void CuspOnStep(const Vec& y, const Vec& t, const Vec& y1, const Vec& t1,
                  std::vector<Codim2Point>* codim2, double tol = 1e-10, int probes = 0) const;

 private:
  // A function of a corrected curve point p and the unit tangent there (along the step's t, from
  // p's correction; empty unless asked for); false where it cannot be evaluated.
  using Value = std::function<bool(const Vec& p, const Vec& tangent, double* f)>;
  // The root on the step from y along t of length h of a function of the curve point (values f0,
  // f1 at the step's ends): Illinois on the arclength, each trial point corrected onto the curve,
  // until |value| <= tol or the bracket is below 1e-14 of the step. `value` returns false where
  // it cannot be evaluated (the root is then not located). `y_end`, when given, is the corrected
  // point at h (trial points are then predicted between corrected ones); `tangents`: `value` is
  // given the tangent at each trial point.
  bool LocateOnStep(const Vec& y, const Vec& t, double h, double f0, double f1, double tol,
                    const Value& value, Vec* root, const Vec* y_end = nullptr,
                    bool tangents = false) const;
  // The root of a codimension-2 test function on the step (values d0, d1 at its ends), to
  // |value| <= 1e-10.
  bool LocateCodim2(const Vec& y, const Vec& t, double h, const Codim2TestFunction& test, double d0,
                    double d1, Vec* root) const;
  // A cusp on the step from y (tangent t) of length h to the curve point y1, where the tangent's
  // parameter part turns against its direction u at y: the root of psi = u . (parameter part of
  // the tangent at the corrected point), psi1 at y1, to |psi| <= tol |u| (tol 0: until the sign
  // change is bracketed to rounding).
  bool LocateCusp(const Vec& y, const Vec& t, const Vec& y1, double h, double psi1, double tol,
                  Vec* root) const;

  const CurveSystem& system_;
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_CURVE_CODIM2_H_
