#include "problems/grazing.h"

#include <cmath>

namespace drillbif::testing {

double GuardMinimum(const DriftingOscillator& model, int mode, int guard, const Params& params,
                    const StateVector& x0, double t_guess, double* t_min) {
  double t = t_guess;
  StateVector x;
  for (int k = 0; k < 100; ++k) {
    model.Flow(mode, x0, t, params, &x, nullptr);
    const GuardValue g = model.Guard(mode, guard, x, params);
    const double step = g.dh / g.ddh;
    t -= step;
    if (std::abs(step) < 1e-15 * std::max(1.0, t)) break;
  }
  model.Flow(mode, x0, t, params, &x, nullptr);
  *t_min = t;
  return model.Guard(mode, guard, x, params).h;
}

namespace {

// Adjusts component `k` of c->x0 by secant iteration until the guard's minimum equals depth.
void Tune(const DriftingOscillator& model, GrazingCase* c, int k, double depth) {
  double t = c->t_touch;
  auto f = [&](double v) {
    StateVector x0 = c->x0;
    x0[k] = v;
    return GuardMinimum(model, c->mode, c->guard, c->params, x0, t, &t) - depth;
  };
  double v0 = c->x0[k], v1 = v0 * (1.0 + 1e-3) + 1e-6;
  double f0 = f(v0), f1 = f(v1);
  for (int it = 0; it < 60 && f1 != 0.0 && f1 != f0; ++it) {
    const double v2 = v1 - f1 * (v1 - v0) / (f1 - f0);
    v0 = v1, f0 = f1, v1 = v2, f1 = f(v1);
    if (std::abs(f1) < 1e-17) break;
  }
  c->x0[k] = v1;
  GuardMinimum(model, c->mode, c->guard, c->params, c->x0, t, &c->t_touch);
}

}  // namespace

GrazingCase GrazeImpact(double depth) {
  DriftingOscillator model;
  GrazingCase c;
  c.mode = DriftingOscillator::kNoContact;
  c.guard = DriftingOscillator::kImpact;
  c.params = DriftingOscillator::MakeParams();
  // Near s = pi the forcing pulls the bit back (a cos + b = -0.15): launched upwards at 0.05, it
  // rises for about 1/3 time unit and turns back. q = 0 stays 0 in free flight.
  c.x0 = StateVector::Zero(4);
  c.x0 << 0.0, 0.05, 0.0, M_PI - 0.2;
  double t;
  const double h_min = GuardMinimum(model, c.mode, c.guard, c.params, c.x0, 0.3, &t);
  // h = q + g - p is shifted exactly by -dp0 (p is p0 plus a function of the other components).
  c.x0[DriftingOscillator::kP] += h_min - depth;
  GuardMinimum(model, c.mode, c.guard, c.params, c.x0, t, &c.t_touch);
  c.t_end = c.t_touch + 0.3;
  return c;
}

namespace {

// A contact phase (CwoP) from (q0, y0) whose guard `guard` has its minimum near t_guess, tuned by
// the initial velocity to reach `depth`.
GrazingCase GrazeInContact(int guard, double q0, double y0, double t_guess, double depth) {
  DriftingOscillator model;
  GrazingCase c;
  c.mode = DriftingOscillator::kContact;
  c.guard = guard;
  c.params = DriftingOscillator::MakeParams();
  c.x0 = StateVector::Zero(4);
  c.x0 << q0 + c.params[DriftingOscillator::kG], y0, q0, 0.0;
  GuardMinimum(model, c.mode, c.guard, c.params, c.x0, t_guess, &c.t_touch);
  Tune(model, &c, DriftingOscillator::kY, depth);
  c.t_end = c.t_touch + 0.5;
  return c;
}

}  // namespace

// In contact q oscillates about b with unit frequency: from q = 0.5 moving up at 0.77 the force
// peaks near 1 after about a quarter period.
GrazingCase GrazeProgression(double depth) {
  return GrazeInContact(DriftingOscillator::kProgressionStart, 0.5, 0.77, 0.8, depth);
}

// From q = 0.15 moving down at 0.15 the force dips near 0 after about a quarter period.
GrazingCase GrazeSeparation(double depth) {
  return GrazeInContact(DriftingOscillator::kSeparation, 0.15, -0.15, 1.2, depth);
}

}  // namespace drillbif::testing
