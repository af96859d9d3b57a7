// The extended system of a two-parameter curve (continuation/curve.h): the periodic orbit's
// shooting system G(X, lambda1, lambda2) = 0 (orbit/orbit_bvp.h) and the curve's defining
// condition, one row: sigma of the shifted monodromy for fold, period-doubling and
// Neimark-Sacker curves (bordered_sigma.h), h' at the tangent end (or a corner's duration) for
// grazing curves. Unknowns y = (X, lambda1, lambda2); the curve is {F(y) = 0}, corrected onto by
// the pseudo-arclength corrector (corrector.h) with the curve's settings, and read back as
// orbits and curve points.
#ifndef DRILLBIF_CONTINUATION_CURVE_SYSTEM_H_
#define DRILLBIF_CONTINUATION_CURVE_SYSTEM_H_

#include <Eigen/Dense>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "continuation/bordered_sigma.h"
#include "continuation/corrector.h"
#include "continuation/tangent_grazing.h"
#include "drillbif/continuation/curve.h"
#include "orbit/orbit_bvp.h"

namespace drillbif::internal {

// The extended system of one curve, in one signature.
class CurveSystem : public CorrectorSystem {
 public:
  using Vec = Eigen::VectorXd;
  using Mat = Eigen::MatrixXd;

  // The curve of `kind` in parameters index1, index2 through `start` (on it, or next to it:
  // CurveTracer::CorrectStart), in start's signature. `options` must outlive the system.
  CurveSystem(const HybridModel& model, Propagator& propagator, const CurveOptions& options,
              CurveKind kind, int index1, int index2, const PeriodicOrbit& start);

  // The unknowns y = (X, lambda1, lambda2) of an orbit of this signature.
  Vec Pack(const PeriodicOrbit& orbit) const;
  Params ParamsAt(const Vec& y) const;
  PeriodicOrbit Unpack(const Vec& y) const;

  int m() const { return bvp1_.size(); }  // X's size
  int n() const { return m() + 2; }       // y's size
  CurveKind kind() const { return kind_; }
  const CurveOptions& options() const { return options_; }
  const OrbitBvp& bvp() const { return bvp1_; }
  const HybridModel& model() const { return model_; }
  Propagator& propagator() const { return propagator_; }
  int index1() const { return index1_; }
  int index2() const { return index2_; }

  // CorrectorSystem: F(y) = (G, condition) and its Jacobian (n - 1 rows, n columns).
  bool EvaluateInto(const Vec& y, Vec* f, Eigen::Ref<Mat>* jac) const override;
  // Whether the propagator's throttle has seen a stop: nothing computed since is kept.
  bool Stopped() const override { return propagator_.stopped(); }
  int Segments() const override { return bvp1_.segments(); }
  int Block() const override { return m() / bvp1_.segments(); }

  // Renews the condition's borders (sigma's) from the monodromy of an accepted point.
  void SetBorders(const Mat& monodromy) const;

  // The defining condition: sigma(M -+ I) for folds and period doublings; for grazing, h' at the
  // tangent end (the guard's rate where it touches zero).
  double Condition(const Vec& y) const;
  // The same for an unpacked orbit; for fold / PD / NS curves its monodromy factors, and the
  // segments' flows they were made from, are kept in *factors / *flows when asked (the
  // condition's row of the Jacobian reuses them).
  double ConditionAt(const PeriodicOrbit& o, std::vector<StateMatrix>* factors = nullptr,
                     std::vector<FlowResult>* flows = nullptr) const;

  // Newton onto the curve from y_pred in the hyperplane through it normal to `dir`
  // (PseudoArclengthCorrector with the curve's settings: the contraction test, and with
  // settle_condition the condition's residual settled; curve_system.cc says why). `tangent`,
  // when given, receives the unit tangent there oriented along dir, at no further evaluation.
  bool Correct(const Vec& y_pred, const Vec& dir, Vec* y, int* iterations, Vec* tangent = nullptr,
               bool settle_condition = true) const;
  // A corrector with the curve's factorization mode, for the two below.
  PseudoArclengthCorrector NewCorrector() const;
  // Correct without settling the condition (settle_condition false), by *corrector, which keeps
  // the last factorization for ChordCorrect.
  bool CorrectKeeping(PseudoArclengthCorrector* corrector, const Vec& y_pred, const Vec& dir,
                      Vec* y) const;
  // Chord iterations on *corrector's last factorization, which must have been made with the same
  // `dir` (PseudoArclengthCorrector::CorrectChord, with Correct's settings).
  bool ChordCorrect(PseudoArclengthCorrector* corrector, const Vec& y_pred, const Vec& dir,
                    Vec* y) const;
  // The unit tangent at y oriented along `prev` (internal::UnitTangent), from a new evaluation.
  bool Tangent(const Vec& y, const Vec& prev, Vec* t) const;

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
                  Admissibility* violation = nullptr) const;

  // The curve point of y (its orbit's measures and stability).
  CurvePoint MakePoint(const Vec& y) const;
  // `stability` given: that one (an extrapolated end's), else the orbit's own.
  CurvePoint PointFromOrbit(PeriodicOrbit orbit, const Stability* stability = nullptr) const;

  // The parameter part of the unit tangent, in the box's scaled coordinates.
  Eigen::Vector2d ParamDirection(const Vec& t) const { return {t[m()] / w1_, t[m() + 1] / w2_}; }
  // How far the chord from y to y1 (a step of arclength h, unit tangents t and t1) strays from
  // the curve in the parameter plane, box-scaled: the largest distance from the chord of the
  // cubic that has the parameters and their derivatives h ParamDirection(t), h ParamDirection(t1)
  // at the ends (the curve itself to O(h^4)), sampled at a quarter, half and three quarters.
  double ChordSagitta(const Vec& y, const Vec& t, const Vec& y1, const Vec& t1, double h) const;
  // Distance of two curve points' parameters, scaled by the box's widths.
  double BoxDistance(const CurvePoint& a, const CurvePoint& b) const {
    return std::hypot((a.value1 - b.value1) / w1_, (a.value2 - b.value2) / w2_);
  }
  // The box's widths where finite: parameter scales.
  double w1() const { return w1_; }
  double w2() const { return w2_; }

 private:
  // The corrector's settings for Correct.
  CorrectorOptions CorrectSettings(bool settle_condition) const;

  // sigma of the shifted monodromy (without its phase).
  double Sigma(const Eigen::Ref<const Mat>& monodromy) const;
  // The condition's row of the Jacobian (forward differences).
  void SigmaRow(const Vec& y, const PeriodicOrbit& o, const std::vector<StateMatrix>& base,
                const std::vector<FlowResult>& flows, double sigma0, Eigen::Ref<Mat>* jac) const;

  const HybridModel& model_;
  Propagator& propagator_;
  const CurveOptions& options_;
  CurveKind kind_;
  int index1_, index2_;
  Params base_;
  double w1_ = 1.0, w2_ = 1.0;   // the box's widths where finite: parameter scales
  OrbitBvp bvp1_;                // derivatives in both parameters
  mutable BorderedSigma sigma_;  // SetBorders
  // A grazing curve of a corner (internal::CornerSegment): the segment held at zero length, its
  // duration the curve's condition; -1 for a grazing curve of a touch (a tangent end).
  int corner_ = -1;
  // A grazing curve of a touch: its first tangent segment, whose end's rate is the condition (-1:
  // none, or not a grazing curve).
  int tangent_ = -1;
  // Evaluate's workspace (G and its derivatives, the unpacked orbit, the segments' flows and
  // monodromy factors), kept between calls: a system is used by one thread (its propagator's).
  mutable Vec g_, gp1_, gp2_;
  mutable PeriodicOrbit orbit_;
  mutable std::vector<FlowResult> flows_;
  mutable std::vector<StateMatrix> factors_;
  // The condition's row's workspace (SigmaRow, the grazing row, Condition), kept likewise: y with
  // one entry moved, its orbit and factors, sigma's gradient, MonodromyGradientRow's scratch.
  mutable Vec moved_y_;
  mutable PeriodicOrbit moved_orbit_;
  mutable std::vector<StateMatrix> moved_factors_;
  mutable Mat gradient_;
  mutable MonodromyRowScratch row_scratch_;
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_CURVE_SYSTEM_H_
