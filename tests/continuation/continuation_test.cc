// One-parameter continuation of the drifting oscillator's period-1 orbit: MODEL.md's table for the
// b-continuation, the defining conditions of located points, admissibility of every point,
// stability against direct simulation, hard cases and invalid requests.
#include "drillbif/continuation/continuation.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <string>

#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"
#include "support/multipliers.h"
#include "support/special_point_near.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

PeriodicOrbit StartOrbit(const DO& model, Propagator& prop, const Params& params) {
  StatusOr<PeriodicOrbit> orbit = testing::SolvedOrbitFromRest(model, prop, params);
  EXPECT_TRUE(orbit.ok()) << orbit.status().ToString();
  return orbit.ok() ? *orbit : PeriodicOrbit{};
}

ContinuationResult ContinueInB(double a) {
  DO model;
  ExactPropagator prop(model);
  Params prm = testing::ReferenceParams();
  prm[DO::kA] = a;
  ContinuationOptions opt;
  opt.param = "b";
  opt.min = 0.0;
  opt.max = 0.2;
  return Continue(model, prop, StartOrbit(model, prop, prm), opt);
}

// The b-continuation at the reference a = 0.3, computed once for the tests below.
const ContinuationResult& ReferenceBranch() {
  static const ContinuationResult r = ContinueInB(0.3);
  return r;
}

// The first special point of a kind whose parameter lies in [lo, hi].
const SpecialPoint* Find(const ContinuationResult& r, SpecialPointKind kind, double lo, double hi) {
  for (const SpecialPoint& s : r.special_points) {
    if (s.kind == kind && s.point.value >= lo && s.point.value <= hi) return &s;
  }
  return nullptr;
}

// Every point of the branch is admissible: positive durations, and no guard vanishes inside a
// segment. The located special points themselves are excluded (a grazing point lies on the
// boundary, with a zero-length segment).
void ExpectAdmissibleAwayFromSpecialPoints(const DO& model, Propagator& prop,
                                           const ContinuationResult& r, const std::string& label) {
  std::vector<double> special;
  for (const SpecialPoint& s : r.special_points) special.push_back(s.point.value);
  for (const ContinuationPoint& p : r.points) {
    if (std::any_of(special.begin(), special.end(),
                    [&](double v) { return std::abs(v - p.value) < 1e-9; })) {
      continue;
    }
    const Admissibility a = CheckAdmissible(model, prop, p.orbit);
    EXPECT_TRUE(a.admissible) << label << " = " << p.value << ": " << a.message;
  }
}

// Stability agrees with direct simulation at 20 points of the branch: from the orbit's section
// state perturbed by 1e-7, a stable orbit's deviation shrinks over 30 periods and an unstable
// one's grows (by the largest multiplier's modulus to the 30th power; points with it in
// [0.8, 1.25] are skipped, so the factor is below 1e-3 or above 8e2 and a non-normal transient
// cannot blur it; so are points next to a grazing, where a segment is shorter than 1e-2).
// Returns how many stable and unstable points were checked.
std::pair<int, int> ExpectStabilityMatchesSimulation(const DO& model, Propagator& prop,
                                                     const ContinuationResult& r,
                                                     const std::string& label) {
  std::vector<const ContinuationPoint*> chosen;
  for (const ContinuationPoint& p : r.points) {
    if (p.stability.multipliers.empty()) continue;
    const double mu = std::abs(p.stability.multipliers[0]);
    const double dmin = *std::min_element(p.orbit.durations.begin(), p.orbit.durations.end());
    if ((mu > 0.8 && mu < 1.25) || dmin < 1e-2) continue;
    chosen.push_back(&p);
  }
  EXPECT_GE(chosen.size(), 20u) << label;
  int stable = 0, unstable = 0;
  for (size_t k = 0; k < 20 && k < chosen.size(); ++k) {
    const ContinuationPoint& p = *chosen[k * chosen.size() / 20];
    StateVector x = p.orbit.starts[0];
    x[DO::kY] += 1e-7;
    SimulationOptions opt;
    opt.transient_periods = 0;
    opt.sample_periods = 30 * p.orbit.signature.periods;
    opt.outputs = SimulationOutputs{false, true, false, false, 0.0};
    const SimulationResult s = Simulate(model, prop, p.orbit.params, x, opt);
    EXPECT_EQ(s.summary.termination, Termination::kCompleted) << label << " = " << p.value;
    if (s.poincare.empty()) continue;
    const double d = (s.poincare.back().x - p.orbit.starts[0]).head(3).norm();
    if (p.stability.stable) {
      EXPECT_LT(d, 1e-7) << "stable orbit at " << label << " = " << p.value;
      ++stable;
    } else {
      EXPECT_GT(d, 1e-7) << "unstable orbit at " << label << " = " << p.value;
      ++unstable;
    }
  }
  return {stable, unstable};
}

// MODEL.md's table, independent-computation column (8 significant digits), to 1e-6 relative.
TEST(BContinuation, ReproducesThePublishedTable) {
  const ContinuationResult& r = ReferenceBranch();
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.message;
  struct Row {
    SpecialPointKind kind;
    double b;
  };
  for (const Row& row :
       {Row{SpecialPointKind::kRopMax, 0.16381677}, Row{SpecialPointKind::kFold, 0.16715050},
        Row{SpecialPointKind::kPeriodDoubling, 0.11001173},
        Row{SpecialPointKind::kGrazingL1, 0.02772417}}) {
    const SpecialPoint* s = Find(r, row.kind, row.b * 0.99, row.b * 1.01);
    ASSERT_NE(s, nullptr) << SpecialPointKindName(row.kind) << " near b = " << row.b;
    EXPECT_NEAR(s->point.value, row.b, 1e-6 * row.b) << SpecialPointKindName(row.kind);
    // Tighter: the published values carry 8 decimals, so they are exact to half a unit of the
    // last one (5e-9); the location adds 1e-10.
    EXPECT_NEAR(s->point.value, row.b, 5e-9 + 1e-10) << SpecialPointKindName(row.kind);
  }
  const SpecialPoint* rop_max = Find(r, SpecialPointKind::kRopMax, 0.16, 0.165);
  ASSERT_NE(rop_max, nullptr);
  EXPECT_NEAR(rop_max->point.measures[DO::kDrift], 0.53873914, 1e-6 * 0.53873914);
  EXPECT_NEAR(rop_max->point.measures[DO::kDrift], 0.53873914, 5e-9);
}

// Only what is asked: without measure maxima and with ROP alone on the points, the same
// bifurcations are located (to rounding: the same corrector path) and no ROP_MAX / POWER_MAX is
// reported; Pc is left 0.
TEST(BContinuation, ComputesOnlyTheAskedMeasures) {
  DO model;
  ExactPropagator prop(model);
  ContinuationOptions opt;
  opt.param = "b";
  opt.min = 0.0, opt.max = 0.2;
  opt.locate_measure_maxima = false;
  opt.point_measures = 1u << DO::kDrift;
  const ContinuationResult r =
      Continue(model, prop, StartOrbit(model, prop, testing::ReferenceParams()), opt);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.message;
  const ContinuationResult& full = ReferenceBranch();
  std::vector<const SpecialPoint*> expected;
  for (const SpecialPoint& s : full.special_points) {
    if (s.kind != SpecialPointKind::kRopMax && s.kind != SpecialPointKind::kPowerMax) {
      expected.push_back(&s);
    }
  }
  ASSERT_EQ(r.special_points.size(), expected.size());
  for (size_t i = 0; i < expected.size(); ++i) {
    EXPECT_EQ(r.special_points[i].kind, expected[i]->kind);
    EXPECT_NEAR(r.special_points[i].point.value, expected[i]->point.value, 1e-12);
  }
  for (const ContinuationPoint& p : r.points) {
    ASSERT_EQ(p.measures.size(), 2u);
    EXPECT_EQ(p.measures[DO::kPower], 0.0);
  }
  // ROP is still there where the orbit progresses (the reference point's 0.4989).
  EXPECT_GT(r.points.front().measures[DO::kDrift] + r.points.back().measures[DO::kDrift], 0.0);
}

// Down through the l1 grazing to b = 0, where the period-1 orbit runs off (the period-adding
// cascade accumulates there): below the grazing the orbit never progresses (ROP = 0) and Pc is
// the measure.
TEST(BContinuation, GoesThroughTheL1GrazingDownToZeroWithPcAsTheMeasure) {
  const ContinuationResult& r = ReferenceBranch();
  ASSERT_FALSE(r.points.empty());
  EXPECT_LT(r.points.front().value, 1e-5);
  int below = 0;
  for (const ContinuationPoint& p : r.points) {
    if (p.value >= 0.0277 || p.value < 1e-4) continue;
    ++below;
    EXPECT_EQ(p.measures[DO::kDrift], 0.0) << "b = " << p.value;
    EXPECT_GT(p.measures[DO::kPower], 0.0) << "b = " << p.value;
    EXPECT_EQ(SignatureString(DO(), p.orbit.signature), "NC>Pi CwoP>l2 NC|");
  }
  EXPECT_GT(below, 10);
  const SpecialPoint* graze = Find(r, SpecialPointKind::kGrazingL1, 0.02, 0.03);
  ASSERT_NE(graze, nullptr);
  EXPECT_NE(graze->detail.find("-> NC>Pi CwoP>l2 NC|"), std::string::npos) << graze->detail;
}

// Each located point satisfies its defining condition: a multiplier at +1 (fold) or -1 (period
// doubling) to 1e-9, the vanished segment's duration at zero (grazing) to 1e-9. The location
// brackets the parameter to 1e-10 (fold: the arclength to 1e-9 of the step), and the multiplier
// moves by O(1) per unit of parameter or arclength there, so 1e-9 is what the location promises.
TEST(BContinuation, LocatedPointsSatisfyTheirDefiningConditions) {
  const ContinuationResult& r = ReferenceBranch();
  int checked = 0;
  for (const SpecialPoint& s : r.special_points) {
    const auto& mu = s.point.stability.multipliers;
    auto closest = [&](double target) {
      double d = std::numeric_limits<double>::infinity();
      for (const auto& m : mu) d = std::min(d, std::abs(m - target));
      return d;
    };
    switch (s.kind) {
      case SpecialPointKind::kFold:
        EXPECT_LE(closest(1.0), 1e-9) << "fold at b = " << s.point.value;
        ++checked;
        break;
      case SpecialPointKind::kPeriodDoubling:
        EXPECT_LE(closest(-1.0), 1e-9) << "PD at b = " << s.point.value;
        ++checked;
        break;
      case SpecialPointKind::kGrazingL1: {
        const auto& d = s.point.orbit.durations;
        EXPECT_LE(*std::min_element(d.begin(), d.end(),
                                    [](double x, double y) { return std::abs(x) < std::abs(y); }) *
                      1.0,
                  1e-9);
        ++checked;
        break;
      }
      default:
        break;
    }
  }
  EXPECT_GE(checked, 3);
}

// Every reported point is admissible: positive durations, and no guard vanishes inside a segment
// (the points at a grazing lie on the boundary and are excluded).
TEST(BContinuation, EveryPointIsAdmissible) {
  DO model;
  ExactPropagator prop(model);
  ExpectAdmissibleAwayFromSpecialPoints(model, prop, ReferenceBranch(), "b");
}

// Stability agrees with direct simulation (ExpectStabilityMatchesSimulation) on the b branch,
// which has both stable and unstable orbits.
TEST(BContinuation, StabilityAgreesWithDirectSimulation) {
  DO model;
  ExactPropagator prop(model);
  const auto [stable, unstable] =
      ExpectStabilityMatchesSimulation(model, prop, ReferenceBranch(), "b");
  EXPECT_GT(stable, 0);
  EXPECT_GT(unstable, 0);
}

// The same picture at a = 0.28 and 0.32 (MODEL.md): ROP maximum below the fold, period doubling
// below the maximum, the l1 grazing below that, and the branch reaches b = 0.
TEST(BContinuation, SamePictureAtNeighbouringAmplitudes) {
  for (double a : {0.28, 0.32}) {
    const ContinuationResult r = ContinueInB(a);
    ASSERT_EQ(r.summary.termination, Termination::kCompleted) << "a = " << a;
    const SpecialPoint* fold = Find(r, SpecialPointKind::kFold, 0.12, 0.2);
    const SpecialPoint* rop = Find(r, SpecialPointKind::kRopMax, 0.12, 0.2);
    const SpecialPoint* pd = Find(r, SpecialPointKind::kPeriodDoubling, 0.05, 0.15);
    const SpecialPoint* graze = Find(r, SpecialPointKind::kGrazingL1, 0.0, 0.06);
    ASSERT_TRUE(fold && rop && pd && graze) << "a = " << a;
    EXPECT_LT(rop->point.value, fold->point.value);
    EXPECT_LT(pd->point.value, rop->point.value);
    EXPECT_LT(graze->point.value, pd->point.value);
    EXPECT_LT(r.points.front().value, 1e-5);
  }
}

// Hard case: a = 5, where the impact goes straight into progression and, as b falls, a contact
// phase appears between impact and progression before the l1 grazing.
TEST(Continuation, LargeAmplitudeSwitchesSignatureTwiceOnTheWayDown) {
  DO model;
  ExactPropagator prop(model);
  Params prm = testing::ReferenceParams();
  prm[DO::kA] = 5.0;
  ContinuationOptions opt;
  opt.param = "b";
  opt.min = 0.0;
  opt.max = 0.3;
  const ContinuationResult r = Continue(model, prop, StartOrbit(model, prop, prm), opt);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.message;
  const SpecialPoint* change = Find(r, SpecialPointKind::kSignatureChange, 0.0, 0.3);
  const SpecialPoint* graze = Find(r, SpecialPointKind::kGrazingL1, 0.0, 0.3);
  ASSERT_TRUE(change && graze);
  EXPECT_NE(change->detail.find("NC>Pi CwP>l1 CwoP>l2 NC| -> NC>Pi CwoP>l1 CwP>l1"),
            std::string::npos)
      << change->detail;
  EXPECT_LT(graze->point.value, change->point.value);
}

TEST(Continuation, InvalidRequestsAreClearErrors) {
  DO model;
  ExactPropagator prop(model);
  const PeriodicOrbit start = StartOrbit(model, prop, testing::ReferenceParams());
  struct Case {
    std::string param;
    double min, max;
    const char* needle;
  };
  for (const Case& c : {Case{"zeta", 0.0, 1.0, "zeta"}, Case{"b", 0.2, 0.1, "empty"},
                        Case{"b", 0.2, 0.3, "outside"}}) {
    ContinuationOptions opt;
    opt.param = c.param;
    opt.min = c.min;
    opt.max = c.max;
    const ContinuationResult r = Continue(model, prop, start, opt);
    EXPECT_EQ(r.summary.termination, Termination::kFailed);
    EXPECT_EQ(r.summary.status.code(), StatusCode::kInvalidArgument) << c.param;
    EXPECT_NE(r.summary.message.find(c.needle), std::string::npos) << r.summary.message;
  }
  PeriodicOrbit broken = start;
  broken.durations[2] = -0.1;  // a negative-duration segment: not an admissible orbit
  ContinuationOptions opt;
  opt.param = "b";
  opt.min = 0.0;
  opt.max = 0.2;
  const ContinuationResult r = Continue(model, prop, broken, opt);
  EXPECT_EQ(r.summary.termination, Termination::kFailed);
  EXPECT_EQ(r.summary.status.code(), StatusCode::kFailedPrecondition);
  EXPECT_EQ(r.summary.steps, 0);
}

// MODEL.md's other continuations from the start orbit: in a over [0.05, 3] and in omega over
// [0.03, 3.5]. Both run to both ends, through every special point on the way, with every point
// admissible and every located fold and period doubling at a multiplier +1 / -1 to 1e-9.
class RangeContinuationTest
    : public ::testing::TestWithParam<std::tuple<const char*, double, double>> {};

TEST_P(RangeContinuationTest, RunsToBothEndsThroughEverySpecialPoint) {
  const auto [param, lo, hi] = GetParam();
  DO model;
  ExactPropagator prop(model);
  ContinuationOptions opt;
  opt.param = param;
  opt.min = lo;
  opt.max = hi;
  const ContinuationResult r =
      Continue(model, prop, StartOrbit(model, prop, testing::ReferenceParams()), opt);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.message;
  EXPECT_NEAR(r.points.front().value, lo, 1e-9) << r.summary.message;
  EXPECT_NEAR(r.points.back().value, hi, 1e-9) << r.summary.message;
  EXPECT_GE(r.special_points.size(), 3u);
  for (const SpecialPoint& s : r.special_points) {
    const double target = s.kind == SpecialPointKind::kFold ? 1.0 : -1.0;
    const double closest = testing::DistanceToMultiplier(s.point.stability, target);
    if (s.kind == SpecialPointKind::kFold || s.kind == SpecialPointKind::kPeriodDoubling) {
      EXPECT_LE(closest, 1e-9) << SpecialPointKindName(s.kind) << " at " << s.point.value;
    }
  }
  ExpectAdmissibleAwayFromSpecialPoints(model, prop, r, param);
}

INSTANTIATE_TEST_SUITE_P(ModelRanges, RangeContinuationTest,
                         ::testing::Values(std::make_tuple("a", 0.05, 3.0),
                                           std::make_tuple("omega", 0.03, 3.5)),
                         [](const auto& test_info) { return std::get<0>(test_info.param); });

// Hard cases: repeated characteristic roots in contact (xi = 1) and slow forcing with a period-3
// start orbit (omega = 0.02): the b-continuation completes with admissible points.
TEST(Continuation, HardParametersCompleteWithAdmissiblePoints) {
  DO model;
  ExactPropagator prop(model);
  for (const auto& [index, value] : {std::make_pair(static_cast<int>(DO::kXi), 1.0),
                                     std::make_pair(static_cast<int>(DO::kOmega), 0.02)}) {
    Params prm = testing::ReferenceParams();
    prm[index] = value;
    const PeriodicOrbit start = StartOrbit(model, prop, prm);
    ContinuationOptions opt;
    opt.param = "b";
    opt.min = 0.1;
    opt.max = 0.3;
    opt.steps.max_steps = 300;
    const ContinuationResult r = Continue(model, prop, start, opt);
    EXPECT_EQ(r.summary.termination, Termination::kCompleted)
        << model.param_names()[index] << ": " << r.summary.message;
    ExpectAdmissibleAwayFromSpecialPoints(model, prop, r, model.param_names()[index] + ", b");
  }
}

// A period-2 orbit that is a period-1 orbit traversed twice reaches each boundary in both copies
// at once. At xi = 0.5 the simulation settles on a period-2 orbit (a = 0.3, omega = 0.1) whose
// branch, continued up in omega, becomes such an orbit; both of its impacts fall below the
// progression threshold at omega = 0.68815, so both CwP phases must get a CwoP phase before them
// at that one point. Crossing one violation at a time leaves the other already violated at the
// step-off point and the branch FAILED there; so both are switched together and the branch goes
// on to omega = 3.5 with admissible points. The same at omega = 0.69896, where both CwP phases
// vanish: located in arclength 1e-2 of a step apart (the branch is stationary in omega there)
// but 6e-9 apart in omega, they are one switch. Down in omega the branch turns at omega = 0.0909,
// a branch point where it meets the period-1 orbit traversed twice, and ends there: beyond it run
// the same orbits shifted by one period (which, run on, went back up through both switches a
// second time, to omega = 3.5).
TEST(Continuation, SwitchesBothCopiesOfATwiceTraversedOrbitAtOnce) {
  DO model;
  ExactPropagator prop(model);
  Params prm = testing::ReferenceParams();
  prm[DO::kXi] = 0.5;
  const PeriodicOrbit start = StartOrbit(model, prop, prm);
  ASSERT_EQ(start.signature.periods, 2);
  ContinuationOptions opt;
  opt.param = "omega";
  opt.min = 0.03;
  opt.max = 3.5;
  const ContinuationResult r = Continue(model, prop, start, opt);
  const SpecialPoint* change = Find(r, SpecialPointKind::kSignatureChange, 0.68, 0.69);
  ASSERT_NE(change, nullptr) << r.summary.message;
  const std::string after = change->detail.substr(change->detail.find("->"));
  size_t copies = 0;
  for (size_t at = after.find("CwoP>l1 CwP"); at != std::string::npos;
       at = after.find("CwoP>l1 CwP", at + 1)) {
    ++copies;
  }
  EXPECT_EQ(copies, 2u) << change->detail;
  EXPECT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.message;
  int vanishings = 0;
  for (const SpecialPoint& s : r.special_points) {
    if (s.kind != SpecialPointKind::kGrazingL1 || std::abs(s.point.value - 0.69896) > 1e-4)
      continue;
    ++vanishings;
    // Both CwP phases gone in one switch.
    EXPECT_EQ(s.detail.substr(s.detail.find("->")).find("CwP"), std::string::npos) << s.detail;
  }
  EXPECT_EQ(vanishings, 1) << r.summary.message;
  double highest = 0.0;
  for (const ContinuationPoint& p : r.points) highest = std::max(highest, p.value);
  EXPECT_EQ(highest, opt.max) << r.summary.message;
  // The turn, where the branch meets the period-1 orbit traversed twice: a fold (a multiplier at
  // +1, the square of that orbit's -1) and a branch point, where the direction ends.
  EXPECT_NE(Find(r, SpecialPointKind::kFold, 0.09, 0.092), nullptr) << r.summary.message;
  EXPECT_NE(Find(r, SpecialPointKind::kBranchPoint, 0.09, 0.092), nullptr) << r.summary.message;
  EXPECT_NE(r.summary.message.find("decreasing: stopped at BRANCH_POINT"), std::string::npos)
      << r.summary.message;
  ExpectAdmissibleAwayFromSpecialPoints(model, prop, r, "xi = 0.5, omega");
}

// A flight that leaves the slider at a vanishing force rate comes back to Pi almost at once. On the
// period-4 a-branch at omega = 0.09 (the attractor at a = 0.57), near a = 0.6851, the flight after
// a separation re-crosses Pi 0.30 into its 92, inside the first of the intervals at which the
// violation's test function samples the gap, where h' starts at zero: the samples missed that dip,
// the crossing was not bracketed and the branch FAILED ("could not locate or cross"). Now located,
// the branch goes on and ends each way at a branch point where the period-4 orbit meets a period-2
// orbit traversed twice, beyond which it ran round its own shifted copy to max_steps, every
// special point reported again; each is reported once, and every point is admissible.
TEST(Continuation, APeriodFourBranchLocatesAReturnInsideOneSampleAndEndsAtItsBranchPoints) {
  DO model;
  ExactPropagator prop(model);
  Params prm = testing::ReferenceParams();
  prm[DO::kOmega] = 0.09;
  prm[DO::kA] = 0.57;
  const PeriodicOrbit start = StartOrbit(model, prop, prm);
  ASSERT_EQ(start.signature.periods, 4);
  ContinuationOptions opt;
  opt.param = "a";
  opt.min = 0.25, opt.max = 0.75;
  const ContinuationResult r = Continue(model, prop, start, opt);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.message;
  for (const char* way :
       {"increasing: stopped at BRANCH_POINT", "decreasing: stopped at BRANCH_POINT"}) {
    EXPECT_NE(r.summary.message.find(way), std::string::npos) << r.summary.message;
  }
  for (size_t i = 0; i < r.special_points.size(); ++i) {
    const SpecialPoint& s = r.special_points[i];
    for (size_t j = 0; j < i; ++j) {
      const SpecialPoint& t = r.special_points[j];
      EXPECT_FALSE(t.kind == s.kind && t.detail == s.detail &&
                   std::abs(t.point.value - s.point.value) <= 1e-9)
          << SpecialPointKindName(s.kind) << " at a = " << s.point.value << " twice";
    }
  }
  ExpectAdmissibleAwayFromSpecialPoints(model, prop, r, "omega = 0.09, a");
}

// A touch just after the section: on branches of period-2 attractors the contact phase that the
// section splits reaches the progression threshold l1 with h falling after the section, so its
// guard touches zero inside the segment before it fires at the section's start. Switched at the
// start (a CwP phase first), the branch FAILED: the CwP phase ended at once ("could not locate or
// cross: segment 0 (CwP) crosses l1 at t = 0"; the a-branch at omega = 0.6 from a = 0.2), or
// its other half crossed l1 through the section ("segment 3 (CwoP) crosses l1 at
// t = 2.749364 of 2.764830"; the omega-branch at a = 0.5 from omega = 0.07). Located as the touch
// (the guard's minimum over the segment, found here independently by golden-section search
// around the best of 400 samples, zero to the locator's value tolerance 1e-10, the start's value
// positive) and crossed by splitting the segment there, both branches end at their turns, every
// point admissible.
void ExpectTouchAfterTheSectionCrossed(double omega, double a, const std::string& param, double min,
                                       double max) {
  SCOPED_TRACE(param + "-branch from omega = " + std::to_string(omega) +
               ", a = " + std::to_string(a));
  DO model;
  ExactPropagator prop(model);
  Params prm = testing::ReferenceParams();
  prm[DO::kOmega] = omega;
  prm[DO::kA] = a;
  const PeriodicOrbit start = StartOrbit(model, prop, prm);
  ASSERT_EQ(start.signature.periods, 2);
  ContinuationOptions opt;
  opt.param = param;
  opt.min = min, opt.max = max;
  const ContinuationResult r = Continue(model, prop, start, opt);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.message;
  int touches = 0;
  for (const SpecialPoint& s : r.special_points) {
    const PeriodicOrbit& o = s.point.orbit;
    if (s.kind != SpecialPointKind::kGrazingL1 || o.signature.segments[0].mode != DO::kContact) {
      continue;
    }
    auto h = [&](double t) {
      const StateVector x = prop.FlowMap(DO::kContact, o.starts[0], t, o.params, {}).x;
      return model.Guard(DO::kContact, DO::kProgressionStart, x, o.params).h;
    };
    constexpr int kSamples = 400;
    const double tau = o.durations[0];
    int best = 1;
    for (int j = 1; j < kSamples; ++j) {
      if (h(tau * j / kSamples) < h(tau * best / kSamples)) best = j;
    }
    double lo = tau * (best - 1) / kSamples, hi = tau * (best + 1) / kSamples;
    const double phi = 0.5 * (std::sqrt(5.0) - 1.0);
    for (int it = 0; it < 100; ++it) {
      const double t1 = hi - phi * (hi - lo), t2 = lo + phi * (hi - lo);
      if (h(t1) < h(t2)) {
        hi = t2;
      } else {
        lo = t1;
      }
    }
    if (std::abs(h(0.5 * (lo + hi))) <= 1e-10 && h(0.0) > 0.0) ++touches;
  }
  EXPECT_GE(touches, 1) << "no l1 touch located inside the phase after the section";
  ExpectAdmissibleAwayFromSpecialPoints(model, prop, r, param);
}

TEST(Continuation, CrossesATouchJustAfterTheSectionAsATouch) {
  ExpectTouchAfterTheSectionCrossed(0.6, 0.2, "a", 0.01, 8.0);
  ExpectTouchAfterTheSectionCrossed(0.07, 0.5, "omega", 0.05, 2.0);
}

// A guard crossing hidden behind a vanishing segment: at omega = 0.05 (reached from the reference
// orbit by the omega-branch) the a-branch meets, near a = 0.21531, a touch of Pi inside a free
// flight 72 long 1.2e-6 in a before its first segment (a free flight 0.02 long) vanishes, both
// within one step. AdmissibilityViolations lists only the vanishing segment there; crossed first,
// it left the touch already violated and the branch FAILED ("could not locate or cross"). Now
// the touch is located and crossed first (a GRAZING_PI) and the branch reaches both bounds with
// every point admissible.
TEST(Continuation, CrossesAGuardTouchHiddenBehindAVanishingSegment) {
  DO model;
  ExactPropagator prop(model);
  ContinuationOptions down;
  down.param = "omega";
  down.min = 0.05, down.max = 0.1;
  down.direction = ContinuationDirection::kDecreasing;
  const ContinuationResult w =
      Continue(model, prop, StartOrbit(model, prop, testing::ReferenceParams()), down);
  ASSERT_EQ(w.summary.termination, Termination::kCompleted) << w.summary.message;
  const auto lowest = std::min_element(
      w.points.begin(), w.points.end(),
      [](const ContinuationPoint& x, const ContinuationPoint& y) { return x.value < y.value; });
  ASSERT_NEAR(lowest->value, 0.05, 1e-9);
  ContinuationOptions opt;
  opt.param = "a";
  opt.min = 0.01, opt.max = 8.0;
  const ContinuationResult r = Continue(model, prop, lowest->orbit, opt);
  EXPECT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.message;
  EXPECT_NE(Find(r, SpecialPointKind::kGrazingPi, 0.21530, 0.21532), nullptr);
  double lo = opt.max, hi = opt.min;
  for (const ContinuationPoint& p : r.points)
    lo = std::min(lo, p.value), hi = std::max(hi, p.value);
  // The bound points are solved with a at the bound, to rounding.
  EXPECT_NEAR(lo, opt.min, 1e-15) << r.summary.message;
  EXPECT_NEAR(hi, opt.max, 1e-14) << r.summary.message;
  ExpectAdmissibleAwayFromSpecialPoints(model, prop, r, "omega = 0.05, a");
}

// A vanishing segment located where the points next to its root do not correct: on the
// omega-branch at a = 0.15 from omega = 0.1, an NC segment between two impacts vanishes at
// omega = 0.2555708 (GRAZING_L2, the branch stationary in omega there), and at that root its two
// events' rows coincide, so trial points within ~1e-4 of it (in arclength) fail to correct. The
// location gave up where its first trial point and the bracket's midpoint both failed, which
// hung on rounding: with the condensed solve the branch FAILED there ("could not locate or
// cross: segment 1 (NC) has duration -0.0119"). Both solves now complete with the same special
// points, each located to locate_tolerance, so within twice that of each other.
TEST(Continuation, LocatesAVanishingSegmentWhoseNeighbourhoodDoesNotCorrect) {
  DO model;
  ExactPropagator prop(model);
  // The attractor there, simulated from the reference orbit's start (trace_test's completeness
  // check starts this branch so).
  const PeriodicOrbit reference = StartOrbit(model, prop, testing::ReferenceParams());
  Params prm = reference.params;
  prm[DO::kOmega] = 0.1;
  prm[DO::kA] = 0.15;
  StatusOr<PeriodicOrbit> start = OrbitFromSimulation(model, prop, prm, reference.starts[0]);
  ASSERT_TRUE(start.ok()) << start.status().ToString();
  ASSERT_EQ(SolveOrbit(model, prop, {}, &*start).termination, Termination::kCompleted);
  ContinuationResult r[2];
  for (const bool condensed : {false, true}) {
    ContinuationOptions opt;
    opt.param = "omega";
    opt.min = 0.05, opt.max = 2.0;
    opt.steps.condensed_solve = condensed;
    r[condensed] = Continue(model, prop, *start, opt);
    EXPECT_EQ(r[condensed].summary.termination, Termination::kCompleted)
        << (condensed ? "condensed: " : "dense: ") << r[condensed].summary.message;
  }
  EXPECT_NE(Find(r[0], SpecialPointKind::kGrazingL2, 0.25557, 0.25558), nullptr);
  // A fold just before the signature's representation changes (its first segment vanishing at
  // the section, at omega = 0.2038366: no grazing), once left untested there: its multiplier at 1.
  const SpecialPoint* fold = Find(r[0], SpecialPointKind::kFold, 0.2038364, 0.2038365);
  ASSERT_NE(fold, nullptr);
  EXPECT_LE(testing::DistanceToMultiplier(fold->point.stability, 1.0), 1e-6);
  ASSERT_EQ(r[0].special_points.size(), r[1].special_points.size());
  const double tol = 2.0 * ContinuationOptions().locate_tolerance;
  for (size_t i = 0; i < r[0].special_points.size(); ++i) {
    const SpecialPoint &p = r[0].special_points[i], &q = r[1].special_points[i];
    EXPECT_EQ(p.kind, q.kind) << i;
    EXPECT_NEAR(p.point.value, q.point.value, tol) << SpecialPointKindName(p.kind);
  }
}

// Longer steps (aiming at 4 corrector iterations, as the curves' do) locate every
// special point that the default steps locate. On the a-branch at omega = 0.1 a step of 0.48 ran
// past a fold 9.8e-7 before a grazing (the turn at a = 0.1568849) and a step after a switch past
// another (a = 0.1974666): the side before the grazing never tested for folds. And a step passed
// the period doubling at a = 0.2098364 where a multiplier crossed the structural-zero threshold,
// and the doubling was tested only between points with as many multipliers.
TEST(Continuation, LongerStepsLocateEveryPointTheDefaultStepsLocate) {
  DO model;
  ExactPropagator prop(model);
  const PeriodicOrbit start = StartOrbit(model, prop, testing::ReferenceParams());
  ContinuationResult r[2];
  for (const int target : {3, 4}) {
    ContinuationOptions opt;
    opt.param = "a";
    opt.min = 0.01, opt.max = 8.0;
    opt.steps.target_iterations = target;
    r[target - 3] = Continue(model, prop, start, opt);
    ASSERT_EQ(r[target - 3].summary.termination, Termination::kCompleted)
        << r[target - 3].summary.message;
  }
  EXPECT_LT(r[1].summary.steps, r[0].summary.steps);
  EXPECT_NE(Find(r[1], SpecialPointKind::kFold, 0.156884, 0.156886), nullptr);
  EXPECT_NE(Find(r[1], SpecialPointKind::kFold, 0.197466, 0.197467), nullptr);
  EXPECT_NE(Find(r[1], SpecialPointKind::kPeriodDoubling, 0.209836, 0.209837), nullptr);
  // Each located to locate_tolerance in the parameter (a fold in arclength, tighter still).
  testing::ExpectSameSpecialPoints(r[0], "with target_iterations 3", r[1],
                                   "with target_iterations 4",
                                   2.0 * ContinuationOptions().locate_tolerance);
}

TEST(Continuation, CallbackReceivesEveryPointAndCanCancel) {
  DO model;
  ExactPropagator prop(model);
  const PeriodicOrbit start = StartOrbit(model, prop, testing::ReferenceParams());
  ContinuationOptions opt;
  opt.param = "b";
  opt.min = 0.0;
  opt.max = 0.2;
  int calls = 0;
  double last_fraction = -1.0;
  const ContinuationResult r =
      Continue(model, prop, start, opt, [&](const ContinuationPoint& p, double fraction) {
        EXPECT_GE(fraction, last_fraction);
        EXPECT_LE(fraction, 1.0);
        EXPECT_FALSE(p.measures.empty());
        last_fraction = fraction;
        return ++calls < 10;
      });
  EXPECT_EQ(calls, 10);
  EXPECT_EQ(r.summary.termination, Termination::kCancelled);
  EXPECT_EQ(r.summary.status.code(), StatusCode::kCancelled);
}

// Stability against direct simulation on the a and omega branches (as on the b branch above).
TEST(Continuation, StabilityAgreesWithSimulationOnTheAAndOmegaBranches) {
  DO model;
  ExactPropagator prop(model);
  const PeriodicOrbit start = StartOrbit(model, prop, testing::ReferenceParams());
  for (const auto& [param, lo, hi] :
       {std::make_tuple("a", 0.05, 3.0), std::make_tuple("omega", 0.03, 3.5)}) {
    ContinuationOptions opt;
    opt.param = param;
    opt.min = lo;
    opt.max = hi;
    ExpectStabilityMatchesSimulation(model, prop, Continue(model, prop, start, opt), param);
  }
}

// Continuation in the remaining parameters, xi and g, from the start orbit: completes with every
// point admissible. (g only shifts where contact happens: the orbit moves rigidly in p.)
TEST(Continuation, RunsInXiAndG) {
  DO model;
  ExactPropagator prop(model);
  const PeriodicOrbit start = StartOrbit(model, prop, testing::ReferenceParams());
  for (const auto& [param, lo, hi] :
       {std::make_tuple("xi", 0.02, 0.5), std::make_tuple("g", 0.001, 1.0)}) {
    ContinuationOptions opt;
    opt.param = param;
    opt.min = lo;
    opt.max = hi;
    const ContinuationResult r = Continue(model, prop, start, opt);
    ASSERT_EQ(r.summary.termination, Termination::kCompleted) << param << ": " << r.summary.message;
    EXPECT_GE(r.points.size(), 3u);
    ExpectAdmissibleAwayFromSpecialPoints(model, prop, r, param);
  }
}

// Stability at a grazing is each side's: on the period-2 a-branch at omega = 0.4644 (the attractor
// at a = 0.19) a CwP phase vanishes at the GRAZING_L1 near a = 0.2048239, with the branch unstable
// on both sides (|mu| 1.67 at the point before, 2.02 at the point after). The monodromy at the
// grazing itself, with its zero-length segment, has one multiplier 0.215 and called the point
// stable. The reference is the neighbouring branch points' multipliers, computed again here from
// their orbits. This grazing removes a segment, across which the multipliers are continuous, so
// each side's limit lies between the two neighbours' largest |mu|: the multipliers vary with
// the square root of the distance to the grazing (the phase's duration), so the limit is not
// close to either neighbour, but the neighbours bracket it.
TEST(Continuation, GrazingReportsTheStabilityOfBothSides) {
  DO model;
  ExactPropagator prop(model);
  Params prm = testing::ReferenceParams();
  prm[DO::kOmega] = 0.4644;
  prm[DO::kA] = 0.19;
  const PeriodicOrbit start = StartOrbit(model, prop, prm);
  ASSERT_EQ(start.signature.periods, 2);
  ContinuationOptions opt;
  opt.param = "a";
  opt.min = 0.19;
  opt.max = 0.21;
  opt.direction = ContinuationDirection::kIncreasing;
  const ContinuationResult r = Continue(model, prop, start, opt);
  const SpecialPoint* graze = Find(r, SpecialPointKind::kGrazingL1, 0.2048, 0.2049);
  ASSERT_NE(graze, nullptr) << r.summary.message;
  // The grazing point in the branch's points, and its neighbours on either side.
  size_t at = r.points.size();
  for (size_t i = 0; i < r.points.size(); ++i) {
    if (r.points[i].value == graze->point.value) at = i;
  }
  ASSERT_GT(at, 0u);
  ASSERT_LT(at + 1, r.points.size());
  const ContinuationPoint& before = r.points[at - 1];
  const ContinuationPoint& after = r.points[at + 1];
  ASSERT_LT(after.orbit.signature.segments.size(), before.orbit.signature.segments.size());
  const Stability ref_before = OrbitStability(model, prop, before.orbit);
  const Stability ref_after = OrbitStability(model, prop, after.orbit);
  ASSERT_FALSE(ref_before.multipliers.empty());
  ASSERT_FALSE(ref_after.multipliers.empty());
  const double mu_before = std::abs(ref_before.multipliers.front());
  const double mu_after = std::abs(ref_after.multipliers.front());
  ASSERT_FALSE(ref_before.stable);
  ASSERT_FALSE(ref_after.stable);

  ASSERT_TRUE(graze->before.known);
  ASSERT_TRUE(graze->after.known);
  EXPECT_EQ(graze->before.stable, ref_before.stable);
  EXPECT_EQ(graze->after.stable, ref_after.stable);
  // Unstable on both sides: never reported stable.
  EXPECT_FALSE(graze->point.stability.stable);
  EXPECT_FALSE(r.points[at].stability.stable);
  for (const double side : {graze->before.max_modulus, graze->after.max_modulus}) {
    EXPECT_GE(side, std::min(mu_before, mu_after)) << mu_before << " .. " << mu_after;
    EXPECT_LE(side, std::max(mu_before, mu_after)) << mu_before << " .. " << mu_after;
  }
  // The point's multipliers are the side before's: as many as its neighbour before, the largest
  // as large as that side's limit.
  ASSERT_EQ(graze->point.stability.multipliers.size(), ref_before.multipliers.size());
  EXPECT_DOUBLE_EQ(std::abs(graze->point.stability.multipliers.front()), graze->before.max_modulus);
}

}  // namespace
}  // namespace drillbif
