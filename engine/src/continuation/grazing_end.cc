#include "continuation/grazing_end.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <vector>

#include "continuation/bordered_sigma.h"
#include "continuation/tangent_grazing.h"
#include "orbit/orbit_bvp.h"

namespace drillbif::internal {

StatusOr<PeriodicOrbit> SolveGrazingEnd(const HybridModel& model, Propagator& propagator,
                                        const PeriodicOrbit& guess, CurveKind kind, int index1,
                                        int index2, double tolerance) {
  const int tangents = static_cast<int>(TangentEndRates(model, propagator, guess).size());
  const int wanted = kind == CurveKind::kGrazing ? 2 : 1;
  if (tangents != wanted) {
    return InvalidArgument("the end of a " + std::string(CurveKindName(kind)) + " curve needs " +
                           std::to_string(wanted) + " tangent ends, the guess has " +
                           std::to_string(tangents));
  }
  const OrbitBvp bvp(model, propagator, guess.signature, index1, index2);
  const int m = bvp.size(), n = m + 2;
  Params params = guess.params;
  Eigen::VectorXd y(n);
  y.head(m) = bvp.Pack(guess);
  y[m] = params[index1];
  y[m + 1] = params[index2];
  auto unpack = [&](const Eigen::VectorXd& yy) {
    Params p = params;
    p[index1] = yy[m];
    p[index2] = yy[m + 1];
    PeriodicOrbit o;
    bvp.Unpack(yy.head(m), p, &o);
    return o;
  };
  BorderedSigma sigma;
  if (kind != CurveKind::kGrazing) {
    sigma =
        BorderedSigma(ShiftedMonodromy(kind, OrbitStability(model, propagator, guess).monodromy));
  }
  // The two conditions besides G, as functions of (X, lambda1, lambda2).
  auto conditions = [&](const Eigen::VectorXd& yy) {
    const PeriodicOrbit o = unpack(yy);
    const std::vector<double> rates = TangentEndRates(model, propagator, o);
    if (kind == CurveKind::kGrazing) return Eigen::Vector2d(rates[0], rates[1]);
    const double s = sigma(ShiftedMonodromy(kind, OrbitStability(model, propagator, o).monodromy));
    return Eigen::Vector2d(rates[0], s);
  };
  Eigen::VectorXd g, gp1, gp2, f(n);
  Eigen::MatrixXd gx, jac(n, n);
  for (int it = 0; it < 30; ++it) {
    params[index1] = y[m];
    params[index2] = y[m + 1];
    if (!model.ValidateParams(params).ok()) return Internal("left the parameter domain");
    if (Status s = bvp.Evaluate(y.head(m), params, &g, &gx, &gp1, &gp2); !s.ok()) return s;
    const Eigen::Vector2d c0 = conditions(y);
    f.head(m) = g;
    f.tail(2) = c0;
    jac.setZero();
    jac.topLeftCorner(m, m) = gx;
    jac.col(m).head(m) = gp1;
    jac.col(m + 1).head(m) = gp2;
    // Forward differences of the two conditions: truncation h |c''| / 2 and rounding
    // eps |c| / h, both ~1e-8 with h = 1.5e-8 (1 + |y_j|); they only steer Newton, the residual
    // is exact.
    for (int j = 0; j < n; ++j) {
      const double h = 1.5e-8 * (1.0 + std::abs(y[j]));
      Eigen::VectorXd yp = y;
      yp[j] += h;
      jac.block(m, j, 2, 1) = (conditions(yp) - c0) / h;
    }
    if (!f.allFinite() || !jac.allFinite()) return Internal("non-finite residual or Jacobian");
    const Eigen::VectorXd step = jac.partialPivLu().solve(-f);
    if (!step.allFinite()) return Internal("singular codimension-2 system");
    y += step;
    if (step.lpNorm<Eigen::Infinity>() <= tolerance * (1.0 + y.lpNorm<Eigen::Infinity>())) {
      return unpack(y);
    }
  }
  return Internal("the codimension-2 system did not converge");
}

}  // namespace drillbif::internal
