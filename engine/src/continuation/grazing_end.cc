#include "continuation/grazing_end.h"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <complex>
#include <functional>
#include <vector>

#include "continuation/tangent_grazing.h"

namespace drillbif::internal {

namespace {

// The curve's own defining condition near `guess`: sigma of the shifted monodromy (bordered at
// `guess`) on a fold / PD / NS curve, h' at the (first) tangent end on a grazing curve.
ExtraCondition OwnCondition(const HybridModel& model, Propagator& propagator,
                            const PeriodicOrbit& guess, CurveKind kind) {
  if (kind == CurveKind::kGrazing) {
    const std::vector<int> tangents = TangentSegments(guess.signature);
    return ExtraCondition::OfSegmentFlow(tangents.empty() ? -1 : tangents.front(),
                                         [&model, &propagator](const PeriodicOrbit& o) {
                                           return TangentEndRate(model, propagator, o);
                                         });
  }
  return ExtraCondition::Sigma(model, propagator, guess, kind);
}

// `guess` with its zero-length `segment` made `length` long, taken from the next segment: the
// segment's flow for that long, the jump at its end the next start (the first guess of the
// fixed-length step-offs).
PeriodicOrbit WithSegmentLength(const HybridModel& model, Propagator& propagator,
                                const PeriodicOrbit& guess, int segment, double length) {
  PeriodicOrbit g = guess;
  const int next = segment + 1;
  const SegmentSpec& seg = g.signature.segments[segment];
  const StateVector end = propagator.FlowMap(seg.mode, g.starts[segment], length, g.params, {}).x;
  g.starts[next] = model.Jump(seg.mode, seg.guard, end, g.params).x;
  g.durations[segment] = length;
  g.durations[next] -= length;
  return g;
}

}  // namespace

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
  // h' at the last tangent end, and the curve's own condition: on a grazing curve h' at the
  // first, so that both touches count, whichever of them is the new one.
  const int last = TangentSegments(guess.signature).back();
  return SolveWithConditions(
      model, propagator, guess, {index1, index2},
      {ExtraCondition::OfSegmentFlow(
           last,
           [&](const PeriodicOrbit& o) { return RateAtTangentEnd(model, propagator, o, last); }),
       OwnCondition(model, propagator, guess, kind)},
      tolerance, "codimension-2 system");
}

StatusOr<PeriodicOrbit> SolveZeroLengthEnd(const HybridModel& model, Propagator& propagator,
                                           const PeriodicOrbit& guess, int segment, CurveKind kind,
                                           int index1, int index2, double tolerance) {
  return SolveSegmentLength(model, propagator, guess, segment, 0.0, kind, index1, index2,
                            tolerance);
}

StatusOr<PeriodicOrbit> SolveSegmentLength(const HybridModel& model, Propagator& propagator,
                                           const PeriodicOrbit& guess, int segment, double length,
                                           CurveKind kind, int index1, int index2,
                                           double tolerance) {
  if (segment < 0 || segment >= static_cast<int>(guess.durations.size())) {
    return InvalidArgument("no segment " + std::to_string(segment));
  }
  if (kind == CurveKind::kGrazing && TangentEndRates(model, propagator, guess).size() != 1) {
    return InvalidArgument("the end of a GRAZING curve needs its one tangent end");
  }
  // Newton on the orbit, both parameters and the curve's condition (bordered at `from`), with the
  // segment held at `length`.
  auto solve_from = [&](const PeriodicOrbit& from) {
    return SolveWithConditions(
        model, propagator, from, {index1, index2},
        {ExtraCondition::Duration(segment, length), OwnCondition(model, propagator, from, kind)},
        tolerance, length == 0.0 ? "zero-length segment system" : "fixed segment-length system");
  };
  const int next = segment + 1;
  // Not for a grazing curve: its orbit's tangent end, held only by h = 0 with one parameter free
  // (its h' = 0 is the curve's condition, left out there), is where that system's two crossings
  // of the guard merge, a double root: Newton halves its step towards it and stagnates at
  // rounding's floor (in the reference box 99% of these solves failed, most after 16 to 30
  // iterations, and every grazing step-off but one that succeeded did so from the root itself,
  // the whole system's h' = 0 making it regular).
  if (kind != CurveKind::kGrazing && length > 0.0 && guess.durations[segment] == 0.0 &&
      next < static_cast<int>(guess.durations.size()) && guess.durations[next] > length) {
    // Stepped off a zero-length segment whose ends lie on one guard (CrossingForm's: the touch
    // become a crossing there and back). At length zero the two ends' guard rows coincide and
    // the crossing speed, the saltations' denominator, is zero, so Newton's matrix and the
    // monodromy (sigma's borders) are singular there. First the orbit of that signature with
    // the segment `length` long, one parameter free (no monodromy: a regular system, the
    // crossing speed ~ h'' length / 2), then the whole system from it. Not from the root itself
    // where neither gives it: there Newton lost its way (in the reference box: a step-off solved
    // or not by rounding differences in the root), and as a fallback after both it solved 0 of
    // 121 such step-offs in the reference box and 18 of 3588 with --period2, whose curves and
    // codimension-2 points are all found without it.
    const PeriodicOrbit g = WithSegmentLength(model, propagator, guess, segment, length);
    Status failed;
    for (const int free : {index1, index2}) {
      const StatusOr<PeriodicOrbit> consistent = SolveWithConditions(
          model, propagator, g, {free}, {ExtraCondition::Duration(segment, length)}, tolerance,
          "fixed segment-length orbit");
      StatusOr<PeriodicOrbit> solved = consistent.ok() ? solve_from(*consistent) : consistent;
      if (solved.ok()) return solved;
      failed = solved.status();
    }
    return failed;
  }
  return solve_from(guess);
}

StatusOr<PeriodicOrbit> SolveSegmentLengthAlongLevel(const HybridModel& model,
                                                     Propagator& propagator,
                                                     const PeriodicOrbit& guess, int segment,
                                                     double length, CurveKind kind, int index1,
                                                     int index2, double tolerance) {
  const int next = segment + 1;
  if (kind == CurveKind::kGrazing || length <= 0.0 || segment < 0 ||
      next >= static_cast<int>(guess.durations.size()) || guess.durations[segment] != 0.0 ||
      guess.durations[next] <= length) {
    return InvalidArgument("no zero-length segment to step off along its level set");
  }
  const PeriodicOrbit g = WithSegmentLength(model, propagator, guess, segment, length);
  const ExtraCondition held = ExtraCondition::Duration(segment, length);
  Status last = Internal("the level-set secant found no fold / PD point");
  for (const std::pair<int, int>& free_moved :
       {std::pair{index1, index2}, std::pair{index2, index1}}) {
    // Plain names, not structured bindings: the lambda below captures them (clang before 16
    // does not capture bindings).
    const int free = free_moved.first, moved = free_moved.second;
    StatusOr<PeriodicOrbit> at = SolveWithConditions(model, propagator, g, {free}, {held},
                                                     tolerance, "fixed segment-length orbit");
    if (!at.ok()) {
      last = at.status();
      continue;
    }
    // The curve's own condition, bordered once at the first orbit of the level set: a smooth
    // function along it whose root is the curve's point of this segment length.
    const ExtraCondition own = OwnCondition(model, propagator, *at, kind);
    // The level set's orbit with params[moved] = t (from the last one) and its condition.
    auto level = [&](double t, PeriodicOrbit* o, double* c) {
      PeriodicOrbit from = *o;
      from.params[moved] = t;
      StatusOr<PeriodicOrbit> solved = SolveWithConditions(model, propagator, from, {free}, {held},
                                                           tolerance, "fixed segment-length orbit");
      if (!solved.ok()) return solved.status();
      *o = *std::move(solved);
      *c = ConditionValue(model, propagator, *o, own);
      return std::isfinite(*c) ? Status() : Internal("non-finite condition on the level set");
    };
    PeriodicOrbit o0 = *at, o1 = *at;
    double t0 = at->params[moved], c0 = ConditionValue(model, propagator, o0, own);
    const double first = c0;
    // The first secant step: the parameters' scale of the level set, length^2 (along the curve
    // the segment's length goes like the square root of the distance to its root).
    double t1 = t0 + length * length * (1.0 + std::abs(t0)), c1 = 0.0;
    if (Status s = level(t1, &o1, &c1); !s.ok() || !std::isfinite(c0)) {
      last = s.ok() ? Internal("non-finite condition on the level set") : s;
      continue;
    }
    for (int it = 0; it < 40 && c1 != c0; ++it) {
      const double t2 = t1 - c1 * (t1 - t0) / (c1 - c0);
      if (!std::isfinite(t2)) break;
      PeriodicOrbit o2 = o1;
      double c2 = 0.0;
      if (Status s = level(t2, &o2, &c2); !s.ok()) {
        last = s;
        break;
      }
      // Converged where the step is below the tolerance and the condition has fallen at least
      // tenfold from the level set's first orbit: next to the root the condition carries noise
      // (~1e-9 against 1e-6 there at length 1e-6), and on a secant slope of noise the step can
      // fall below the tolerance with the condition where it started.
      if (std::abs(t2 - t1) <= tolerance * (1.0 + std::abs(t2))) {
        if (std::abs(c2) <= 0.1 * std::abs(first)) return o2;
        last = Internal("the level-set secant stalled on the condition's noise");
        break;
      }
      t0 = t1, c0 = c1, o0 = std::move(o1);
      t1 = t2, c1 = c2, o1 = std::move(o2);
    }
  }
  return last;
}

// The fixed-length solves' scaled step: on a period-2 PD curve of the reference box sigma settles
// at 1e-11 (a long orbit's monodromy), where Newton's steps hover at 1e-11 .. 1e-9 and 1e-12 is
// never reached; at 1e-10 the extrapolated parameters carry ~5e-10 of that noise (the weights' sum
// of magnitudes is 5), within the required 1e-8.
constexpr double kExtrapolationTolerance = 1e-10;

StatusOr<ExtrapolatedEnd> ExtrapolateZeroLength(const HybridModel& model, Propagator& propagator,
                                                const PeriodicOrbit& guess, int segment,
                                                CurveKind kind, int index1, int index2,
                                                double length) {
  std::vector<PeriodicOrbit> at;  // the curve's points at tau = L, 2L, 4L
  for (const double tau : {length, 2.0 * length, 4.0 * length}) {
    StatusOr<PeriodicOrbit> solved =
        SolveSegmentLength(model, propagator, at.empty() ? guess : at.back(), segment, tau, kind,
                           index1, index2, kExtrapolationTolerance);
    if (!solved.ok()) return solved.status();
    at.push_back(*std::move(solved));
  }
  // w0 x(L) + w1 x(2L) + w2 x(4L), componentwise over the orbit's unknowns and parameters.
  auto combine = [&at](double w0, double w1, double w2) {
    PeriodicOrbit o = at[0];
    o.params = w0 * at[0].params + w1 * at[1].params + w2 * at[2].params;
    for (size_t k = 0; k < o.starts.size(); ++k) {
      o.starts[k] = w0 * at[0].starts[k] + w1 * at[1].starts[k] + w2 * at[2].starts[k];
      o.durations[k] = w0 * at[0].durations[k] + w1 * at[1].durations[k] + w2 * at[2].durations[k];
    }
    return o;
  };
  ExtrapolatedEnd end;
  end.orbit = combine(8.0 / 3.0, -2.0, 1.0 / 3.0);  // the quadratic through L, 2L, 4L at 0
  const PeriodicOrbit linear = combine(2.0, -1.0, 0.0);
  end.orbit.durations[segment] = 0.0;
  end.error = std::hypot(linear.params[index1] - end.orbit.params[index1],
                         linear.params[index2] - end.orbit.params[index2]);
  // The multipliers of L and 2L paired by proximity (they move by O(L) between the two).
  const Stability near = OrbitStability(model, propagator, at[0]);
  const Stability far = OrbitStability(model, propagator, at[1]);
  if (near.multipliers.size() != far.multipliers.size()) {
    return Internal("the multipliers at two lengths of the vanishing segment do not pair");
  }
  end.stability = near;
  end.stability.stable = true;
  for (std::complex<double>& mu : end.stability.multipliers) {
    const auto& f = far.multipliers;
    const auto nearest = std::min_element(f.begin(), f.end(), [&](const auto& x, const auto& y) {
      return std::abs(x - mu) < std::abs(y - mu);
    });
    mu = 2.0 * mu - *nearest;
    end.stability.stable = end.stability.stable && std::abs(mu) < 1.0;
  }
  return end;
}

namespace {
// The merged touch system's scaled step where its h''' is differenced: a hundred times the
// rounding floor its steps hover at (~1e-12, above), so that Newton stops above it; the end's
// parameters then carry about the last step's size, far within the 1e-8 a located point needs.
constexpr double kDifferencedTouchTolerance = 1e-10;
}  // namespace

StatusOr<PeriodicOrbit> SolveMergedTouchEnd(const HybridModel& model, Propagator& propagator,
                                            const PeriodicOrbit& guess, int segment, int index1,
                                            int index2, double tolerance) {
  const auto& segs = guess.signature.segments;
  const int k = static_cast<int>(segs.size()), j = segment;
  if (j < 1 || j >= k) return InvalidArgument("no segment " + std::to_string(j) + " to merge at");
  if (segs[j - 1].tangent && segs[j - 1].mode == segs[j].mode &&
      segs[j - 1].guard == segs[j].guard) {
    // The touch ends segment j - 1; merged, segment j - 1 ends at the crossing.
    const StatusOr<PeriodicOrbit> merged = MergedForm(guess, j - 1);
    if (!merged.ok()) return merged.status();
    const int e = j - 1;
    auto at_end = [&model, &propagator, e](const PeriodicOrbit& o) {
      const SegmentSpec& s = o.signature.segments[e];
      const StateVector end =
          propagator.FlowMap(s.mode, o.starts[e], o.durations[e], o.params, {}).x;
      return model.Guard(s.mode, s.guard, end, o.params);
    };
    return SolveWithConditions(
        model, propagator, *merged, {index1, index2},
        {ExtraCondition::OfOrbit([at_end](const PeriodicOrbit& o) { return at_end(o).dh; }),
         ExtraCondition::OfOrbit([at_end](const PeriodicOrbit& o) { return at_end(o).ddh; })},
        tolerance, "merged touch system");
  }
  if (!(segs[j].tangent && j + 1 < k && segs[j + 1].mode == segs[j].mode)) {
    return InvalidArgument("segment " + std::to_string(j) +
                           " is neither a touch's own segment nor follows one");
  }
  const StatusOr<PeriodicOrbit> merged = MergedForm(guess, j);
  if (!merged.ok()) return merged.status();
  const int mode = segs[j].mode, guard = segs[j].guard;
  // h, h', h'' of the touched guard along the flow of the merged segment j at time t.
  auto at = [&model, &propagator, j, mode, guard](const PeriodicOrbit& o, double t) {
    const StateVector x = propagator.FlowMap(mode, o.starts[j], t, o.params, {}).x;
    return model.Guard(mode, guard, x, o.params);
  };
  const GuardValue g0 = at(guess, 0.0);
  const double scale = 1.0 + guess.starts[j].lpNorm<Eigen::Infinity>();
  const bool structural = std::abs(g0.h) <= 1e-12 * scale && std::abs(g0.dh) <= 1e-12 * scale;
  // (h, h') at the start, or (h'', h''') with h''' by the one-sided second-order difference of
  // h'' (exact, from the model) along the flow: truncation ~ dt^2 |h^(5)| / 3, rounding
  // ~ eps |h''| / dt.
  auto first = [&at, structural](const PeriodicOrbit& o) {
    const GuardValue g = at(o, 0.0);
    return structural ? g.ddh : g.h;
  };
  auto second = [&at, structural](const PeriodicOrbit& o) {
    const GuardValue g = at(o, 0.0);
    if (!structural) return g.dh;
    constexpr double dt = 1e-5;
    return (-3.0 * g.ddh + 4.0 * at(o, dt).ddh - at(o, 2.0 * dt).ddh) / (2.0 * dt);
  };
  const std::vector<ExtraCondition> conditions = {ExtraCondition::OfOrbit(first),
                                                  ExtraCondition::OfOrbit(second)};
  StatusOr<PeriodicOrbit> solved = SolveWithConditions(
      model, propagator, *merged, {index1, index2}, conditions, tolerance, "merged touch system");
  if (solved.ok() || !structural || tolerance >= kDifferencedTouchTolerance) return solved;
  // h''' by differences carries rounding: Newton's steps hover at ~1e-12, around a 1e-12
  // tolerance (in the reference box a grazing curve's end at (0.1360, 0.1546) stagnated with
  // steps 1.2e-12 .. 6e-12 from one bisected end and converged from another 3e-13 away, both at
  // the same point to 1e-16). Stagnated at that floor, it is solved to a tolerance above it.
  return SolveWithConditions(model, propagator, *merged, {index1, index2}, conditions,
                             kDifferencedTouchTolerance, "merged touch system");
}

bool TouchesAtStart(const HybridModel& model, const PeriodicOrbit& orbit, int segment, int guard) {
  const auto& segs = orbit.signature.segments;
  if (segment < 0 || segment >= static_cast<int>(segs.size()) || guard < 0 ||
      guard >= static_cast<int>(model.guards(segs[segment].mode).size())) {
    return false;
  }
  const StateVector& x = orbit.starts[segment];
  const GuardValue g = model.Guard(segs[segment].mode, guard, x, orbit.params);
  const double tol = 1e-9 * (1.0 + x.lpNorm<Eigen::Infinity>());
  return std::abs(g.h) <= tol && std::abs(g.dh) <= tol && std::abs(g.ddh) <= tol;
}

}  // namespace drillbif::internal
