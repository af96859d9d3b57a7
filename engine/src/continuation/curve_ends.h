// Where a two-parameter curve (continuation/curve.h) ends: where its orbit stops being
// admissible (the boundary bisected on the curve, then solved as the codimension-2 point it is,
// grazing_end.h), where it meets the Poincare section (the orbit goes on in a rotated signature),
// and where it leaves the box; and the requested parameter values crossed on a step.
#ifndef DRILLBIF_CONTINUATION_CURVE_ENDS_H_
#define DRILLBIF_CONTINUATION_CURVE_ENDS_H_

#include <Eigen/Dense>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "continuation/curve_codim2.h"
#include "continuation/curve_system.h"
#include "drillbif/continuation/curve.h"

namespace drillbif::internal {

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

// Where one traced direction's results go.
struct CurveOutputs {
  std::vector<CurvePoint>* points;       // the curve's points, in order
  std::vector<CurvePoint>* crossings;    // requested lambda1 / lambda2 values crossed
  std::vector<Codim2Point>* codim2;      // codimension-2 points
  std::vector<Codim2Point>* unverified;  // ends only a prediction brackets (CurveResult)
  SectionCrossing* crossing;             // filled where the direction meets the section
};

// How a curve's message names an unverified end (CurveResult::unverified_ends) `end`, whose
// prediction beyond was inadmissible for `why`: "next to (param1, param2) = (.., ..), where
// ...: no FOLD_GRAZING point claimed".
std::string UnverifiedEndText(const CurveOptions& options, const Codim2Point& end,
                              const std::string& why);

// A curve's ends, on its system.
class CurveEnds {
 public:
  using Vec = Eigen::VectorXd;
  using Mat = Eigen::MatrixXd;

  // `system` and `codim2` must outlive this.
  CurveEnds(const CurveSystem& system, const CurveCodim2& codim2)
      : system_(system), codim2_(codim2) {}

  // A point of the curve (its unknowns) known to lie on its admissibility boundary: the
  // codimension-2 point a switched curve was stepped off, where its segment `vanishing` is of
  // zero length, or (`vanishing` -1) the point it starts at (ContinueCurveFromRoot). A bisection
  // whose bracket holds the point tries points next to it first (TryKnownEnd).
  void SetKnownEnd(const Vec& y, int vanishing) { known_end_ = y, known_vanishing_ = vanishing; }

  // How a direction that saw a stop ends (nothing computed after the stop is kept).
  static constexpr const char* kCancelledEnd = "cancelled";

  // A step is refused (and retried shorter, as when Newton fails) when the corrected point lies
  // farther than kMaxDrift times the step from the prediction: along a smooth curve of curvature
  // kappa the distance is about kappa h^2 / 2, so beyond h / 4 the tangent turns by ~0.5 rad
  // within the step, or the corrector has landed on another branch of solutions. With
  // target_iterations 4 a step of 0.86 on the PD curve from the flip-grazing at
  // (omega, a) = (0.35, 0.2446) landed 0.44 h away, with the CwoP phase that vanishes at
  // a = 0.17943 (the flip-grazing the default steps find) 0.81 long instead of crossing zero, and
  // the curve went on to another flip-grazing 1e-2 further.
  static constexpr double kMaxDrift = 0.25;

  // The curve's end on the step from y (tangent t) towards yb, where the orbit is not admissible
  // (`why`, `violation`): a codimension-2 point appended to out.codim2, or a Poincare-section
  // crossing (*out.crossing filled, the end appended to out.points). Roots of the test functions
  // on the way are appended too, and the requested crossings before the end (out.crossings).
  // Returns how the direction ended. `from_prediction`: yb is a prediction (not corrected); an
  // end only that prediction brackets goes to out.unverified instead (curve_ends.cc).
  std::string EndAtBoundary(const Vec& y, const Vec& t, const Vec& yb, const std::string& why,
                            const Admissibility& violation,
                            const std::vector<Codim2TestFunction>& tests, std::vector<double>* dets,
                            const CurveOutputs& out, bool from_prediction) const;

  // The step y -> y1 left the box: the point where it crosses the edge it meets first is solved
  // with that parameter fixed at the bound and appended, so that a curve ends on the box (the
  // stability region's polygons need its crossing there). Skipped when the corrector fails or
  // the orbit there is not admissible.
  void EndOnBox(const Vec& y, const Vec& y1, std::vector<CurvePoint>* points) const;

  // The requested lambda1 / lambda2 values crossed on the step y -> y1, each solved with that
  // parameter fixed and appended to *crossings.
  void CrossingsOnStep(const Vec& y, const Vec& y1, std::vector<CurvePoint>* crossings) const;

 private:
  struct Boundary;
  // Where a bisection's midpoint corrects to.
  enum class Side { kUncorrected, kAdmissible, kBeyond };

  bool IsSectionCrossing(const Admissibility& v, const PeriodicOrbit& end) const;
  bool MayBeSectionCrossing(const Admissibility& v) const;
  void Bisect(const Vec& t, double tol, Boundary* b) const;
  void TryKnownEnd(const Vec& t, double tol, Boundary* b,
                   const std::function<void(const Vec&)>& trial) const;
  // Trial points before a known end (TryKnownEnd): 0.25, 2, 16, 128, 1024 tolerances.
  static constexpr int kKnownEndTrials = 5;
  Side CorrectMidpoint(PseudoArclengthCorrector* corrector, const Vec& t, const Vec& mid,
                       const Admissibility& seen, Vec* yc, std::string* why,
                       Admissibility* violation) const;
  bool SolveEnd(Codim2Point* end) const;
  bool AcceptEnd(const Codim2Point& end, const StatusOr<PeriodicOrbit>& solved, int vanishing,
                 int zero_length, int touch_start, const Stability* stability,
                 CurvePoint* point) const;
  double ReachToVanishing(const PeriodicOrbit& o, int j) const;
  bool OnCondition(const CurvePoint& point) const;
  CurvePoint SettledVertex(const Vec& ya, const Vec& t, CurvePoint end) const;
  void CuspBeforeEnd(const Vec& y, const Vec& t, const Vec& ya,
                     std::vector<Codim2Point>* codim2) const;

  const CurveSystem& system_;
  const CurveCodim2& codim2_;
  std::optional<Vec> known_end_;
  int known_vanishing_ = -1;
};

// ContinueCurve from `start`, stepped off the codimension-2 point `root` (an orbit of start's
// signature whose segment `vanishing` is of zero length), or started at it (`vanishing` -1,
// `root` the start's orbit): the curve's end there is bracketed from points next to the root
// before the whole step is bisected (CurveEnds::SetKnownEnd).
CurveResult ContinueCurveFromRoot(const HybridModel& model, Propagator& propagator,
                                  const SpecialPoint& start, const PeriodicOrbit& root,
                                  int vanishing, const CurveOptions& options);

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_CURVE_ENDS_H_
