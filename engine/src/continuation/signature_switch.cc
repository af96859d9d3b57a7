#include "continuation/signature_switch.h"

#include <algorithm>
#include <cmath>

namespace drillbif::internal {
namespace {

// The kind of a grazing named after the surface the orbit touches (the drifting oscillator's Pi,
// l1, l2); SIGNATURE_CHANGE for a segment that vanishes without a tangency.
SpecialPointKind KindOfSurface(const std::string& surface) {
  if (surface == "l1") return SpecialPointKind::kGrazingL1;
  if (surface == "l2") return SpecialPointKind::kGrazingL2;
  if (surface == "Pi") return SpecialPointKind::kGrazingPi;
  return SpecialPointKind::kSignatureChange;
}

// A segment vanishes between the event that starts it and the one that ends it. Entered and left
// through the same surface, the orbit touches that surface (a CwP phase between two l1 events:
// l1 grazing). A free flight between separation and impact vanishes when the separation becomes
// tangential (l2); a contact phase between impact and separation when the impact does (Pi).
// Anything else (a contact phase between impact and progression: the force at impact reaches the
// threshold) is a signature change without grazing.
SpecialPointKind KindOfVanishing(const HybridModel& model, const Signature& sig, int i) {
  const int k = static_cast<int>(sig.segments.size());
  const SegmentSpec& seg = sig.segments[i];
  const SegmentSpec& prev = sig.segments[(i + k - 1) % k];
  if (seg.guard < 0 || prev.guard < 0) return SpecialPointKind::kSignatureChange;
  const std::string& in = model.guards(prev.mode)[prev.guard].surface;
  const std::string& out = model.guards(seg.mode)[seg.guard].surface;
  if (in == out) return KindOfSurface(in);
  if (in == "l2" && out == "Pi") return SpecialPointKind::kGrazingL2;
  if (in == "Pi" && out == "l2") return SpecialPointKind::kGrazingPi;
  return SpecialPointKind::kSignatureChange;
}

// The segment on the other side of `guard` of `mode`: the mode across it, ending on its guard
// that leads back into `mode` (e.g. across NC's impact: CwoP, ending on separation).
SegmentSpec Across(const HybridModel& model, int mode, int guard) {
  SegmentSpec s{model.ModeAcross(mode, guard), -1};
  for (int g = 0; g < static_cast<int>(model.guards(s.mode).size()); ++g) {
    if (model.ModeAcross(s.mode, g) == mode) s.guard = g;
  }
  return s;
}

}  // namespace

GuardMinimum SegmentGuardMinimum(const HybridModel& model, Propagator& propagator,
                                 const PeriodicOrbit& orbit, int segment, int guard, double near) {
  const int mode = orbit.signature.segments[segment].mode;
  const StateVector& x0 = orbit.starts[segment];
  const double tau = orbit.durations[segment];
  const Params& prm = orbit.params;
  auto at = [&](double t) {
    return model.Guard(mode, guard, propagator.FlowMap(mode, x0, t, prm, {}).x, prm);
  };
  constexpr int kSamples = 64;
  GuardValue g[kSamples + 1];
  for (int j = 0; j <= kSamples; ++j) g[j] = at(tau * j / kSamples);
  GuardMinimum best, sampled;
  for (int j = 1; j < kSamples; ++j) {
    if (g[j].h < sampled.h) sampled = {tau * j / kSamples, g[j].h};
  }
  const double t_tolerance = 1e-15 * std::max(1.0, tau);
  // Each sampled local minimum of h, refined by Newton on h' kept inside its neighbouring samples.
  bool refined[kSamples + 1] = {};
  for (int j = 1; j < kSamples; ++j) {
    if (!(g[j].h <= g[j - 1].h && g[j].h <= g[j + 1].h)) continue;
    refined[j] = true;
    const double lo = tau * (j - 1) / kSamples, hi = tau * (j + 1) / kSamples;
    double t = tau * j / kSamples;
    GuardValue v = g[j];
    for (int it = 0; it < 30 && v.ddh > 0.0; ++it) {
      const double next = std::clamp(t - v.dh / v.ddh, lo, hi);
      const bool done = std::abs(next - t) <= t_tolerance;
      t = next;
      v = at(t);
      if (done) break;
    }
    if (v.h < best.h) best = {t, v.h};
  }
  // Each interval where h' goes from falling to rising holds a minimum even when no sample shows
  // it: a dip narrower than two samples next to an end (a free flight of length 95 leaving the
  // slider, whose gap comes back to within 1e-3 of zero 2 time units after separation, between
  // the first two samples 1.5 apart) has h[1] above the end's h[0] = 0. Such a minimum is located
  // by Newton on h' safeguarded by bisection inside the interval (`dip`). The ends of the segment
  // are left out: the segment starts or ends on some guards, where h' may vanish by construction.
  // Intervals next to a sampled minimum are left to its refinement above, so that a minimum both
  // find is the same to the last bit (a touch time 1e-14 apart took the period-2 omega-branch
  // onto another side of the branch point at the period-1 doubling near omega = 1.6258).
  auto dip = [&](double lo, double hi) {
    double t = 0.5 * (lo + hi);
    GuardValue v = at(t);
    for (int it = 0; it < 100 && hi - lo > t_tolerance; ++it) {
      if (v.dh < 0.0) {
        lo = t;
      } else if (v.dh > 0.0) {
        hi = t;
      } else {
        break;
      }
      const double newton = v.ddh > 0.0 ? t - v.dh / v.ddh : lo - 1.0;
      t = newton > lo && newton < hi ? newton : 0.5 * (lo + hi);
      v = at(t);
    }
    if (t > t_tolerance && t < tau - t_tolerance && v.h < best.h) best = {t, v.h};
  };
  for (int j = 0; j < kSamples; ++j) {
    if (!(g[j].dh < 0.0 && g[j + 1].dh > 0.0) || refined[j] || refined[j + 1]) continue;
    dip(tau * j / kSamples, tau * (j + 1) / kSamples);
  }
  // The dip that a crossing seen at `near` enters, where neither pass above finds it: h' falling
  // and rising again between two samples, as where a segment starts on a guard with h' = 0 (a
  // free flight leaving the slider at a vanishing force rate, which comes back to Pi 0.30 into a
  // flight 92 long, inside the first sample interval of 1.44; the period-4 a-branch at
  // omega = 0.09 near a = 0.685). Its h' is sampled 32 times over the interval around `near` and
  // the next one, and a fall-to-rise refined as above.
  const double w = tau / kSamples;
  if (near > 0.0 && near < tau && !(std::isfinite(best.h) && std::abs(best.t - near) <= 2.0 * w)) {
    constexpr int kFine = 32;
    const double lo = std::max(0.0, near - w), hi = std::min(tau, near + 2.0 * w);
    double t0 = lo;
    GuardValue v0 = at(t0);
    for (int j = 1; j <= kFine; ++j) {
      const double t1 = lo + (hi - lo) * j / kFine;
      const GuardValue v1 = at(t1);
      if (v0.dh < 0.0 && v1.dh > 0.0) {
        dip(t0, t1);
        break;
      }
      t0 = t1, v0 = v1;
    }
  }
  return std::isfinite(best.h) ? best : sampled;
}

GuardMinimum AtStartMinimum(const HybridModel& model, Propagator& propagator,
                            const PeriodicOrbit& orbit, const Admissibility& violation) {
  const int i = violation.segment;
  const SegmentSpec& seg = orbit.signature.segments[i];
  const GuardMinimum start{0.0,
                           model.Guard(seg.mode, violation.guard, orbit.starts[i], orbit.params).h};
  const GuardMinimum inner = SegmentGuardMinimum(model, propagator, orbit, i, violation.guard);
  const double tau = orbit.durations[i];
  if (!(inner.t > 0.0 && inner.t < tau && inner.h < start.h)) return start;
  // A stationary point (SegmentGuardMinimum's refined minima; its smallest sample, where h has no
  // interior minimum, is not one: h' there is h'' times a sample spacing or more).
  const GuardValue v = model.Guard(
      seg.mode, violation.guard,
      propagator.FlowMap(seg.mode, orbit.starts[i], inner.t, orbit.params, {}).x, orbit.params);
  return v.ddh > 0.0 && std::abs(v.dh) <= 1e-6 * v.ddh * tau ? inner : start;
}

double ViolationTestFunction(const HybridModel& model, Propagator& propagator,
                             const PeriodicOrbit& orbit, const Admissibility& violation) {
  if (violation.guard < 0) return orbit.durations[violation.segment];
  if (violation.at_start) return AtStartMinimum(model, propagator, orbit, violation).h;
  return SegmentGuardMinimum(model, propagator, orbit, violation.segment, violation.guard,
                             violation.time)
      .h;
}

SwitchedOrbit SwitchSignature(const HybridModel& model, Propagator& propagator,
                              const PeriodicOrbit& orbit, const Admissibility& violation) {
  SwitchedOrbit out;
  out.orbit = orbit;
  PeriodicOrbit& o = out.orbit;
  std::vector<SegmentSpec>& segs = o.signature.segments;
  const int i = violation.segment;
  const int k = static_cast<int>(segs.size());
  if (violation.guard < 0 && i == 0 && k > 1) {
    // The first segment vanished: its ending event reached the section and moves into the
    // previous period. Rotate: the last segment now ends on that event, and a zero-length segment
    // of the mode it enters runs on to the section. A change of representation, not of the orbit.
    out.representation_only = true;
    out.kind = SpecialPointKind::kSignatureChange;
    segs.back().guard = segs[0].guard;
    segs.back().tangent = segs[0].tangent;  // a tangent end (grazing curves) moves with its event
    segs.push_back({segs[1].mode, -1});
    o.starts.push_back(o.starts[1]);
    o.durations.push_back(0.0);
    segs.erase(segs.begin());
    o.starts.erase(o.starts.begin());
    o.durations.erase(o.durations.begin());
  } else if (violation.guard < 0 && i == k - 1 && k > 1) {
    // The last segment vanished: the event before it reached the section and moves into the next
    // period. Rotate the other way: a zero-length first segment ends on that event.
    out.representation_only = true;
    out.kind = SpecialPointKind::kSignatureChange;
    const SegmentSpec before = segs[k - 2];
    segs.insert(segs.begin(), before);
    o.starts.insert(o.starts.begin(), o.starts[k - 1]);
    o.durations.insert(o.durations.begin(), 0.0);
    segs[k - 1].guard = -1;  // the old segment k - 2, shifted by one
    segs[k - 1].tangent = false;
    segs.pop_back();
    o.starts.pop_back();
    o.durations.pop_back();
  } else if (violation.guard < 0) {
    // Remove the vanished interior segment; merge its neighbours when they are in the same mode.
    out.kind = KindOfVanishing(model, orbit.signature, i);
    if (segs[i - 1].mode == segs[i + 1].mode) {
      segs[i - 1].guard = segs[i + 1].guard;
      o.durations[i - 1] += o.durations[i] + o.durations[i + 1];
      segs.erase(segs.begin() + i, segs.begin() + i + 2);
      o.starts.erase(o.starts.begin() + i, o.starts.begin() + i + 2);
      o.durations.erase(o.durations.begin() + i, o.durations.begin() + i + 2);
    } else {
      segs[i - 1].guard = segs[i].guard;
      o.durations[i - 1] += o.durations[i];
      segs.erase(segs.begin() + i);
      o.starts.erase(o.starts.begin() + i);
      o.durations.erase(o.durations.begin() + i);
    }
  } else if (violation.at_start && AtStartMinimum(model, propagator, orbit, violation).t == 0.0) {
    // The segment's guard fires at its very start (e.g. the force at impact fell below the
    // progression threshold): a zero-length segment of the mode across that guard now comes first,
    // ending where the old segment begins.
    const SegmentSpec seg = segs[i];
    const SegmentSpec across = Across(model, seg.mode, violation.guard);
    out.kind = SpecialPointKind::kSignatureChange;
    segs.insert(segs.begin() + i, across);
    o.starts.insert(o.starts.begin() + i, o.starts[i]);
    o.durations.insert(o.durations.begin() + i, 0.0);
    out.new_segment = i;
  } else {
    // Split segment i at the touch: (m > guard) (across) (m > old end).
    const SegmentSpec seg = segs[i];
    const SegmentSpec across = Across(model, seg.mode, violation.guard);
    out.kind = KindOfSurface(model.guards(seg.mode)[violation.guard].surface);
    // The touching time: the guard's interior minimum.
    const StateVector x0 = o.starts[i];
    const double tau = o.durations[i];
    const double t_touch =
        SegmentGuardMinimum(model, propagator, orbit, i, violation.guard, violation.time).t;
    StateVector xt = propagator.FlowMap(seg.mode, x0, t_touch, o.params, {}).x;
    const StateVector x_across = model.Jump(seg.mode, violation.guard, xt, o.params).x;
    segs[i].guard = violation.guard;
    segs.insert(segs.begin() + i + 1, {across, {seg.mode, seg.guard}});
    o.durations[i] = t_touch;
    o.durations.insert(o.durations.begin() + i + 1, {0.0, tau - t_touch});
    o.starts.insert(o.starts.begin() + i + 1, {x_across, x_across});
    out.new_segment = i + 1;
  }
  out.detail =
      SignatureString(model, orbit.signature) + " -> " + SignatureString(model, o.signature);
  return out;
}

}  // namespace drillbif::internal
