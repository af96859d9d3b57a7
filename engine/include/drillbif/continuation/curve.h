// Two-parameter continuation of bifurcation curves by extended systems: from a fold, period
// doubling or grazing point located by a one-parameter continuation, follow the curve of such
// points in two parameters (lambda1, lambda2).
//
// Unknowns Y = (X, lambda1, lambda2), X the orbit's boundary-value unknowns
// (orbit/periodic_orbit.h); equations G(X; lambda) = 0 plus one defining condition:
//   fold:              sigma(M - I) = 0
//   period doubling:   sigma(M + I) = 0
//   Neimark-Sacker:    sigma(M (.) M - I) = 0, M (.) M the bialternate square of M (eigenvalues
//                      mu_i mu_j, i < j): a complex pair on the unit circle has mu mu-bar = 1
//                      (also a real pair with mu_i mu_j = 1, a neutral saddle; Kuznetsov,
//                      "Elements of Applied Bifurcation Theory", 2004, sec. 10.3)
// where M is the monodromy (state without phase) and sigma(A) the last component of the solution
// of the bordered system [[A, b], [c^T, 0]] (v, sigma) = (0, 1), with b and c the singular vectors
// of A's smallest singular value at the last accepted point (Govaerts, "Numerical Methods for
// Bifurcations of Dynamical Equilibria", SIAM 2000): sigma is smooth and vanishes exactly where A
// is singular; the borders are renewed at every point so that the bordered matrix stays regular.
// Its derivatives are taken by central differences (each needs a monodromy); the rest of the
// Jacobian is exact. Pseudo-arclength with the same step control as the one-parameter continuation.
//
//   grazing:           h'(x_touch) = 0 at the touching point, which becomes a tangent segment end
//                      (SegmentSpec::tangent: h = 0 there, then the same mode goes on)
// Grazing curves start from grazings where a segment vanishes between two segments of the same
// mode (l1: the CwP phase between two contact phases; Pi: a contact phase between free flights);
// the vanishing segment is dropped and the one before it ends tangentially. From the other side
// (no segment vanishes: a free flight touches Pi and turns back) the segment where a guard
// touches zero is split there, its first part ending tangentially.
// A curve is traced while its orbits stay admissible; it ends where one is not (a codimension-2
// point, see Codim2Point), at the box bounds, where it stalls, or after max_steps.
#ifndef DRILLBIF_CONTINUATION_CURVE_H_
#define DRILLBIF_CONTINUATION_CURVE_H_

#include <limits>
#include <string>
#include <vector>

#include "drillbif/common/parameter_box.h"
#include "drillbif/continuation/continuation.h"

namespace drillbif {

enum class CurveKind { kFold, kPeriodDoubling, kGrazing, kNeimarkSacker };
const char* CurveKindName(CurveKind kind);

// The box (ParameterBox): param1 is the parameter of the one-parameter continuation that found
// the point, param2 the second; the curve stops at the box's edges (none unless set).
struct CurveOptions : ParameterBox {
  // Values of lambda2 where the curve's crossing points are solved exactly (Newton with lambda2
  // fixed, from the interpolation between the two points around it), e.g. to compare with a
  // one-parameter continuation at that value.
  std::vector<double> crossings2;
  std::vector<double> crossings1;  // likewise for lambda1
  // Shorter steps than a branch's: a first step of 0.02, 1e-8 to 1.0, a tolerance of 1e-10.
  // max_steps: curves of long orbits are long in the unknowns (at omega ~ 0.1 a period-2 orbit's
  // drift coordinate moves ~6000 times as far as omega along its PD curve): in the reference
  // (omega, a) box (omega in [0.05, 2], a in [0.01, 8] at b = 0.15) with period 2, 12 of the
  // period-2 curves of omega in [0.09, 0.11] stopped at 2000.
  // target_iterations 4: the corrector's contraction test stops almost every step at 3
  // iterations, and the step grows only below the target, so with 3 it almost never grew; with
  // 4 the reference box's trace has a fifth of the vertices and finds the same codimension-2
  // points and crossings. Condensed solves (condensed_solve true, docs/engine.md): with these
  // steps, and with target_iterations 3, that box's trace finds the same network as with dense
  // ones (bench/compare_networks.py) in ~13% less CPU.
  StepControl steps{0.02, 1e-8, 1.0, 4, 8, 10000, 1e-10, true};

  Status Validate() const;
};

struct CurvePoint {
  double value1 = 0.0, value2 = 0.0;  // (lambda1, lambda2)
  PeriodicOrbit orbit;
  std::vector<double> measures;  // ROP, and Pc left 0 (not computed: no consumer asks for it)
  Stability stability;
};

// Codimension-2 points found along a curve by the sign of det(M - I) (fold) and det(M + I)
// (period doubling), located by a safeguarded secant along the curve until |det| <= 1e-10:
// on a grazing curve FOLD_GRAZING / FLIP_GRAZING, on a fold curve (PD test) or a PD curve (fold
// test) FOLD_FLIP. A curve that ends where its orbit grazes ends at a FOLD_GRAZING (fold curve),
// FLIP_GRAZING (PD curve), NS_GRAZING (Neimark-Sacker curve) or DOUBLE_GRAZING (grazing curve: a
// second boundary touched).
// On a Neimark-Sacker curve, RESONANCE_1_q (q = 1..4): the critical pair's kappa = Re(mu) passes
// 1, -1, -1/2, 0 (the strong resonances; for 1:1 and 1:2 generically where the pair turns real).
// On a fold curve, CUSP: the curve's direction in the parameter plane reverses (its tangent's
// parameter part passes through zero while the curve goes on smoothly in the orbit's unknowns:
// two folds meet there, and beyond it the fold curve returns alongside itself), located where
// that parameter part, projected on its direction at the step's start, vanishes.
enum class Codim2Kind {
  kFoldGrazing,
  kFlipGrazing,
  kFoldFlip,
  kDoubleGrazing,
  kNsGrazing,
  kResonance11,
  kResonance12,
  kResonance13,
  kResonance14,
  kCusp,
};
const char* Codim2KindName(Codim2Kind kind);

// A root of a determinant is located as above; a curve's end where its orbit stops being
// admissible is located by bisection: the last admissible point, `detail` naming the violation just
// beyond it and `bracket` the arclength to the nearest inadmissible point the corrector reached
// (~1e-12 when the bisection converged; wider where Newton stalled next to the boundary). The end
// is then solved as a codimension-2 point in tangent form (continuation/grazing_end.h: the
// grazing's tangency plus the curve's condition, or both tangencies of a double grazing) where
// the violation is a segment vanishing between two of one mode or a guard touching zero inside a
// segment; a solution within the bracket replaces the end (its orbit in tangent form, `detail`
// ending "(solved in tangent form)", bracket 0). Where a segment vanishes and no such system is
// regular (a contact phase vanishing between two flights), the end is the limit of the curve's
// points as the segment's length goes to zero, extrapolated from lengths 1e-5, 2e-5 and 4e-5
// (`detail` ending "(extrapolated to segment j of zero length)"; `bracket` then the estimated
// error of its two parameters, 3e-13 .. 2.5e-9 in the reference box, and its multipliers the
// curve's, extrapolated too). Other ends keep their bisection bracket.
struct Codim2Point {
  Codim2Kind kind = Codim2Kind::kFoldGrazing;
  CurvePoint point;
  std::string detail;
  double bracket = 0.0;
  // At a curve's end: the violation just beyond it (`detail` is its message), e.g. which segment
  // vanishes; at roots of test functions not set.
  Admissibility violation;
  // Set by the trace's last pass (TraceCurves, continuation/trace.h) where the same point (kind,
  // period, parameters within 1e-9 of the box) is already an entry of a curve before this one,
  // or earlier in this curve's list: that entry's curve index and its index in that curve's
  // codim2. The point is reported there (the service's result lists it once); -1: reported here.
  int same_as_curve = -1;
  int same_as_index = -1;
};

struct CurveResult {
  CurveKind kind = CurveKind::kFold;
  std::vector<CurvePoint> points;     // along the curve
  std::vector<CurvePoint> crossings;  // at the requested lambda1 / lambda2 values, in order found
  std::vector<Codim2Point> codim2;    // in the order found
  // Ends where the corrector failed next to the last point and only a prediction beyond it, not
  // a corrected orbit, is inadmissible: not located, so not among codim2 (the summary's message
  // names them); kept for switching to try the curves that may leave there.
  std::vector<Codim2Point> unverified_ends;
  ContinuationSummary summary;
};

// Traces the curve through `start` (a FOLD, PERIOD_DOUBLING, NEIMARK_SACKER or GRAZING_* point) in
// both directions. A GRAZING_* start whose orbit already has a tangent end is taken as that
// tangent form; else the form is found from the orbit (a vanishing segment, or an interior touch).
// INVALID_ARGUMENT for a point of another kind or bad options; UNIMPLEMENTED for a grazing with
// neither a vanishing segment between two segments of one mode nor a guard touching zero inside a
// segment. `progress` (optional, common/progress.h) is polled within the steps (every flow) and
// can stop the tracing: termination kCancelled, status CANCELLED, the points and codimension-2
// points found before the stop; without it the tracing polls the throttle the propagator
// carries, if any (flow/propagator.h).
CurveResult ContinueCurve(const HybridModel& model, Propagator& propagator,
                          const SpecialPoint& start, const CurveOptions& options,
                          const ProgressCallback& progress = {});

}  // namespace drillbif

#endif  // DRILLBIF_CONTINUATION_CURVE_H_
