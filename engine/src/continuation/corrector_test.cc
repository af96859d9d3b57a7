// PseudoArclengthCorrector on small analytic systems whose solution curves are known: what each
// of its options changes, and what it leaves alone. (Bit-identity with the tracers' results is
// the trace's: bench/trace_network before and after a change to the corrector.)
#include "corrector.h"

#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <functional>
#include <limits>

#include "arclength.h"

namespace drillbif::internal {
namespace {

using Vec = Eigen::VectorXd;
using Mat = Eigen::MatrixXd;

// F: R^n -> R^(n-1) from a function, counting its evaluations; Valid and Stopped as set.
class FunctionSystem : public CorrectorSystem {
 public:
  using Function = std::function<void(const Vec& y, Vec* f, Mat* jac)>;
  explicit FunctionSystem(Function f) : f_(std::move(f)) {}

  bool EvaluateInto(const Vec& y, Vec* f, Eigen::Ref<Mat>* jac) const override {
    ++evaluations;
    if (jac == nullptr) {
      f_(y, f, nullptr);
    } else {
      ++jacobians;
      Mat j;
      f_(y, f, &j);
      *jac = j;
    }
    return f->allFinite();
  }
  bool Stopped() const override { return stopped; }
  bool Valid(const Vec& y) const override { return y[0] <= valid_below; }
  int Segments() const override { return 1; }
  int Block() const override { return 1; }

  mutable int evaluations = 0, jacobians = 0;
  bool stopped = false;
  double valid_below = std::numeric_limits<double>::infinity();

 private:
  Function f_;
};

// The unit circle x^2 + y^2 = 1, with its exact Jacobian.
void Circle(const Vec& y, Vec* f, Mat* jac) {
  f->resize(1);
  (*f)[0] = y.squaredNorm() - 1.0;
  if (jac) *jac = 2.0 * y.transpose();
}

// Two equations in (x, y, z): z = x (exact row) and the condition c = k (x^2 + y^2 - 1) = 0 with
// k = 1e4, steep as a curve's condition next to a vanishing segment, its Jacobian row 0.9 of the
// true one (as an approximated row): Newton on it contracts only linearly, the error by
// 1 - 1 / 0.9 = -0.11 per step, so that the residual 2 k |x error| is still far above 1e-11 where
// the step passes 1e-11.
void SteepCondition(const Vec& y, Vec* f, Mat* jac) {
  constexpr double k = 1e4;
  f->resize(2);
  (*f)[0] = y[2] - y[0];
  (*f)[1] = k * (y[0] * y[0] + y[1] * y[1] - 1.0);
  if (!jac) return;
  jac->setZero(2, 3);
  (*jac)(0, 0) = -1.0;
  (*jac)(0, 2) = 1.0;
  (*jac)(1, 0) = 0.9 * k * 2.0 * y[0];
  (*jac)(1, 1) = 0.9 * k * 2.0 * y[1];
}

CorrectorOptions Defaults() {
  CorrectorOptions o;
  o.max_iterations = 20;
  o.tolerance = 1e-11;
  return o;
}

TEST(PseudoArclengthCorrector, LandsOnTheCurveInTheHyperplaneThroughThePrediction) {
  FunctionSystem system(Circle);
  PseudoArclengthCorrector corrector(system, CondensedMode::kDense);
  const Vec pred = Vec::Map(std::array<double, 2>{1.1, 0.3}.data(), 2);
  const Vec dir = Vec::Map(std::array<double, 2>{0.0, 1.0}.data(), 2);
  Vec y, t;
  int iterations = 0;
  ASSERT_TRUE(corrector.Correct(Defaults(), pred, dir, &y, &iterations, &t));
  // On the circle to the step tolerance (the last step 1e-11 at most, so |F| ~ 2 |y| 1e-11), in
  // the hyperplane y_2 = 0.3 to rounding: (sqrt(1 - 0.09), 0.3).
  EXPECT_NEAR(y[0], std::sqrt(1.0 - 0.09), 1e-10);
  EXPECT_NEAR(y[1], 0.3, 1e-15);
  EXPECT_GT(iterations, 1);
  EXPECT_LE(iterations, 8);
  EXPECT_EQ(corrector.steps(), system.jacobians);
  // The tangent: orthogonal to the gradient (to the step tolerance: it is the last
  // factorization's, one step before the result), unit, on dir's side.
  EXPECT_NEAR(t.norm(), 1.0, 1e-15);
  EXPECT_NEAR(t.dot(y) / y.norm(), 0.0, 1e-9);
  EXPECT_GT(t.dot(dir), 0.0);
  // And internal::UnitTangent's at the result, to that accuracy.
  Vec f, unit;
  Mat jac;
  Circle(y, &f, &jac);
  ASSERT_TRUE(UnitTangent(jac, dir, &unit));
  EXPECT_LT((t - unit).norm(), 1e-9);
}

TEST(PseudoArclengthCorrector, TangentFollowsTheDirectionItIsOrientedAlong) {
  FunctionSystem system(Circle);
  PseudoArclengthCorrector corrector(system, CondensedMode::kDense);
  const Vec pred = Vec::Map(std::array<double, 2>{0.9, 0.5}.data(), 2);
  const Vec up = Vec::Map(std::array<double, 2>{-0.3, 1.0}.data(), 2);
  Vec y_up, t_up, y_down, t_down;
  int iterations = 0;
  ASSERT_TRUE(corrector.Correct(Defaults(), pred, up, &y_up, &iterations, &t_up));
  ASSERT_TRUE(corrector.Correct(Defaults(), pred, -up, &y_down, &iterations, &t_down));
  EXPECT_LT((y_up - y_down).norm(), 1e-12);  // the same hyperplane either way
  EXPECT_GT(t_up.dot(up), 0.0);
  EXPECT_GT(t_down.dot(-up), 0.0);
  EXPECT_LT((t_up + t_down).norm(), 1e-9);
}

TEST(PseudoArclengthCorrector, ContractionTestSavesTheConfirmingEvaluationButCountsIt) {
  const Vec pred = Vec::Map(std::array<double, 2>{1.1, 0.3}.data(), 2);
  const Vec dir = Vec::Map(std::array<double, 2>{0.0, 1.0}.data(), 2);
  FunctionSystem plain_system(Circle), contraction_system(Circle);
  PseudoArclengthCorrector plain(plain_system, CondensedMode::kDense);
  PseudoArclengthCorrector contraction(contraction_system, CondensedMode::kDense);
  CorrectorOptions with = Defaults();
  with.contraction_test = true;
  Vec y_plain, y_contraction;
  int it_plain = 0, it_contraction = 0;
  ASSERT_TRUE(plain.Correct(Defaults(), pred, dir, &y_plain, &it_plain));
  ASSERT_TRUE(contraction.Correct(with, pred, dir, &y_contraction, &it_contraction));
  // Newton's quadratic contraction bounds the last step by far less than the tolerance one
  // iteration earlier: one evaluation fewer, the same count reported, the point within the
  // tolerance of the confirmed one.
  EXPECT_EQ(it_contraction, it_plain);
  EXPECT_EQ(contraction_system.evaluations, plain_system.evaluations - 1);
  EXPECT_LT((y_plain - y_contraction).lpNorm<Eigen::Infinity>(), 2e-11);
}

TEST(PseudoArclengthCorrector, SettlingTheConditionLowersItsResidualAtTheSameIterationCount) {
  const Vec pred = Vec::Map(std::array<double, 3>{0.95, 0.3, 0.95}.data(), 3);
  const Vec dir = Vec::Map(std::array<double, 3>{0.0, 1.0, 0.0}.data(), 3);
  FunctionSystem step_system(SteepCondition), settled_system(SteepCondition);
  PseudoArclengthCorrector step_only(step_system, CondensedMode::kDense);
  PseudoArclengthCorrector settled(settled_system, CondensedMode::kDense);
  CorrectorOptions settle = Defaults();
  settle.condition_tolerance = 1e-11;
  Vec y_step, y_settled, f;
  int it_step = 0, it_settled = 0;
  ASSERT_TRUE(step_only.Correct(Defaults(), pred, dir, &y_step, &it_step));
  ASSERT_TRUE(settled.Correct(settle, pred, dir, &y_settled, &it_settled));
  SteepCondition(y_step, &f, nullptr);
  const double step_residual = std::abs(f[1]);
  SteepCondition(y_settled, &f, nullptr);
  const double settled_residual = std::abs(f[1]);
  // At the step's convergence the error is ~0.1 of the last step (~1e-11), so the residual
  // 2 k |x| error ~2e-8; each chord step divides it by ~9, down to 1e-11 or rounding's floor
  // (k eps ~ 2e-12).
  EXPECT_GT(step_residual, 1e-9);
  EXPECT_LT(settled_residual, 1e-10);
  EXPECT_EQ(it_settled, it_step);
  // The chord steps evaluate the residual alone.
  EXPECT_EQ(settled_system.jacobians, step_system.jacobians);
  EXPECT_GT(settled_system.evaluations, step_system.evaluations);
}

TEST(PseudoArclengthCorrector, ChordIterationsReuseTheLastFactorizationNearItsPoint) {
  FunctionSystem system(Circle);
  PseudoArclengthCorrector corrector(system, CondensedMode::kDense);
  const Vec dir = Vec::Map(std::array<double, 2>{0.0, 1.0}.data(), 2);
  auto at = [](double x, double y) {
    Vec v(2);
    v << x, y;
    return v;
  };
  Vec y;
  int iterations = 0;
  // No factorization yet: nothing to iterate with.
  EXPECT_FALSE(corrector.CorrectChord(Defaults(), at(1.0, 0.2), dir, &y, &iterations));
  EXPECT_EQ(system.evaluations, 0);
  ASSERT_TRUE(corrector.Correct(Defaults(), at(1.1, 0.1), dir, &y, &iterations));
  const int jacobians = system.jacobians;
  // In the hyperplane y_2 = 0.2 the point is (sqrt(0.96), 0.2). With the factorization's row
  // (2 x_f, 2 y_f), x_f ~ sqrt(0.99), the error contracts by 1 - (x + x*) / (2 x_f) per step,
  // ~0.015 near the solution: converged to the step tolerance, 1e-11 (1 + |y|_inf) < 2e-11 (the
  // contraction bounds the steps still to come by that), without a Jacobian.
  ASSERT_TRUE(corrector.CorrectChord(Defaults(), at(1.0, 0.2), dir, &y, &iterations));
  EXPECT_NEAR(y[0], std::sqrt(0.96), 2e-11);
  EXPECT_NEAR(y[1], 0.2, 1e-15);
  EXPECT_EQ(system.jacobians, jacobians);
  EXPECT_GE(iterations, 2);
  // At y_2 = 0.99 (x* = sqrt(0.0199) ~ 0.14) the contraction tends to 1 - x* / x_f ~ 0.86: the
  // chord iterations give up rather than crawl.
  EXPECT_FALSE(corrector.CorrectChord(Defaults(), at(1.0, 0.99), dir, &y, &iterations));
  EXPECT_EQ(system.jacobians, jacobians);
}

TEST(PseudoArclengthCorrector, FailsWhereTheResultIsNotValidOrAStopIsSeen) {
  FunctionSystem system(Circle);
  PseudoArclengthCorrector corrector(system, CondensedMode::kDense);
  const Vec pred = Vec::Map(std::array<double, 2>{1.1, 0.3}.data(), 2);
  const Vec dir = Vec::Map(std::array<double, 2>{0.0, 1.0}.data(), 2);
  Vec y;
  int iterations = 0;
  CorrectorOptions validate = Defaults();
  validate.validate_result = true;
  system.valid_below = 0.9;  // the result's x is 0.954
  EXPECT_FALSE(corrector.Correct(validate, pred, dir, &y, &iterations));
  EXPECT_TRUE(corrector.Correct(Defaults(), pred, dir, &y, &iterations));
  system.valid_below = 1.0;
  EXPECT_TRUE(corrector.Correct(validate, pred, dir, &y, &iterations));
  system.stopped = true;
  system.evaluations = 0;
  EXPECT_FALSE(corrector.Correct(Defaults(), pred, dir, &y, &iterations));
  EXPECT_EQ(system.evaluations, 0);
}

TEST(PseudoArclengthCorrector, FailsWithinMaxIterationsWhereNewtonCannotConverge) {
  // x^2 + y^2 = -1 has no real point: the iterates wander and never pass the step test.
  FunctionSystem system([](const Vec& y, Vec* f, Mat* jac) {
    Circle(y, f, jac);
    (*f)[0] += 2.0;
  });
  PseudoArclengthCorrector corrector(system, CondensedMode::kDense);
  const Vec pred = Vec::Map(std::array<double, 2>{1.0, 0.3}.data(), 2);
  const Vec dir = Vec::Map(std::array<double, 2>{0.0, 1.0}.data(), 2);
  Vec y;
  int iterations = 0;
  CorrectorOptions options = Defaults();
  options.max_iterations = 8;
  EXPECT_FALSE(corrector.Correct(options, pred, dir, &y, &iterations));
  EXPECT_EQ(system.jacobians, 8);
}

}  // namespace
}  // namespace drillbif::internal
