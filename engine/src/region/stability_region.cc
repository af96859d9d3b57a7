#include "drillbif/region/stability_region.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <deque>
#include <limits>
#include <memory>
#include <string>
#include <utility>

#include "common/format.h"
#include "common/phase_progress.h"
#include "region/region_boundary.h"
#include "region/segment_index.h"

namespace drillbif {
namespace {

constexpr unsigned kRopOnly = 1u << 0;  // ROP is measure 0 (HybridModel::measure_names())

std::string Num(double v) { return internal::FormatNumber(v, 10); }

RegionGrid MakeGrid(const RegionOptions& o) {
  RegionGrid g;
  g.n1 = o.n1;
  g.n2 = o.n2;
  for (int i = 0; i < o.n1; ++i) g.values1.push_back(o.min1 + o.width1() * i / (o.n1 - 1));
  for (int j = 0; j < o.n2; ++j) g.values2.push_back(o.min2 + o.width2() * j / (o.n2 - 1));
  g.values1.back() = o.max1;  // exactly: box edges are recognised by equality
  g.values2.back() = o.max2;
  g.label.assign(static_cast<size_t>(o.n1) * o.n2, RegionGrid::kOutside);
  g.rop.assign(g.label.size(), 0.0);
  return g;
}

// The traced curves' segments that reach into the box, bucketed by grid cell; tag = curve,
// part = segment index along it.
internal::SegmentIndex IndexCurves(const std::vector<RegionCurve>& curves, const RegionOptions& o) {
  internal::SegmentIndex index({o.min1, o.min2}, {o.max1, o.max2}, o.n1 - 1, o.n2 - 1);
  for (size_t c = 0; c < curves.size(); ++c) {
    const RegionCurve& curve = curves[c];
    const size_t n = std::min(curve.values1.size(), curve.values2.size());
    for (size_t k = 0; k + 1 < n; ++k) {
      const Eigen::Vector2d p(curve.values1[k], curve.values2[k]);
      const Eigen::Vector2d q(curve.values1[k + 1], curve.values2[k + 1]);
      const Eigen::Vector2d lo = p.cwiseMin(q), hi = p.cwiseMax(q);
      if (hi[0] < o.min1 || lo[0] > o.max1 || hi[1] < o.min2 || lo[1] > o.max2) continue;
      index.Add({p, q, static_cast<int>(c), static_cast<int>(k)});
    }
  }
  return index;
}

// Fills the grid breadth first from the start and locates the boundary crossings.
class RegionBuilder {
 public:
  RegionBuilder(const HybridModel& model, Propagator& propagator,
                const std::vector<RegionCurve>& curves, const RegionOptions& options,
                internal::PhaseProgress& phase, StabilityRegion* region)
      : model_(model),
        propagator_(propagator),
        options_(options),
        phase_(phase),
        region_(*region),
        grid_(region->grid),
        curves_(IndexCurves(curves, options)),
        orbits_(grid_.label.size()) {
    k1_ = model.ParamIndex(options.param1).value();
    k2_ = model.ParamIndex(options.param2).value();
  }

  enum class Outcome { kInside, kInadmissible, kFailed };

  // The orbit of guess's signature at (v1, v2) by Newton: kInside when it converges to an
  // admissible, stable orbit; kInadmissible when it converges to a stable orbit that is not
  // admissible; kFailed otherwise (no convergence, or unstable).
  Outcome Solve(const PeriodicOrbit& guess, double v1, double v2, PeriodicOrbit* out) {
    *out = guess;
    out->params[k1_] = v1;
    out->params[k2_] = v2;
    // The durations scale with the forcing period, so that the segments keep their phases.
    const double ratio =
        model_.ForcingFrequency(guess.params) / model_.ForcingFrequency(out->params);
    if (std::isfinite(ratio) && ratio > 0.0) {
      for (double& tau : out->durations) tau *= ratio;
    }
    ++region_.summary.solves;
    if (!SolveOrbit(model_, propagator_, options_.solver, out).completed() ||
        !OrbitStability(model_, propagator_, *out).stable) {
      return Outcome::kFailed;
    }
    return CheckAdmissible(model_, propagator_, *out).admissible ? Outcome::kInside
                                                                 : Outcome::kInadmissible;
  }

  // The stable period-1 orbit of another signature than `from`'s at (v1, v2), reached by
  // simulation from `from`'s start state.
  bool Switch(const PeriodicOrbit& from, double v1, double v2, PeriodicOrbit* out) {
    if (options_.switch_transient_periods <= 0) return false;
    Params params = from.params;
    params[k1_] = v1;
    params[k2_] = v2;
    GuessOptions guess;
    guess.transient_periods = options_.switch_transient_periods;
    guess.max_period = 1;
    StatusOr<PeriodicOrbit> found =
        OrbitFromSimulation(model_, propagator_, params, from.starts[0], guess);
    if (!found.ok() || found->signature == from.signature) return false;
    *out = *found;
    ++region_.summary.solves;
    return SolveOrbit(model_, propagator_, options_.solver, out).completed() &&
           OrbitStability(model_, propagator_, *out).stable &&
           CheckAdmissible(model_, propagator_, *out).admissible;
  }

  // Breadth-first fill from the grid nodes around the start. False when cancelled.
  bool Fill(const PeriodicOrbit& start) {
    region_.signatures = {start.signature};
    std::deque<int> queue;
    const double f1 = (start.params[k1_] - options_.min1) / options_.width1();
    const double f2 = (start.params[k2_] - options_.min2) / options_.width2();
    const int i0 = std::min(static_cast<int>(f1 * (grid_.n1 - 1)), grid_.n1 - 2);
    const int j0 = std::min(static_cast<int>(f2 * (grid_.n2 - 1)), grid_.n2 - 2);
    for (int dj = 0; dj < 2; ++dj) {
      for (int di = 0; di < 2; ++di) Visit(start, 0, i0 + di, j0 + dj, &queue);
    }
    const double total = static_cast<double>(grid_.label.size());
    int done = 0;
    while (!queue.empty()) {
      if (!phase_.Continue(kRegionFillShare * done / total)) return false;
      const int node = queue.front();
      queue.pop_front();
      const int i = node % grid_.n1, j = node / grid_.n1;
      const PeriodicOrbit& from = *orbits_[node];  // stays put: held by pointer
      const int label = grid_.label[node];
      if (i > 0) Visit(from, label, i - 1, j, &queue);
      if (i + 1 < grid_.n1) Visit(from, label, i + 1, j, &queue);
      if (j > 0) Visit(from, label, i, j - 1, &queue);
      if (j + 1 < grid_.n2) Visit(from, label, i, j + 1, &queue);
      ++done;
    }
    return !phase_.stopped();
  }

  // Where the boundary crosses the edge from inside node a to outside node b.
  internal::EdgeCrossing Cross(int a, int b) {
    ++region_.summary.boundary_edges;
    const Eigen::Vector2d pa = Position(a), pb = Position(b);
    internal::EdgeCrossing e;
    // Stopped: the polygons are dropped (ComputeStabilityRegion); no more solves. The edge's
    // bisections poll with the fraction given here (a throttle repeats the last one).
    if (!phase_.Continue(kRegionFillShare)) return e;
    double best = std::numeric_limits<double>::infinity();
    curves_.ForEachNear(pa.cwiseMin(pb), pa.cwiseMax(pb), [&](const internal::Segment& s) {
      double t = 0.0, u = 0.0;
      if (internal::IntersectSegments(pa, pb, s.p, s.q, &t, &u) && t < best) {
        best = t;
        e.curve = s.tag;
        e.curve_position = s.part + u;
      }
    });
    if (best <= 1.0) {
      const Eigen::Vector2d x = pa + best * (pb - pa);
      e.value1 = x[0];
      e.value2 = x[1];
      return e;
    }
    // No traced curve: bisect the edge, keeping the last point where the orbit is still inside.
    ++region_.summary.untraced_edges;
    PeriodicOrbit inside = *orbits_[a], trial;
    double lo = 0.0, hi = 1.0;
    for (int k = 0; k < options_.bisections && !phase_.stopped(); ++k) {
      const double mid = 0.5 * (lo + hi);
      const Eigen::Vector2d x = pa + mid * (pb - pa);
      if (Solve(inside, x[0], x[1], &trial) == Outcome::kInside) {
        lo = mid;
        inside = trial;
      } else {
        hi = mid;
      }
    }
    // A seam of the fill rather than a boundary: b is inside in another signature and a's orbit
    // goes on, stable and admissible, all the way to b (by Newton in its signature, or, where its
    // representation rotates on the way, along the edge's one-parameter branch), so two stable
    // orbits coexist there.
    const bool seam =
        grid_.Inside(b) && grid_.label[b] != grid_.label[a] &&
        (Solve(inside, pb[0], pb[1], &trial) == Outcome::kInside || CarriedStable(inside, pb));
    if (seam) ++region_.summary.seam_edges;
    const Eigen::Vector2d x = pa + lo * (pb - pa);
    e.value1 = x[0];
    e.value2 = x[1];
    e.curve = seam ? RegionVertex::kSeam : RegionVertex::kUntraced;
    return e;
  }

 private:
  // Whether the branch of `from` along the edge to `to` (one coordinate differs) reaches it with
  // every point stable and no fold, period doubling, Neimark-Sacker point or grazing on the way:
  // the one-parameter continuation carries the orbit on where its representation rotates (an
  // event crossing the section), which Solve, with the signature fixed, cannot (in the reference
  // box: a seam at (0.87, 0.02125) went unclassified, the flight orbit's representation rotating at
  // a = 0.0213 on its way to the far node).
  bool CarriedStable(const PeriodicOrbit& from, const Eigen::Vector2d& to) {
    const bool along1 = from.params[k1_] != to[0];
    const int k = along1 ? k1_ : k2_;
    const double x0 = from.params[k], x1 = to[along1 ? 0 : 1];
    ContinuationOptions c;
    c.param = along1 ? options_.param1 : options_.param2;
    c.min = std::min(x0, x1);
    c.max = std::max(x0, x1);
    c.direction = x1 > x0 ? ContinuationDirection::kIncreasing : ContinuationDirection::kDecreasing;
    c.locate_measure_maxima = false;
    c.point_measures = 0;
    c.stop_at = {SpecialPointKind::kFold,          SpecialPointKind::kPeriodDoubling,
                 SpecialPointKind::kNeimarkSacker, SpecialPointKind::kGrazingL1,
                 SpecialPointKind::kGrazingL2,     SpecialPointKind::kGrazingPi};
    const ContinuationResult branch = Continue(model_, propagator_, from, c);
    region_.summary.solves += branch.summary.steps + branch.summary.rejected_steps;
    // (Reached: a point at the bound; a decreasing run lists its points from there.)
    if (branch.summary.termination != Termination::kCompleted ||
        std::none_of(branch.points.begin(), branch.points.end(), [&](const ContinuationPoint& p) {
          return std::abs(p.value - x1) <= 1e-9 * (1.0 + std::abs(x1));
        })) {
      return false;
    }
    return std::all_of(branch.points.begin(), branch.points.end(),
                       [](const ContinuationPoint& p) { return p.stability.stable; });
  }

  Eigen::Vector2d Position(int node) const {
    return {grid_.values1[node % grid_.n1], grid_.values2[node / grid_.n1]};
  }

  // Solves node (i, j) from `from` (of signature `label`), switching signature beyond a grazing.
  void Visit(const PeriodicOrbit& from, int label, int i, int j, std::deque<int>* queue) {
    const int node = grid_.Index(i, j);
    if (grid_.Inside(node)) return;
    const double v1 = grid_.values1[i], v2 = grid_.values2[j];
    PeriodicOrbit orbit;
    const Outcome outcome = Solve(from, v1, v2, &orbit);
    if (outcome == Outcome::kFailed || phase_.stopped()) return;
    if (outcome == Outcome::kInadmissible) {
      if (!Switch(from, v1, v2, &orbit) || phase_.stopped()) return;
      ++region_.summary.switches;
      label = LabelOf(orbit.signature);
    }
    const double rop = OrbitMeasures(model_, propagator_, orbit, kRopOnly)[0];
    if (phase_.stopped()) return;  // nothing computed after a stop is kept
    grid_.label[node] = label;
    grid_.rop[node] = rop;
    ++region_.summary.inside_nodes;
    orbits_[node] = std::make_unique<PeriodicOrbit>(std::move(orbit));
    queue->push_back(node);
  }

  // One label per orbit: signatures that differ only in where the section cuts the orbit (an
  // event crossing s = 0 inside the region) share it, else the seam would count as a boundary
  // (in the reference box: 205 of 863 boundary edges, none on a traced curve, were such seams).
  int LabelOf(const Signature& signature) {
    for (size_t k = 0; k < region_.signatures.size(); ++k) {
      if (SameUpToSection(region_.signatures[k], signature)) return static_cast<int>(k);
    }
    region_.signatures.push_back(signature);
    return static_cast<int>(region_.signatures.size()) - 1;
  }

  const HybridModel& model_;
  Propagator& propagator_;
  const RegionOptions& options_;
  internal::PhaseProgress& phase_;
  StabilityRegion& region_;
  RegionGrid& grid_;
  internal::SegmentIndex curves_;
  // At the inside nodes (null elsewhere): a pointer a node, not an orbit (~200 bytes, 0.8 GB at
  // the largest grid) of which most would stay empty.
  std::vector<std::unique_ptr<PeriodicOrbit>> orbits_;
  int k1_ = 0, k2_ = 0;
};

}  // namespace

std::vector<RegionCurve> RegionCurvesOf(const std::vector<TracedCurve>& curves) {
  std::vector<RegionCurve> out;
  for (const TracedCurve& c : curves) {
    RegionCurve& rc = out.emplace_back();
    if (c.start.point.orbit.signature.periods != 1) continue;
    rc.values1 = c.outline.values1;
    rc.values2 = c.outline.values2;
  }
  return out;
}

Status RegionOptions::Validate() const {
  if (param1.empty() || param2.empty() || param1 == param2) {
    return InvalidArgument("param1, param2: name two different parameters");
  }
  if (!(std::isfinite(min1) && std::isfinite(max1) && min1 < max1)) {
    return InvalidArgument("min1, max1: need finite min1 < max1, got [" + Num(min1) + ", " +
                           Num(max1) + "]");
  }
  if (!(std::isfinite(min2) && std::isfinite(max2) && min2 < max2)) {
    return InvalidArgument("min2, max2: need finite min2 < max2, got [" + Num(min2) + ", " +
                           Num(max2) + "]");
  }
  if (n1 < 3 || n2 < 3) {
    return InvalidArgument("n1, n2: need at least 3 grid nodes per parameter, got " +
                           std::to_string(n1) + ", " + std::to_string(n2));
  }
  if (static_cast<double>(n1) * n2 > 4e6) {
    return InvalidArgument("n1, n2: at most 4e6 grid nodes, got " + std::to_string(n1) + " x " +
                           std::to_string(n2));
  }
  if (bisections < 0 || bisections > 50) {
    return InvalidArgument("bisections: need 0..50, got " + std::to_string(bisections));
  }
  return solver.Validate();
}

StabilityRegion ComputeStabilityRegion(const HybridModel& model, Propagator& propagator,
                                       const PeriodicOrbit& start,
                                       const std::vector<RegionCurve>& curves,
                                       const RegionOptions& options,
                                       const RegionProgress& progress) {
  StabilityRegion region;
  region.box() = options.box();
  RegionSummary& summary = region.summary;
  if (Status s = options.Validate(); !s.ok()) {
    summary.Fail(s);
    return region;
  }
  const StatusOr<int> k1 = model.ParamIndex(options.param1), k2 = model.ParamIndex(options.param2);
  if (!k1.ok() || !k2.ok()) {
    summary.Fail(InvalidArgument((k1.ok() ? k2 : k1).status().message()));
    return region;
  }
  const double v1 = start.params[*k1], v2 = start.params[*k2];
  if (!(v1 >= options.min1 && v1 <= options.max1 && v2 >= options.min2 && v2 <= options.max2)) {
    summary.Fail(InvalidArgument("the start orbit (" + options.param1 + " = " + Num(v1) + ", " +
                                 options.param2 + " = " + Num(v2) + ") is outside the box"));
    return region;
  }
  // The region's throttle, attached to the propagator: every solve polls it.
  internal::PhaseProgress phase(propagator, progress);
  auto cancelled = [&] {
    summary.Cancel("cancelled");
    return std::move(region);
  };
  const bool stable =
      start.signature.periods == 1 && OrbitStability(model, propagator, start).stable;
  if (phase.stopped()) return cancelled();
  if (!stable) {
    summary.Fail(FailedPrecondition(
        "the start orbit is not a stable period-1 orbit: it has no stability region of period-1 "
        "motion"));
    return region;
  }
  region.grid = MakeGrid(options);
  RegionBuilder builder(model, propagator, curves, options, phase, &region);
  if (!builder.Fill(start)) return cancelled();
  if (summary.inside_nodes == 0) {
    summary.Fail(FailedPrecondition(
        "no grid node next to the start orbit has a stable orbit of its signature (the start is "
        "within one grid spacing of the boundary?)"));
    return region;
  }
  for (size_t label = 0; label < region.signatures.size(); ++label) {
    std::vector<RegionPolygon> rings = internal::TraceBoundary(
        region.grid, static_cast<int>(label), [&](int a, int b) { return builder.Cross(a, b); },
        curves);
    region.polygons.insert(region.polygons.end(), rings.begin(), rings.end());
    if (phase.stopped()) break;
  }
  // Stopped while the boundary was located: the grid is complete, the polygons are not.
  if (phase.stopped()) {
    region.polygons.clear();
    return cancelled();
  }
  summary.Complete(
      std::to_string(summary.inside_nodes) + " of " + std::to_string(region.grid.label.size()) +
      " grid nodes inside in " + std::to_string(region.signatures.size()) + " signatures (" +
      std::to_string(summary.switches) + " switches), " + std::to_string(region.polygons.size()) +
      " rings, " + std::to_string(summary.boundary_edges) + " boundary edges (" +
      std::to_string(summary.untraced_edges) + " crossed by no traced curve, " +
      std::to_string(summary.seam_edges) + " of them seams between coexisting stable orbits), " +
      std::to_string(summary.solves) + " Newton solves");
  return region;
}

std::string RegionSummary::BriefReport() const {
  return RunSummary::BriefReport(
      CountOf(solves, "Newton solve") + ", " + CountOf(inside_nodes, "inside node") + " (" +
      std::to_string(switches) + " switched), " + CountOf(boundary_edges, "boundary edge") + " (" +
      std::to_string(untraced_edges) + " untraced, " + std::to_string(seam_edges) + " seams)");
}

}  // namespace drillbif
