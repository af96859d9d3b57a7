// Safe-step event location on synthetic guards: a touch of the surface inside the tolerance band is
// an event wherever the steps happen to end, and the lower bound that lets a step skip a minimum's
// polish holds.
#include "flow/safe_event_locator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

#include "drillbif/model/drifting_oscillator.h"

namespace drillbif::internal {
namespace {

using DO = DriftingOscillator;

// The free-flight mode has one guard (the impact); its h here is c (t - 1)^2 + depth, a parabola
// with its minimum `depth` at t = 1, and its curvature 2 c, `loose` times, as its bound.
struct Parabola {
  double c = 1.0;
  double depth = 0.0;
  double loose = 1.0;  // the curvature bound over the curvature
  void operator()(double t, SegmentPoint* p) const {
    p->x = StateVector::Zero(4);
    p->guards[0].h = c * (t - 1.0) * (t - 1.0) + depth;
    p->guards[0].dh = 2.0 * c * (t - 1.0);
    p->guards[0].ddh = 2.0 * c;
    p->bounds[0] = 2.0 * c * loose;
  }
};

LocatedEvent Locate(const Parabola& h, double t_max) {
  DO model;
  EventOptions opt;
  return LocateFirstEvent(model, DO::kNoContact, t_max, opt, h, [] { return true; });
}

// Near a minimum the safe steps span about sqrt(2 depth / bound) each, so that a step that
// straddles a minimum `depth` deep often ends outside the 1e-12 band (for depth 0.9e-12, in half
// of these parabolas): a step's end alone would not see the touch. Each touch is an event,
// tangential, at the minimum (located by Newton on h', linear here, to the polishing's 1e-14),
// whatever the curvature and however loose its bound.
TEST(SafeEventLocator, ReportsATouchInsideTheBandWhereverTheStepsEnd) {
  for (const double loose : {1.0, 1.3, 2.0, 5.0}) {
    for (const double c : {1e-4, 1e-2, 1.0, 1e2}) {
      for (const double depth : {0.2e-12, 0.5e-12, 0.9e-12}) {
        const LocatedEvent ev = Locate(Parabola{.c = c, .depth = depth, .loose = loose}, 2.0);
        const std::string where = "c " + std::to_string(c) + ", depth " + std::to_string(depth) +
                                  ", bound x " + std::to_string(loose);
        ASSERT_EQ(ev.end, AdvanceEnd::kEvent) << where;
        EXPECT_EQ(ev.guard, 0) << where;
        EXPECT_TRUE(ev.tangential) << where;
        EXPECT_NEAR(ev.t, 1.0, 1e-13) << where;
      }
    }
  }
}

// A minimum just above the band is a near miss: no event, up to t_max.
TEST(SafeEventLocator, IgnoresAMinimumAboveTheBand) {
  for (const double loose : {1.0, 1.3, 2.0, 5.0}) {
    for (const double c : {1e-4, 1e-2, 1.0, 1e2}) {
      const LocatedEvent ev = Locate(Parabola{.c = c, .depth = 1.1e-12, .loose = loose}, 2.0);
      EXPECT_EQ(ev.end, AdvanceEnd::kTimeLimit) << "c " << c << ", bound x " << loose;
      EXPECT_EQ(ev.t, 2.0);
    }
  }
}

// TurnLowerBound against the true minimum of cubics h = h0 + d0 t + k t^2 / 2 + j t^3 / 6 over
// steps where h' turns once from negative to positive, with m = max |h''| over the step. Never
// above the minimum; and never more than m tau^2 below it (either end's parabola lies at most
// m s^2 below h at distance s from its end), so that a step of tau << sqrt(min h / m) skips the
// polish.
TEST(SafeEventLocator, TurnLowerBoundStaysBelowTheMinimumAndNear) {
  int cases = 0;
  for (const double k : {0.5, 1.0, 3.0}) {
    for (const double j : {-0.4, 0.0, 0.7}) {
      for (const double d0 : {-1.0, -0.3, -0.05}) {
        for (const double tau : {0.2, 0.5, 2.0}) {
          auto h = [&](double t) { return 1.0 + d0 * t + 0.5 * k * t * t + j * t * t * t / 6.0; };
          auto dh = [&](double t) { return d0 + k * t + 0.5 * j * t * t; };
          auto ddh = [&](double t) { return k + j * t; };
          if (!(dh(tau) > 0.0) || ddh(tau) <= 0.0) continue;  // a single turn, - to +
          double lowest = h(0.0);
          for (int i = 1; i <= 10000; ++i) lowest = std::min(lowest, h(tau * i / 10000.0));
          const double m = std::max(std::abs(ddh(0.0)), std::abs(ddh(tau)));
          const GuardValue g0{.h = h(0.0), .dh = dh(0.0), .ddh = ddh(0.0)};
          const GuardValue g1{.h = h(tau), .dh = dh(tau), .ddh = ddh(tau)};
          const double bound = TurnLowerBound(g0, g1, tau, m);
          EXPECT_LE(bound, lowest) << "k " << k << " j " << j << " d0 " << d0 << " tau " << tau;
          EXPECT_GE(bound, lowest - m * tau * tau)
              << "k " << k << " j " << j << " d0 " << d0 << " tau " << tau;
          ++cases;
        }
      }
    }
  }
  EXPECT_GT(cases, 20);
}

}  // namespace
}  // namespace drillbif::internal
