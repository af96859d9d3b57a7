// What the trace's last pass (EndsAtFlipGrazings, trace_internal.h) reports next to a period-1
// flip-grazing, where the period-2 orbit becomes the period-1 orbit traversed twice. From the
// period-1 PD curve through the omega-branch's doubling at omega = 1.6258 (a = 0.3), which ends at
// the flip-grazings (1.3946, 6.7289) and (0.4734, 0.1616) of the reference box, and the period-2
// grazing curves leaving them (GrazingCurvesAtFlipGrazings): each entry's kind is the one its
// curve's message names, each entry lies within its bracket of the point it says it is, and each
// point is reported once.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <vector>

#include "drillbif/flow/exact_propagator.h"
#include "problems/reference_box.h"
#include "support/multipliers.h"
#include "support/pd_curve_to_flip_grazings.h"
#include "support/tangent_end.h"
#include "trace_internal.h"

namespace drillbif::internal {
namespace {

class FlipGrazingEntries : public ::testing::Test {
 protected:
  void SetUp() override {
    opt_ = testing::ReferenceBox();
    opt_.max_period = 2;
    // The shorter steps (target_iterations 3): with them a step of the period-2 grazing curve
    // next to its end at (0.4734, 0.1616) straddles the det(M - I) root that the last pass must
    // report as the flip-grazing (RootOfDetNextToTheEndIsTheFlipGrazing); the default longer
    // steps end the curve with no step across it, and nothing of that pass would be tested.
    opt_.curve.steps.target_iterations = 3;
    TracedCurve pd_curve;
    ASSERT_TRUE(testing::PdCurveToFlipGrazings(model_, prop_, opt_, &pd_curve));
    pd_curve.outline = OutlineOf(pd_curve.curve);
    result_.curves.push_back(std::move(pd_curve));
    ASSERT_TRUE(GrazingCurvesAtFlipGrazings(
        model_, prop_, opt_, [](double) { return true; }, 0, &result_));
    ASSERT_GE(result_.curves.size(), 3u);
    w1_ = opt_.width1(), w2_ = opt_.width2();
  }

  // Box-scaled distance of two entries' parameters.
  double Distance(const Codim2Point& a, const Codim2Point& b) const {
    return std::hypot((a.point.value1 - b.point.value1) / w1_,
                      (a.point.value2 - b.point.value2) / w2_);
  }

  // The PD curve's located FLIP_GRAZING nearest to the entry.
  const Codim2Point& NearestFlip(const Codim2Point& z) const {
    const Codim2Point* nearest = nullptr;
    for (const Codim2Point& q : result_.curves[0].curve.codim2) {
      if (q.kind == Codim2Kind::kFlipGrazing &&
          (nearest == nullptr || Distance(q, z) < Distance(*nearest, z))) {
        nearest = &q;
      }
    }
    return *nearest;
  }

  DriftingOscillator model_;
  ExactPropagator prop_{model_};
  TraceOptions opt_;
  TraceResult result_;
  double w1_ = 1.0, w2_ = 1.0;
};

// A period-2 curve ending where its orbit becomes the period-1 orbit traversed twice is reported
// as ending at that FLIP_GRAZING: its message says so, with the entry's detail. The kind is
// re-derived from the reported orbit: period 1, a multiplier -1 (the located point's 1e-8) and
// h = h' = 0 at its tangent end (the corrector's 1e-10 on O(1)-Lipschitz guards: 1e-9).
TEST_F(FlipGrazingEntries, CurveMessageNamesTheKindOfEachEnd) {
  EndsAtFlipGrazings(model_, opt_, &result_);
  int flip_ends = 0;
  for (const TracedCurve& t : result_.curves) {
    for (const Codim2Point& z : t.curve.codim2) {
      if (z.violation.admissible) continue;  // a root along the curve, not one of its ends
      const std::string text =
          std::string("ended at a ") + Codim2KindName(z.kind) + " point: " + z.detail;
      EXPECT_NE(t.curve.summary.message.find(text), std::string::npos)
          << t.curve.summary.message << "\n  entry: " << text;
      if (z.kind != Codim2Kind::kFlipGrazing || t.curve.kind != CurveKind::kGrazing) continue;
      ++flip_ends;
      EXPECT_EQ(z.point.orbit.signature.periods, 1);
      EXPECT_LE(testing::DistanceToMultiplier(z.point.stability, -1.0), 1e-8);
      const std::optional<GuardValue> g = testing::TangentEndGuard(model_, prop_, z.point.orbit);
      ASSERT_TRUE(g.has_value());
      EXPECT_LE(std::abs(g->h), 1e-9);
      EXPECT_LE(std::abs(g->dh), 1e-9);
    }
  }
  EXPECT_EQ(flip_ends, 2);  // one period-2 grazing curve leaves each flip-grazing
}

// A root of det(M - I) on a period-2 grazing curve next to its end at the flip-grazing
// (0.4734, 0.1616) is no period-2 fold-grazing: it lies within the end's bracket of the end or,
// where the end is solved to a bracket narrower than the root's own accuracy, within 3e-7
// (box-scaled: EndsAtFlipGrazings' kIndistinct) of the flip-grazing nearest the end. The end is
// the flip-grazing (above), and there the period-2 orbit is the period-1 orbit traversed twice,
// whose multiplier -1 squared is the +1 the root found. Its multipliers are the squares of the
// flip-grazing's (checked to 1e-4, an O(1) constant times the passes' split there, which
// simulation puts at 4e-5). It is reported as the flip-grazing, with a detail saying why.
TEST_F(FlipGrazingEntries, RootOfDetNextToTheEndIsTheFlipGrazing) {
  struct Root {
    size_t curve, index;
  };
  std::vector<Root> roots;
  for (size_t c = 1; c < result_.curves.size(); ++c) {
    const std::vector<Codim2Point>& codim2 = result_.curves[c].curve.codim2;
    for (size_t i = 0; i < codim2.size(); ++i) {
      const Codim2Point& z = codim2[i];
      if (z.kind != Codim2Kind::kFoldGrazing || !z.violation.admissible) continue;
      for (const Codim2Point& e : codim2) {
        if (e.violation.admissible) continue;
        const bool in_bracket = std::hypot(z.point.value1 - e.point.value1,
                                           z.point.value2 - e.point.value2) <= e.bracket;
        if (!in_bracket && Distance(z, NearestFlip(e)) > 3e-7) continue;
        roots.push_back({c, i});
        const Codim2Point& flip = NearestFlip(e);
        const std::vector<std::complex<double>>& mu2 = z.point.stability.multipliers;
        for (const std::complex<double>& mu1 : flip.point.stability.multipliers) {
          double closest = 1e300;
          for (const std::complex<double>& m : mu2)
            closest = std::min(closest, std::abs(m - mu1 * mu1));
          EXPECT_LE(closest, 1e-4) << "multiplier " << mu1 << " squared";
        }
        break;
      }
    }
  }
  ASSERT_FALSE(roots.empty()) << "no det(M - I) root next to its end";
  EndsAtFlipGrazings(model_, opt_, &result_);
  for (const Root& r : roots) {
    const Codim2Point& z = result_.curves[r.curve].curve.codim2[r.index];
    EXPECT_EQ(z.kind, Codim2Kind::kFlipGrazing);
    EXPECT_EQ(z.point.orbit.signature.periods, 1);
    EXPECT_EQ(Distance(z, NearestFlip(z)), 0.0);
    EXPECT_NE(z.detail.find("orbit traversed twice"), std::string::npos) << z.detail;
  }
}

// A switched curve that makes no step either way (as from a point next to the period-1 orbit
// traversed twice, where the period-2 system is singular) ends at its start in both directions,
// each end bisected to ~1e-11 in arclength from the start. That bracket says where the curve's
// boundary lies from the start, not where the point is: the ends are reported as the point the
// curve leaves. Made here from the period-2 grazing curve ending at (0.4734, 0.1616): a curve
// leaving that end whose one vertex is the end's last admissible orbit. Each of its entries must
// lie within its bracket (arclength, parameters included) of the point it leaves.
TEST_F(FlipGrazingEntries, EndsOfACurveWithoutStepsAreThePointItLeaves) {
  int from = -1, end = -1;
  for (size_t c = 1; c < result_.curves.size() && from < 0; ++c) {
    const std::vector<Codim2Point>& codim2 = result_.curves[c].curve.codim2;
    for (size_t i = 0; i < codim2.size(); ++i) {
      if (!codim2[i].violation.admissible && codim2[i].bracket > 1e-8 &&
          Distance(codim2[i], NearestFlip(codim2[i])) <= 1e-4) {
        from = static_cast<int>(c), end = static_cast<int>(i);
      }
    }
  }
  ASSERT_GE(from, 0);
  const Codim2Point left = result_.curves[from].curve.codim2[end];
  TracedCurve one;
  one.from_curve = from, one.from_codim2 = end;
  one.curve.kind = CurveKind::kGrazing;
  one.curve.points.push_back(left.point);
  Codim2Point z = left;
  z.kind = Codim2Kind::kDoubleGrazing;
  z.bracket = 1e-12 * (1.0 + 8.3);  // a bisection converged to rounding at |y| ~ 8
  one.curve.codim2 = {z, z};
  const std::string text = std::string("ended at a DOUBLE_GRAZING point: ") + z.detail;
  one.curve.summary.message = "increasing a: " + text + "; decreasing a: " + text;
  result_.curves.push_back(one);
  EndsAtFlipGrazings(model_, opt_, &result_);
  const TracedCurve& after = result_.curves.back();
  const Codim2Point& reference = result_.curves[from].curve.codim2[end];  // merged by the pass
  for (const Codim2Point& q : after.curve.codim2) {
    EXPECT_LE(std::hypot(q.point.value1 - reference.point.value1,
                         q.point.value2 - reference.point.value2),
              q.bracket)
        << Codim2KindName(q.kind) << " at (" << q.point.value1 << ", " << q.point.value2
        << ") claims " << q.bracket;
    EXPECT_EQ(q.kind, reference.kind);
    EXPECT_NE(after.curve.summary.message.find(std::string("ended at a ") + Codim2KindName(q.kind) +
                                               " point: " + q.detail),
              std::string::npos)
        << after.curve.summary.message;
  }
}

// The flip-grazing (0.4734, 0.1616) is the PD curve's end, and the period-2 grazing curve's end
// and root next to it are reported as it: one point, met from two curves, reported once, by the
// first curve; the others refer to it. Checked over all entries: no two reported ones of one
// kind and period lie within 1e-9 of the box, and each referring one lies within 1e-9 of the
// entry it names, of its kind and period, on an earlier curve or earlier in the same list.
TEST_F(FlipGrazingEntries, EachPointIsReportedOnce) {
  EndsAtFlipGrazings(model_, opt_, &result_);
  std::vector<const Codim2Point*> reported;
  int referring = 0;
  for (size_t c = 0; c < result_.curves.size(); ++c) {
    const std::vector<Codim2Point>& codim2 = result_.curves[c].curve.codim2;
    for (size_t i = 0; i < codim2.size(); ++i) {
      const Codim2Point& z = codim2[i];
      if (z.same_as_curve < 0) {
        for (const Codim2Point* r : reported) {
          EXPECT_FALSE(r->kind == z.kind &&
                       r->point.orbit.signature.periods == z.point.orbit.signature.periods &&
                       Distance(*r, z) <= 1e-9)
              << Codim2KindName(z.kind) << " at (" << z.point.value1 << ", " << z.point.value2
              << ") reported twice";
        }
        reported.push_back(&z);
        continue;
      }
      ++referring;
      ASSERT_TRUE(
          z.same_as_curve < static_cast<int>(c) ||
          (z.same_as_curve == static_cast<int>(c) && z.same_as_index < static_cast<int>(i)));
      const Codim2Point& r = result_.curves[z.same_as_curve].curve.codim2[z.same_as_index];
      EXPECT_LT(r.same_as_curve, 0);
      EXPECT_EQ(r.kind, z.kind);
      EXPECT_EQ(r.point.orbit.signature.periods, z.point.orbit.signature.periods);
      EXPECT_LE(Distance(r, z), 1e-9);
    }
  }
  // The two merged ends and the root next to one of them.
  EXPECT_GE(referring, 3);
}

}  // namespace
}  // namespace drillbif::internal
