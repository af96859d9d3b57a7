// The grazing point where a segment vanishes between two segments of one mode, solved by its
// tangency condition: the orbit with that segment dropped and the segment before it ending
// tangentially on its guard (SegmentSpec::tangent: h = 0 there, the same mode goes on), plus
// h' = 0 at that end, with the continuation parameter free: a square, regular system. (Holding
// the vanishing segment at zero length instead is degenerate: its two events coincide and a whole
// family of zero-length solutions at transversal crossings meets the true branch there.)
#ifndef DRILLBIF_CONTINUATION_TANGENT_GRAZING_H_
#define DRILLBIF_CONTINUATION_TANGENT_GRAZING_H_

#include <Eigen/Dense>
#include <cmath>
#include <functional>
#include <string>
#include <vector>

#include "drillbif/continuation/curve.h"
#include "drillbif/orbit/periodic_orbit.h"

namespace drillbif::internal {

class OrbitBvp;  // orbit/orbit_bvp.h

// The orbit `orbit` re-expressed with segment i dropped and segment i - 1 ending tangentially;
// INVALID_ARGUMENT unless 0 < i < k - 1 and segments i - 1 and i + 1 share their mode.
StatusOr<PeriodicOrbit> TangentForm(const PeriodicOrbit& orbit, int i);

// The orbit re-expressed at an interior touch: where a guard of some segment's mode comes down to
// zero inside the segment and turns back (a local minimum of h, h' = 0; the grazing of a free
// flight with the impact surface seen from the side without impact), that segment is split there
// into a part ending tangentially on that guard and the rest, in the same mode. The touch with the
// smallest h is taken (only in segment `segment` and of guard `guard` when these are >= 0);
// FAILED_PRECONDITION when none comes within `tolerance` of zero.
StatusOr<PeriodicOrbit> TouchForm(const HybridModel& model, Propagator& propagator,
                                  const PeriodicOrbit& orbit, double tolerance = 1e-6,
                                  int segment = -1, int guard = -1);

// The tangent form of a grazing orbit (a located grazing, or the last admissible orbit of a curve
// that ends where its orbit grazes): TangentForm at its shortest segment when that one vanishes
// (duration <= 1e-6) between two segments of one mode, else TouchForm. UNIMPLEMENTED when neither
// applies.
StatusOr<PeriodicOrbit> GrazingTangentForm(const HybridModel& model, Propagator& propagator,
                                           const PeriodicOrbit& orbit);

// Whether segment j starts and ends at events of two different surfaces (the end of segment
// j - 1 and its own end; false for the first or last segment, or at the section).
bool EventsOfTwoSurfaces(const HybridModel& model, const Signature& signature, int j);

// A corner: segment j of zero length (|duration| <= 1e-9), neither the first nor the last,
// between events of two different surfaces (e.g. a contact phase between an impact and the
// start of progression: the impact goes straight into progression). Holding it at zero length is
// a regular grazing condition (the same surface twice would be the degenerate case above).
// Returns j, or -1 when the orbit has none (or has a tangent end: a touch, not a corner).
int CornerSegment(const HybridModel& model, const PeriodicOrbit& orbit);

// The orbit without its tangent end: the (first, or the one at segment `segment`) tangent segment
// and the one after it, in the same mode, merged into one segment. At a grazing this is the orbit
// of the signature without the vanishing segment, touching the guard inside a segment.
// INVALID_ARGUMENT without such a tangent segment.
StatusOr<PeriodicOrbit> MergedForm(const PeriodicOrbit& tangent_orbit, int segment = -1);

// The orbit beyond its (first, or the one at segment `segment`) touch on the side where the touch
// has become a crossing: the tangent end crosses its guard into a zero-length segment of the mode
// across it, after which the tangent segment's mode goes on (SwitchSignature's split of the merged
// orbit at the touch); other tangent ends stay. *new_segment is set to the zero-length segment's
// index. At a codimension-2 root of a grazing curve the fold / PD curve of this signature ends
// from that side, MergedForm's from the other; at a double grazing, the grazing curve of the other
// touch. INVALID_ARGUMENT without a tangent segment followed by one of its mode.
StatusOr<PeriodicOrbit> CrossingForm(const HybridModel& model, Propagator& propagator,
                                     const PeriodicOrbit& tangent_orbit, int* new_segment,
                                     int segment = -1);

// h' at the end of the orbit's tangent segment (the guard's rate where it touches zero); the
// first tangent segment when there are several. NaN when the orbit has none.
double TangentEndRate(const HybridModel& model, Propagator& propagator, const PeriodicOrbit& orbit);
// h' at the end of segment k (the guard's rate where a tangent segment touches zero).
double RateAtTangentEnd(const HybridModel& model, Propagator& propagator,
                        const PeriodicOrbit& orbit, int k);
// h' at the end of every tangent segment, in order.
std::vector<double> TangentEndRates(const HybridModel& model, Propagator& propagator,
                                    const PeriodicOrbit& orbit);
// The tangent segments' indices, in order.
std::vector<int> TangentSegments(const Signature& signature);
// Whether unknown j moves segment `segment`'s flow (any unknown where segment < 0): the unknowns
// of a shooting system with `block` per segment (its start without the phase, then its duration)
// and m in all, then the parameters. Its own start and duration do, an earlier duration (through
// its phase) and a parameter do; the others leave the flow's inputs, and so its bits, as they are.
inline bool MovesSegmentFlow(int j, int segment, int block, int m) {
  return segment < 0 || j >= m || j / block == segment ||
         (j / block < segment && j % block == block - 1);
}

// Newton on (G = 0, h' = 0 at the tangent end) for the tangent-form orbit and params[param],
// from `guess` (in tangent form). Returns the solved orbit (in tangent form).
StatusOr<PeriodicOrbit> SolveTangentGrazing(const HybridModel& model, Propagator& propagator,
                                            const PeriodicOrbit& guess, int param,
                                            double tolerance = 1e-12);

// One extra condition of SolveWithConditions: its value at an orbit and how its row of Newton's
// matrix (its derivative in the orbit's unknowns X and the free parameters) is made.
struct ExtraCondition {
  enum class Kind {
    kDuration,   // durations[segment] - length: a duration is one of X, its row a unit row
    kMonodromy,  // of_monodromy(reduced monodromy): MonodromyRow, then the parameters' columns
    kOrbit,      // of_orbit(orbit): differences of whole evaluations
  };
  // Segment `segment` held at `length`; exact row.
  static ExtraCondition Duration(int segment, double length);
  // A function of the orbit's monodromy without its phase row and column (sigma of the shifted
  // monodromy on a fold / PD / NS curve).
  static ExtraCondition OfMonodromy(std::function<double(const Eigen::MatrixXd&)> f);
  // Any other function of the orbit.
  static ExtraCondition OfOrbit(std::function<double(const PeriodicOrbit&)> f);
  // A function of segment `segment`'s flow alone (h' at a tangent end): of its start (its
  // components in X, its phase through the earlier durations), its duration and the parameters.
  // Its row is differenced in those unknowns only: any other moved gives the flow the same inputs
  // and so the condition the same bits, an entry (c - c) / 2h without the evaluations.
  static ExtraCondition OfSegmentFlow(int segment, std::function<double(const PeriodicOrbit&)> f);
  // sigma of the shifted monodromy of `kind` (fold, period doubling, Neimark-Sacker; not
  // kGrazing), bordered at `at`'s (bordered_sigma.h): the defining condition of a bifurcation
  // of that kind near `at`.
  static ExtraCondition Sigma(const HybridModel& model, Propagator& propagator,
                              const PeriodicOrbit& at, CurveKind kind);

  Kind kind = Kind::kOrbit;
  int segment = -1;     // kDuration: the held segment; kOrbit: the one whose flow it reads, or -1
  double length = 0.0;  // kDuration: its length
  std::function<double(const Eigen::MatrixXd&)> of_monodromy;  // kMonodromy: the function
  std::function<double(const PeriodicOrbit&)> of_orbit;        // kOrbit: the function
};

// The condition's value at `orbit`.
double ConditionValue(const HybridModel& model, Propagator& propagator, const PeriodicOrbit& orbit,
                      const ExtraCondition& condition);

// The condition's value at y = (X of `bvp`, then params[free[0]], params[free[1]]) with the other
// parameters from `params`, and its row of Newton's matrix there (*row, y.size() long): exact for
// kDuration, else central differences of step h = 1e-6 (1 + |y_j|) (truncation h^2 |c'''| / 6,
// 2e-13 |c'''|, and rounding eps |c| / h, 2e-10 |c|; forward differences, with their error
// h |c''| / 2, left Newton stagnating on the fixed-length systems a few 1e-6 from a contact phase
// vanishing between flights, where the condition's derivatives grow like powers of 1 / length),
// for kMonodromy by MonodromyRow over X and whole evaluations for the parameters (every factor
// moves with them). The row only steers Newton; the residual is exact.
double ConditionRow(const HybridModel& model, Propagator& propagator, const OrbitBvp& bvp,
                    const std::vector<int>& free, const Params& params, const Eigen::VectorXd& y,
                    const ExtraCondition& condition, Eigen::RowVectorXd* row);

// How MonodromyRow differences f: central with steps h = 1e-6 (1 + |x|) (ConditionRow's), or
// forward from f0 = f(M) with steps h = 1.5e-8 (1 + |x|) (the fold / PD / NS curves' condition
// row, CurveTracer: truncation h |f''| / 2 and rounding eps |f| / h, both ~1e-8 for these O(1)
// quantities; one factor per column instead of two).
enum class RowDifferences { kCentral, kForward };

// The forward-difference step of an unknown of value v: 1.5e-8 (1 + |v|) (RowDifferences).
inline double ForwardStep(double v) { return 1.5e-8 * (1.0 + std::abs(v)); }

// MonodromyRow's and MonodromyGradientRow's workspace, kept by a caller that makes rows over and
// over (CurveSystem: one per Newton iteration) so that they do not allocate it anew each time.
struct MonodromyRowScratch {
  std::vector<StateMatrix> prefix, suffix;  // the factors' partial products
  std::vector<StateMatrix> weight;          // MonodromyGradientRow: the gradient at each factor
  std::vector<StateMatrix> later;           // MonodromyRow: d M per later phase shift
  std::vector<double> later_rates;          // MonodromyGradientRow: the same, contracted
  PeriodicOrbit moved;                      // the orbit, perturbed in place and restored
};

// Differences of f(M) over the orbit's unknowns X (OrbitBvp's order: each segment's start without
// its phase, then its duration), M the reduced monodromy, recomputing only the monodromy factors
// (orbit/monodromy.h) an unknown moves: a start's component moves its own factor (for a model
// with a LinearForm only its saltation, from the segment's flow), a duration its own and, through
// the later segments' phases, every later one, taken to first order as suffix dF_l / ds_l prefix
// summed once per segment (the durations' columns flow 4k factors instead of k^2 centred, 2k
// instead of k^2 / 2 forward; the starts' none with a LinearForm; the second-order terms left out
// are O(h) forward, below the differences' own truncation, and even in the step centred, where
// they cancel to O(h^2)). `base` and `flows` are MonodromyFactors(orbit) and the flows they were
// made from; `f0` is f(M) (used by kForward only). `scratch`, when given, is the workspace (its
// storage reused; the row is the same bits either way).
void MonodromyRow(const HybridModel& model, Propagator& propagator, const PeriodicOrbit& orbit,
                  const std::vector<StateMatrix>& base, const std::vector<FlowResult>& flows,
                  const std::function<double(const Eigen::Ref<const Eigen::MatrixXd>&)>& f,
                  RowDifferences differences, double f0,
                  Eigen::Ref<Eigen::RowVectorXd, 0, Eigen::InnerStride<>> row,
                  MonodromyRowScratch* scratch = nullptr);

// The row of a function f of the reduced monodromy M over X (MonodromyRow's unknowns and order)
// from f's gradient in M (`gradient`, d f / d m_pq, M's size) instead of f evaluated once per
// unknown: the factor F_i an unknown moves is differenced forward as in MonodromyRow (kForward,
// ForwardStep; the durations' later phase shifts to first order likewise), and its change is
// contracted with the gradient carried to that factor, <suffix^T G prefix^T, dF_i> (G with zero
// phase row and column, one weight matrix per segment). It sits beside MonodromyRow for cost: for
// sigma of a fold / PD / NS curve (SigmaWithGradient) each unknown then takes one state-sized
// contraction where MonodromyRow forms the moved monodromy (two products), drops its phase and
// solves a bordered system, which cost more than the moved factor itself (docs/performance.md).
// The row differs from MonodromyRow's forward one by f's own curvature over the step, O(h), of the
// order of the differences' truncation, and with less rounding (a factor's difference, not the
// whole product's); it only steers Newton: the residual is exact. MonodromyRow stays for any f
// without a gradient and for central differences (ConditionRow). `scratch` as MonodromyRow's.
void MonodromyGradientRow(const HybridModel& model, Propagator& propagator,
                          const PeriodicOrbit& orbit, const std::vector<StateMatrix>& base,
                          const std::vector<FlowResult>& flows,
                          const Eigen::Ref<const Eigen::MatrixXd>& gradient,
                          Eigen::Ref<Eigen::RowVectorXd, 0, Eigen::InnerStride<>> row,
                          MonodromyRowScratch* scratch = nullptr);

// Newton on (G = 0, c = 0) from `guess` in its signature, with the unknowns X and the parameters
// `free` (one or two), one condition per free parameter so that the system is square. G's
// Jacobian is exact, the conditions' rows ConditionRow's (they only steer Newton, the residual is
// exact). Stops at a scaled step <= tolerance; INTERNAL when Newton fails or stagnates (no tenfold
// shrinking of the step over 8 iterations, after 16; or its steps shrinking by one ratio, too
// slowly to reach the tolerance in the 30 iterations) (`what` names the system).
StatusOr<PeriodicOrbit> SolveWithConditions(const HybridModel& model, Propagator& propagator,
                                            const PeriodicOrbit& guess,
                                            const std::vector<int>& free,
                                            const std::vector<ExtraCondition>& conditions,
                                            double tolerance, const std::string& what);

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_TANGENT_GRAZING_H_
