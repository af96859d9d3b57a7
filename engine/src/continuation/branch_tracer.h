// The steppable core of one-parameter continuation in one direction (see
// continuation/continuation.h for the method): Init at a solved orbit, then Step until it returns
// false. Each Step appends the accepted point, and any special point located on the way, to a
// ContinuationResult.
#ifndef DRILLBIF_CONTINUATION_BRANCH_TRACER_H_
#define DRILLBIF_CONTINUATION_BRANCH_TRACER_H_

#include <Eigen/Dense>
#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "continuation/corrector.h"
#include "drillbif/continuation/continuation.h"
#include "orbit/orbit_bvp.h"

namespace drillbif::internal {

struct SwitchedOrbit;  // continuation/signature_switch.h

// Test function values at one point of the branch.
struct TestValues {
  double fold = 0.0;  // parameter component of the unit tangent
  double period_doubling = 0.0;
  double neimark_sacker = 0.0;
  bool complex_pair = false;  // the nontrivial multipliers include a complex pair
  int nontrivial = 0;         // number of nontrivial multipliers
  double branch_point = 0.0;  // sign of det [G_X G_lambda; t^T]
  double slope = 0.0;         // d measure / ds along the tangent
  bool power = false;         // the measure is Pc (the orbit has no progression: ROP = 0)
};

class BranchTracer {
 public:
  BranchTracer(const HybridModel& model, Propagator& propagator, const ContinuationOptions& options,
               int param);
  // The corrector holds a reference to the tracer's system: not copied or moved.
  BranchTracer(const BranchTracer&) = delete;
  BranchTracer& operator=(const BranchTracer&) = delete;

  // Starts at `start` (solved, admissible), heading towards increasing (sign > 0) or decreasing
  // parameter values. Appends the start point to `result` when `record_start`.
  Status Init(const PeriodicOrbit& start, int sign, bool record_start, ContinuationResult* result);
  // One continuation step. False when the branch has ended; then termination() and message() say
  // why.
  bool Step(ContinuationResult* result);

  Termination termination() const { return termination_; }
  const std::string& message() const { return message_; }
  int64_t steps() const { return steps_; }
  // The branch came back to its start (a closed branch): the other direction would only run
  // round it again.
  bool closed() const { return closed_; }
  int64_t rejected() const { return rejected_; }
  int64_t newton_iterations() const { return newton_; }

 private:
  using Vec = Eigen::VectorXd;

  Params ParamsAt(double value) const;
  int m() const { return bvp_->size(); }
  // The corrector's system: the shooting system G(X, lambda) of the current signature at
  // y = (X, lambda), the parameter checked against the model's range.
  class System : public CorrectorSystem {
   public:
    explicit System(const BranchTracer& tracer) : tracer_(tracer) {}
    bool EvaluateInto(const Vec& y, Vec* f, Eigen::Ref<Eigen::MatrixXd>* jac) const override;
    bool Stopped() const override { return tracer_.propagator_.stopped(); }
    bool Valid(const Vec& y) const override;
    int Segments() const override { return tracer_.bvp_->segments(); }
    int Block() const override { return tracer_.m() / tracer_.bvp_->segments(); }

   private:
    const BranchTracer& tracer_;
  };

  // Newton on [G; dir . (y - y_pred)] = 0 from y_pred (PseudoArclengthCorrector), the result's
  // parameter checked against the model's range.
  // With accept_rounding_residual, a residual at rounding level also counts as converged.
  bool Correct(const Vec& y_pred, const Vec& dir, Vec* y, int* iterations,
               bool accept_rounding_residual = false);
  // Unit tangent at y oriented along `prev` (same size), and det of the bordered matrix with it.
  bool Tangent(const Vec& y, const Vec& prev, Vec* t, double* det);
  // The same at the point the last Correct() converged to, from its final factorisation (whose
  // last row was the step direction): solving it for e_last gives a vector along the tangent on
  // the direction's side, and det [G_X G_l; v^T] = v . c with c along the tangent, so the sign of
  // that determinant is the sign of det with the tangent itself.
  bool TangentFromCorrector(Vec* t, double* det) const;
  // The orbit of the current signature at y (the unknowns and the parameter).
  PeriodicOrbit OrbitAt(const Vec& y) const;
  ContinuationPoint MakePoint(const Vec& y) const;
  double Measure(const Vec& y, int index) const;
  TestValues Tests(const Vec& y, const Vec& t, double det, const ContinuationPoint& p) const;
  // Whether the orbit at y has a multiplier at 1 (a smooth fold's).
  bool HasUnitMultiplier(const Vec& y);
  // The point at arclength sigma in [0, h] of the current step (predicted along t_, corrected).
  bool PointAt(double sigma, Vec* y);
  // PointAt at arclengths halving the distance from *sigma to a (up to 8 times) until one
  // corrects; *sigma: that arclength. False where none does.
  bool PointTowards(double a, double* sigma, Vec* y);
  // The point at arclength sigma in (a, b) between the corrected points y_a at a and y_b at b of
  // the current step: predicted on their chord (which lies in sigma's hyperplane of PointAt, so
  // the point is PointAt's, to the corrector's tolerance), corrected.
  bool PointBetween(double sigma, double a, const Vec& y_a, double b, const Vec& y_b, Vec* y);
  // Locates a root of psi between the current point (sigma 0, value psi0) and the corrected point
  // y_h at sigma = h (psi1), its trials predicted on the bracket's chord (PointBetween): from the
  // step's tangent alone, trials next to a root near a grazing, a few 1e-3 of arclength from the
  // vanishing segment's root, started off by the tangent's O(sigma^2) error and ran out of
  // iterations converging linearly, and the bracket stopped wide. `stationary`: the parameter is
  // stationary at the root (a fold), so the bracket is shrunk in arclength rather than stopped on
  // the parameter's spread.
  // *bracket: the width in the parameter of the interval left holding the root.
  bool Locate(double h, const Vec& y_h, double psi0, double psi1,
              const std::function<double(const Vec&)>& psi, bool stationary, Vec* y_root,
              double* bracket);
  // Detects sign changes of the test functions between the current point and (y1, tests1) at
  // arclength h, and appends the located special points. `before_grazing`: (y1, tests1) lies just
  // before a grazing point, where the fixed-signature system may fold by itself; a fold is then
  // reported only where a multiplier lies at 1.
  void DetectSpecialPoints(double h, const Vec& y1, const TestValues& tests1,
                           ContinuationResult* result, bool before_grazing = false);
  // The corrected point y1 of a step has a segment of zero length (to rounding) that was clearly
  // positive at the current point. A segment that starts and ends on the same surface (a CwP
  // phase between two l1 events) has a degenerate family of zero-length solutions: for any
  // parameter value its neighbours can end wherever the surface is crossed, so the corrector may
  // land there instead of on the physical orbit, whose segment vanishes only at the grazing
  // point. Such a step is retried shorter, so that the vanishing is bracketed (a negative
  // duration) or the earlier events on the physical branch are seen.
  bool CollapsedSegment(const Vec& y1) const;
  // Where the branch meets its shifted copy (halves_meet_: the branch point's test changes sign in
  // the step to tests1 at arclength h), the orbit of half the periods traversed twice at its
  // doubling is the branch's turn (a fold in the parameter) and its branch point: both reported
  // at that orbit, solved directly (TipInStep). The corrector's system is singular there, so
  // trial points near it fail to correct or land on the orbits traversed twice, and neither point
  // is located onto it (docs/engine.md). ROP and Pc are even in arclength about the turn (the
  // orbits beyond are the same, shifted): their stationary point there is no maximum, and the
  // caller reports none in this step; the turn is the branch's last point (turn_). False (nothing
  // reported) where there is no such turn.
  bool ReportTurn(double h, const TestValues& tests1, ContinuationResult* result);
  // Reports the turn at `tip` (a FOLD too where `fold`; `reached` appended to its detail) and
  // keeps it as the branch's last point.
  void AddTurn(const Vec& tip, bool fold, const std::string& reached, ContinuationResult* result);
  // Where a step of a branch that meets its shifted copy fails to correct, the turn may lie
  // ahead: next to the turn the system is singular, and steps that do not jump across it shrink
  // to min_step (the period-2 omega-branch from omega = 1.5, a = 5.0, at 1.13664). The turn,
  // solved from y_ and admissible, is reported (AddTurn, a fold) where it lies within the failed
  // step, or beyond it where nothing else lies between (OnlyTheTurnAhead: the period-16
  // omega-branch from omega = 1.0, a = 2.5, whose steps stop correcting 2.3e-2 of arclength
  // before its turn at 0.27075185, where the failed step was 1.1e-2 long); true when it is.
  bool TurnAhead(ContinuationResult* result);
  // Whether the turn at `tip`, `sigma` ahead of y_ along t_ and beyond the failed step, is all
  // that lies between: within max_step, the parameter's change that of a quadratic turn (the
  // mean of its rates at y_, t_[m()], and at the turn, 0; no second fold between) and no
  // multiplier crossing -1 or, with a complex pair, the unit circle (the signs of the
  // period-doubling and Neimark-Sacker tests at both ends). The stretch is not traced: the
  // turn's detail says how far it was solved ahead.
  bool OnlyTheTurnAhead(const Vec& tip, double sigma);
  // The turn solved from y_'s orbit (internal::PitchforkTip, in the branch's signature) into
  // *tip, with its arclength ahead of y_ along t_ in *sigma; false where it is not solved.
  bool SolveTip(Vec* tip, double* sigma);
  // The turn within the step from y_ of arclength h into *tip; false where it is not solved or
  // lies outside the step.
  bool TipInStep(double h, Vec* tip);
  // Records a special point located within `bracket` (and whether the options stop at its kind).
  void AddSpecial(SpecialPointKind kind, const Vec& y, double bracket, std::string detail,
                  ContinuationResult* result);
  // Marks the branch to stop after this step when `kind` is one of options.stop_at, or a branch
  // point where the branch meets its own shifted copy (halves_meet_).
  void NoteStop(SpecialPointKind kind);
  // Handles an inadmissible corrected point at arclength h (its violations): locates the earliest
  // grazing, records it and switches the signature. False when the branch cannot go on.
  bool CrossGrazing(double h, const std::vector<Admissibility>& violations,
                    ContinuationResult* result);
  // The pieces of CrossGrazing, in the order it calls them.
  //
  // The violations of a step located between the current point and its end: each located one,
  // and the earliest, which the signature switches at.
  struct GrazingCrossing {
    struct Located {
      double sigma, value;  // arclength from y_, parameter
      Admissibility violation;
    };
    std::vector<Located> located;
    double sigma = std::numeric_limits<double>::infinity();  // the earliest's arclength from y_
    Vec y;                                                   // the earliest's point
    double bracket = 0.0;                                    // and its Locate bracket
    Admissibility violation;                                 // and what it violates
  };
  // Each of `violations`, violated at y_end (arclength h_end), located between y_ and there;
  // the earliest becomes the one crossed if it lies before `before` and before crossing->sigma.
  void LocateViolations(const std::vector<Admissibility>& violations, double h_end,
                        const Vec& y_end, double before, GrazingCrossing* crossing);
  // The crossing is a vanishing segment: a guard crossing elsewhere that lies clearly before it,
  // unseen at the step's end, replaces it.
  void LocateHiddenGuardCrossing(const std::vector<Admissibility>& violations,
                                 GrazingCrossing* crossing);
  // The grazing point reported where `segment` vanishes: at_graze refined by the tangency
  // system, back in the old signature with that segment of zero length (at_graze when the
  // tangency system has no sound solution; *solved_exactly false).
  ContinuationPoint RefinedGrazingPoint(const ContinuationPoint& at_graze, int segment,
                                        bool* solved_exactly);
  // The old signature's point just before the grazing point y_star (none when it cannot be
  // corrected), after detecting the special points between y_ and it; its test values into
  // *tests_before where they are computed.
  std::optional<ContinuationPoint> SideBeforeGrazing(const Vec& y_star, ContinuationResult* result,
                                                     std::optional<TestValues>* tests_before);
  // A maximum of ROP (Pc where the orbit never progresses) at the grazing point
  // result->special_points[grazing], where the measure's slope along the branch is positive on
  // the old signature just before it (`before`) and negative on the new one at its first point
  // (tests_), each beyond the slopes' error: the measure's largest value is the grazing's, a
  // corner of the branch's measure, not a smooth maximum. Reported at the grazing's point and
  // within its bracket, where a guard touches: where a segment vanishes the old signature's
  // measure is stationary at the grazing to first order (its slope 1e-6 of the step before it
  // 1e-11 .. 5e-8 against 1e-4 .. 1e-2 beyond, and its sign changing with the step), so whether
  // the grazing is the maximum is not established.
  void AddCornerMaximum(const TestValues& before, size_t grazing, ContinuationResult* result);
  // The crossing's violation and its twins at the same point, by decreasing segment index.
  std::vector<Admissibility> CrossedTogether(const GrazingCrossing& crossing, double h) const;
  // The orbit at_graze switched at each of `together` in turn; `inserted` receives the
  // zero-length segments inserted, as indices in the switched orbit.
  SwitchedOrbit SwitchTogether(const PeriodicOrbit& at_graze,
                               const std::vector<Admissibility>& together,
                               std::vector<int>* inserted);
  // The start of the new signature's branch where zero-length segments were inserted: y with
  // the inserted durations at the first step-off length whose corrected orbit (duration `fix`
  // held) has every duration positive, else the shortest.
  Vec StepOffGrazing(const Vec& y, const Vec& fix, const std::vector<int>& inserted);
  // Replaces the system by the switched orbit's and corrects its first point at parameter
  // `value` into y_, t_ and *det; false (after Finish where the branch ends) when it cannot.
  bool StartNewSignature(const SwitchedOrbit& sw, const std::vector<int>& inserted, double value,
                         double* det);
  // Turns t_ (and *det) round when the new signature's branch lies behind the grazing point.
  void OrientNewBranch(double* det);
  void Finish(Termination termination, std::string message);

  const HybridModel& model_;
  Propagator& propagator_;
  const ContinuationOptions& options_;
  int param_;
  Params base_;
  std::unique_ptr<OrbitBvp> bvp_;
  Vec y_, t_;    // current point (X, lambda) and unit tangent
  Vec start_y_;  // the start point, to notice a closed branch
  Signature start_signature_;
  // The start has an even number of periods and is no orbit of half as many traversed twice. The
  // shift by half the period maps such an orbit onto another of the same branch, and at a period
  // doubling of the half-period orbit the branch meets that orbit traversed twice (the orbits the
  // shift fixes) and turns back as its own shifted copy, through the points it has located
  // already: the period-2 omega-branch at a = 0.3 born at the doubling near omega = 0.2698 met
  // the one near 1.6258 and came back to its start, every special point reported twice; the
  // period-4 a-branch at omega = 0.09 ran round that copy to max_steps. Such a branch stops at
  // its branch points. (A branch of orbits traversed twice goes on through them: it stays in
  // the orbits the shift fixes, and each branch point is where a period-2n branch leaves.)
  bool halves_meet_ = false;
  bool closed_ = false;
  // The turn ReportTurn reported in this step, if any: the branch's last point.
  std::optional<ContinuationPoint> turn_;
  System system_{*this};
  // Its last factorization is the last corrector iteration's bordered matrix (dense unless
  // condensed_solve).
  PseudoArclengthCorrector corrector_;
  double h_ = 0.0;  // next step length
  ContinuationPoint point_;
  TestValues tests_;
  int64_t steps_ = 0, rejected_ = 0, newton_ = 0;
  Termination termination_ = Termination::kCompleted;
  std::string message_;
  std::string stop_kind_;  // set once a special point of a stop_at kind is recorded
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_CONTINUATION_BRANCH_TRACER_H_
