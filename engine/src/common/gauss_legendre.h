// Composite Gauss-Legendre quadrature on [0, t] with equal panels no longer than `max_panel`.
// Ten nodes per panel integrate polynomials of degree 19 exactly; for the smooth (entire)
// integrands of linear modes, panels shorter than their time scale give errors near rounding.
#ifndef DRILLBIF_COMMON_GAUSS_LEGENDRE_H_
#define DRILLBIF_COMMON_GAUSS_LEGENDRE_H_

#include <algorithm>
#include <cmath>

namespace drillbif::internal {

// Nodes on [-1, 1] (positive half) and weights of the 10-point rule (Abramowitz & Stegun 25.4.30).
inline constexpr double kGl10Nodes[5] = {0.1488743389816312108848260, 0.4333953941292471907992659,
                                         0.6794095682990244062343274, 0.8650633666889845107320967,
                                         0.9739065285171717200779640};
inline constexpr double kGl10Weights[5] = {0.2955242247147528701738930, 0.2692667193099963550912269,
                                           0.2190863625159820439955349, 0.1494513491505805931457763,
                                           0.0666713443086881375935688};

// Integral of f over [0, t]; f(tau) returns a value supporting + and * by double (double or an
// Eigen vector). `zero` is the additive identity of that type.
template <typename F, typename V>
V IntegrateGaussLegendre(const F& f, double t, double max_panel, V zero) {
  if (!(t > 0.0)) return zero;
  const int panels = std::max(1, static_cast<int>(std::ceil(t / max_panel)));
  const double width = t / panels;
  const double half = 0.5 * width;
  V sum = zero;
  for (int k = 0; k < panels; ++k) {
    const double mid = (k + 0.5) * width;
    for (int i = 0; i < 5; ++i) {
      const double d = half * kGl10Nodes[i];
      sum = sum + (f(mid - d) + f(mid + d)) * (kGl10Weights[i] * half);
    }
  }
  return sum;
}

}  // namespace drillbif::internal

#endif  // DRILLBIF_COMMON_GAUSS_LEGENDRE_H_
