// The stability region and the robust optimum in a box around the reference orbit, omega in
// [0.05, 0.15], a in [0.25, 0.6] at b = 0.15: the start's signature (NC, CwoP, CwP, CwoP, NC)
// and, beyond the l1 grazing at small omega, NC, CwP, CwoP, NC; bounded by traced fold, PD and
// grazing curves and by boundaries no traced curve explains. ROP grows towards small omega and
// large a, up to the region's upper boundary, so the margin decides where the optimum lies (with
// margins 0.005 and 0.01 it moves from a = 0.495 to 0.4775; the unconstrained maximum is higher).
//
// References: an independent fill of the grid (sweeps in four directions until nothing changes,
// instead of the breadth-first fill), point-in-polygon tests of every node against the polygons,
// distances of polygon vertices to the traced polylines, and a brute grid search of the optimum
// over the independent fill.
#include "drillbif/region/stability_region.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <optional>
#include <string>

#include "drillbif/continuation/trace.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/orbit/attractors.h"
#include "drillbif/orbit/signature.h"
#include "drillbif/region/robust_optimum.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

constexpr int kN1 = 41, kN2 = 41;

TraceOptions Box() {
  TraceOptions o;
  o.param1 = std::string("omega");
  o.param2 = std::string("a");
  o.min1 = 0.05, o.max1 = 0.15;
  o.min2 = 0.25, o.max2 = 0.6;
  return o;
}

struct Computed {
  PeriodicOrbit start;
  TraceResult trace;
  std::vector<RegionCurve> curves;
  StabilityRegion region;
};

const Computed& Shared() {
  static const Computed* computed = [] {
    auto* c = new Computed;
    DriftingOscillator model;
    ExactPropagator prop(model);
    c->start = *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
    c->trace = TraceCurves(model, prop, c->start, Box());
    c->curves = RegionCurvesOf(c->trace.curves);
    RegionOptions ro;
    ro.param1 = Box().param1, ro.param2 = Box().param2;
    ro.min1 = Box().min1, ro.max1 = Box().max1, ro.min2 = Box().min2, ro.max2 = Box().max2;
    ro.n1 = kN1, ro.n2 = kN2;
    c->region = ComputeStabilityRegion(model, prop, c->start, c->curves, ro);
    return c;
  }();
  return *computed;
}

// The independent fill: every unlabelled node is tried from each labelled neighbour (Newton from
// its orbit; beyond a grazing, simulation for a stable period-1 orbit of another signature), in
// sweeps left, right, down and up until a sweep changes nothing. Labels are signatures.
struct BruteGrid {
  std::vector<int> label;  // index into signatures, -1 outside
  std::vector<Signature> signatures;
  std::vector<double> rop;
};

BruteGrid FillBySweeps(const RegionGrid& g, const PeriodicOrbit& start) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const int n = g.n1 * g.n2;
  BruteGrid b{std::vector<int>(n, -1), {start.signature}, std::vector<double>(n, 0.0)};
  std::vector<PeriodicOrbit> orbits(n);
  auto at = [&](const PeriodicOrbit& from, int node, PeriodicOrbit* out) -> int {
    Params params = from.params;
    params[DriftingOscillator::kOmega] = g.values1[node % g.n1];
    params[DriftingOscillator::kA] = g.values2[node / g.n1];
    *out = from;
    out->params = params;
    for (double& tau : out->durations) {
      tau *= from.params[DriftingOscillator::kOmega] / params[DriftingOscillator::kOmega];
    }
    if (SolveOrbit(model, prop, {}, out).termination != Termination::kCompleted ||
        !OrbitStability(model, prop, *out).stable) {
      return -1;
    }
    if (!CheckAdmissible(model, prop, *out).admissible) {
      GuessOptions guess;
      guess.transient_periods = 200;
      guess.max_period = 1;
      StatusOr<PeriodicOrbit> sim = OrbitFromSimulation(model, prop, params, from.starts[0], guess);
      if (!sim.ok() || sim->signature == from.signature) return -1;
      *out = *sim;
      if (SolveOrbit(model, prop, {}, out).termination != Termination::kCompleted ||
          !OrbitStability(model, prop, *out).stable ||
          !CheckAdmissible(model, prop, *out).admissible) {
        return -1;
      }
    }
    auto it = std::find(b.signatures.begin(), b.signatures.end(), out->signature);
    if (it == b.signatures.end()) it = b.signatures.insert(b.signatures.end(), out->signature);
    return static_cast<int>(it - b.signatures.begin());
  };
  auto set = [&](int node, int l, const PeriodicOrbit& o) {
    b.label[node] = l;
    b.rop[node] = OrbitMeasures(model, prop, o, 1u)[0];  // ROP is measure 0
    orbits[node] = o;
  };
  // Seed: the four nodes around the start, from the start.
  const double f1 = (start.params[DriftingOscillator::kOmega] - g.values1[0]) /
                    (g.values1.back() - g.values1[0]) * (g.n1 - 1);
  const double f2 = (start.params[DriftingOscillator::kA] - g.values2[0]) /
                    (g.values2.back() - g.values2[0]) * (g.n2 - 1);
  for (int dj = 0; dj < 2; ++dj) {
    for (int di = 0; di < 2; ++di) {
      const int node = g.Index(static_cast<int>(f1) + di, static_cast<int>(f2) + dj);
      PeriodicOrbit o;
      if (const int l = at(start, node, &o); l >= 0) set(node, l, o);
    }
  }
  for (bool changed = true; changed;) {
    changed = false;
    for (int sweep = 0; sweep < 4; ++sweep) {
      for (int k = 0; k < n; ++k) {
        const int node = sweep % 2 == 0 ? k : n - 1 - k;
        const int i = node % g.n1, j = node / g.n1;
        if (b.label[node] >= 0) continue;
        const int neighbours[4][2] = {{i - 1, j}, {i + 1, j}, {i, j - 1}, {i, j + 1}};
        for (const auto& nb : neighbours) {
          if (nb[0] < 0 || nb[1] < 0 || nb[0] >= g.n1 || nb[1] >= g.n2) continue;
          const int from = g.Index(nb[0], nb[1]);
          if (b.label[from] < 0) continue;
          PeriodicOrbit o;
          if (const int l = at(orbits[from], node, &o); l >= 0) {
            set(node, l, o);
            changed = true;
            break;
          }
        }
      }
    }
  }
  return b;
}

const BruteGrid& Brute() {
  static const BruteGrid* b = new BruteGrid(FillBySweeps(Shared().region.grid, Shared().start));
  return *b;
}

// Even-odd point-in-polygon over a signature's rings.
bool InRings(const std::vector<RegionPolygon>& rings, int signature, double x, double y) {
  bool in = false;
  for (const RegionPolygon& ring : rings) {
    if (ring.signature != signature) continue;
    const auto& v = ring.vertices;
    for (size_t a = 0, b = v.size() - 1; a < v.size(); b = a++) {
      if ((v[a].value2 > y) != (v[b].value2 > y) &&
          x < (v[b].value1 - v[a].value1) * (y - v[a].value2) / (v[b].value2 - v[a].value2) +
                  v[a].value1) {
        in = !in;
      }
    }
  }
  return in;
}

TEST(StabilityRegion, FillAgreesWithAnIndependentSweepFill) {
  const StabilityRegion& r = Shared().region;
  ASSERT_TRUE(r.summary.status.ok()) << r.summary.status.ToString();
  EXPECT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.BriefReport();
  EXPECT_GE(r.summary.solves, r.summary.inside_nodes);  // one solve at least per node inside
  ASSERT_FALSE(Shared().trace.curves.empty());
  const BruteGrid& b = Brute();
  int inside = 0;
  for (size_t k = 0; k < r.grid.label.size(); ++k) {
    const int fast = r.grid.label[k], brute = b.label[k];
    ASSERT_EQ(fast >= 0, brute >= 0) << "node " << k;
    if (fast < 0) continue;
    ++inside;
    EXPECT_TRUE(r.signatures[fast] == b.signatures[brute]) << "node " << k;
    // Same orbit, solved from different neighbours: ROP agrees to the Newton tolerance (1e-11
    // scaled) times the ROP's sensitivity (O(1) here), with room for the measure's quadrature.
    EXPECT_NEAR(r.grid.rop[k], b.rop[k], 1e-8) << "node " << k;
  }
  EXPECT_EQ(inside, r.summary.inside_nodes);
  // The box holds the start's signature and at least one other (beyond the l1 grazing), and a
  // boundary: otherwise this test would not exercise switching or polygons.
  EXPECT_GE(r.signatures.size(), 2u);
  EXPECT_GT(inside, 100);
  EXPECT_LT(inside, kN1 * kN2);
}

TEST(StabilityRegion, PolygonsSeparateTheNodesOfEachSignature) {
  const StabilityRegion& r = Shared().region;
  ASSERT_TRUE(r.summary.status.ok());
  ASSERT_FALSE(r.polygons.empty());
  for (size_t s = 0; s < r.signatures.size(); ++s) {
    for (int j = 0; j < r.grid.n2; ++j) {
      for (int i = 0; i < r.grid.n1; ++i) {
        const bool mine = r.grid.label[r.grid.Index(i, j)] == static_cast<int>(s);
        // Nodes on the box edge are polygon vertices themselves; test a point nudged inwards by
        // 1e-9 of a spacing, which no boundary can separate from the node (crossings lie at
        // least that far from it unless a curve passes through the node itself).
        const double x = r.grid.values1[i] + (i == 0 ? 1e-12 : i == r.grid.n1 - 1 ? -1e-12 : 0);
        const double y = r.grid.values2[j] + (j == 0 ? 1e-12 : j == r.grid.n2 - 1 ? -1e-12 : 0);
        EXPECT_EQ(InRings(r.polygons, static_cast<int>(s), x, y), mine)
            << "signature " << s << " node (" << i << ", " << j << ")";
      }
    }
  }
}

TEST(StabilityRegion, CurveVerticesLieOnTheirTracedCurves) {
  const StabilityRegion& r = Shared().region;
  const std::vector<RegionCurve>& curves = Shared().curves;
  int on_curves = 0;
  for (const RegionPolygon& ring : r.polygons) {
    for (const RegionVertex& v : ring.vertices) {
      if (v.curve < 0) continue;
      ASSERT_LT(v.curve, static_cast<int>(curves.size()));
      const RegionCurve& c = curves[v.curve];
      double best = 1e300;
      for (size_t k = 0; k + 1 < c.values1.size(); ++k) {
        // Distance to segment k in the box's unit square.
        const double w1 = r.max1 - r.min1, w2 = r.max2 - r.min2;
        const double px = (c.values1[k] - v.value1) / w1, py = (c.values2[k] - v.value2) / w2;
        const double dx = (c.values1[k + 1] - c.values1[k]) / w1,
                     dy = (c.values2[k + 1] - c.values2[k]) / w2;
        const double dd = dx * dx + dy * dy;
        const double t = dd > 0 ? std::clamp(-(px * dx + py * dy) / dd, 0.0, 1.0) : 0.0;
        best = std::min(best, std::hypot(px + t * dx, py + t * dy));
      }
      // Intersections and the curve's own vertices: on the polyline to rounding.
      EXPECT_LE(best, 1e-12);
      ++on_curves;
    }
  }
  EXPECT_GT(on_curves, 10);
}

// The brute optimum: the inside node of maximal ROP such that every grid node within the
// rectangle [+- r1] x [+- r2] around it has its signature.
double BruteOptimumRop(double r1, double r2) {
  const RegionGrid& g = Shared().region.grid;
  const BruteGrid& b = Brute();
  double best = -1.0;
  for (int node = 0; node < g.n1 * g.n2; ++node) {
    if (b.label[node] < 0 || b.rop[node] <= best) continue;
    const double x = g.values1[node % g.n1], y = g.values2[node / g.n1];
    bool clear = true;
    for (int other = 0; other < g.n1 * g.n2 && clear; ++other) {
      if (std::abs(g.values1[other % g.n1] - x) <= r1 &&
          std::abs(g.values2[other / g.n1] - y) <= r2 && b.label[other] != b.label[node]) {
        clear = false;
      }
    }
    if (clear) best = b.rop[node];
  }
  return best;
}

// Sandwich (per-parameter margins m, spacing h): a node whose rectangle of half-widths m meets no
// boundary has every grid node within m of its own signature, so the fast optimum is at most the
// brute one with margin m. Conversely the polygons' edges lie within cells whose corners differ
// in label, or (curve vertices inserted between two crossings) within two cells of such a corner,
// so a node whose nodes within m + 3h all share its label is at least m from every edge: the
// brute optimum with margin m + 3h is at most the fast one.
TEST(RobustOptimum, AgreesWithABruteGridSearchToTheGridsResolution) {
  const StabilityRegion& r = Shared().region;
  const double h1 = (r.max1 - r.min1) / (kN1 - 1), h2 = (r.max2 - r.min2) / (kN2 - 1);
  for (const double m : {0.005, 0.01}) {
    OptimumOptions o;
    o.margin = {m, 2 * m};  // a spans twice omega's width here
    const RobustOptimum best = FindRobustOptimum(r, o);
    ASSERT_TRUE(best.summary.status.ok()) << best.summary.status.ToString();
    EXPECT_GE(best.margin[0], m * (1 - 1e-12));
    EXPECT_GE(best.margin[1], 2 * m * (1 - 1e-12));
    const double upper = BruteOptimumRop(m, 2 * m);
    const double lower = BruteOptimumRop(m + 3 * h1, 2 * m + 3 * h2);
    EXPECT_LE(best.rop, upper + 1e-8) << "margin " << m;
    EXPECT_GE(best.rop, lower - 1e-8) << "margin " << m;
    EXPECT_GT(lower, 0.0) << "the brute search with the wider margin found nothing to compare";
  }
}

TEST(RobustOptimum, ScaledMarginIsADiskInTheUnitSquare) {
  const StabilityRegion& r = Shared().region;
  OptimumOptions o;
  o.margin = {0.05};
  o.scaled = true;
  const RobustOptimum best = FindRobustOptimum(r, o);
  ASSERT_TRUE(best.summary.status.ok()) << best.summary.status.ToString();
  EXPECT_EQ(best.summary.termination, Termination::kCompleted) << best.summary.BriefReport();
  EXPECT_GE(best.summary.candidates, 1);  // the optimum itself was checked
  ASSERT_EQ(best.margin.size(), 1u);
  EXPECT_GE(best.margin[0], 0.05 * (1 - 1e-12));
  EXPECT_NEAR(best.distance_scaled, best.margin[0], 1e-12);  // the same distance, two ways
}

TEST(RobustOptimum, TooLargeAMarginIsNotFoundWithTheLargestAvailable) {
  OptimumOptions o;
  o.margin = {0.5};
  o.scaled = true;
  const RobustOptimum best = FindRobustOptimum(Shared().region, o);
  EXPECT_EQ(best.summary.termination, Termination::kFailed);
  EXPECT_EQ(best.summary.status.code(), StatusCode::kNotFound);
  EXPECT_NE(best.summary.status.message().find("largest margin"), std::string::npos);
}

TEST(RobustOptimum, InvalidMarginsNameTheField) {
  for (const auto& [margin, scaled] :
       std::vector<std::pair<std::vector<double>, bool>>{{{}, false},
                                                         {{0.1, 0.2, 0.3}, false},
                                                         {{-0.1}, false},
                                                         {{NAN}, false},
                                                         {{0.01, 0.02}, true},
                                                         {{0.7}, true}}) {
    OptimumOptions o;
    o.margin = margin;
    o.scaled = scaled;
    const RobustOptimum best = FindRobustOptimum(Shared().region, o);
    EXPECT_EQ(best.summary.termination, Termination::kFailed);
    EXPECT_EQ(best.summary.status.code(), StatusCode::kInvalidArgument);
    EXPECT_EQ(best.summary.status.message().rfind("margin", 0), 0u)
        << best.summary.status.message();
  }
}

// The curves of the (omega, a) box [w0, w1] x [a0, a1] traced from `start`, then the region on an
// n1 x n2 grid bounded by them.
StabilityRegion TracedRegion(const DriftingOscillator& model, Propagator& prop,
                             const PeriodicOrbit& start, double w0, double w1, double a0, double a1,
                             int n1, int n2) {
  TraceOptions box;
  box.param1 = std::string("omega"), box.param2 = std::string("a");
  box.min1 = w0, box.max1 = w1, box.min2 = a0, box.max2 = a1;
  const TraceResult trace = TraceCurves(model, prop, start, box);
  EXPECT_TRUE(trace.summary.status.ok()) << trace.summary.status.ToString();
  RegionOptions ro;
  ro.param1 = box.param1, ro.param2 = box.param2;
  ro.min1 = w0, ro.max1 = w1, ro.min2 = a0, ro.max2 = a1;
  ro.n1 = n1, ro.n2 = n2;
  return ComputeStabilityRegion(model, prop, start, RegionCurvesOf(trace.curves), ro);
}

// Where an event crosses the Poincare section inside the region, the same orbit's signature
// rotates ("NC>Pi CwoP>l2 NC|" <-> "CwoP>l2 NC>Pi CwoP|"): one label, no seam. Below the l2
// grazing curve the bit stays in contact ("CwoP|"), stable once the contact constraint's unit
// multiplier is set apart (else rounding decides: nodes of that orbit are in or out at
// random). In omega in [1.3, 1.42], a in [0.09, 0.17] (spacing 0.01), from the attractor at
// (1.36, 0.15): two labels, and every boundary edge is crossed by the traced l2 grazing curve
// (in the reference box the seams were 205 of 863 boundary edges, none on a traced curve).
TEST(StabilityRegion, OneLabelPerOrbitWhereTheSectionCutsItElsewhere) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  Params at = testing::ReferenceParams();
  at[DriftingOscillator::kOmega] = 1.36, at[DriftingOscillator::kA] = 0.15;
  const StatusOr<PeriodicOrbit> start = testing::SolvedOrbitFromRest(model, prop, at);
  ASSERT_TRUE(start.ok()) << start.status().ToString();
  const StabilityRegion region = TracedRegion(model, prop, *start, 1.3, 1.42, 0.09, 0.17, 13, 9);
  ASSERT_TRUE(region.summary.status.ok()) << region.summary.status.ToString();
  std::vector<std::string> names;
  for (const Signature& s : region.signatures) names.push_back(SignatureString(model, s));
  ASSERT_EQ(names.size(), 2u) << region.summary.message;
  EXPECT_NE(std::find(names.begin(), names.end(), "CwoP|"), names.end());
  EXPECT_GT(region.summary.boundary_edges, 0);
  EXPECT_EQ(region.summary.untraced_edges, 0) << region.summary.message;
}

// The orbit `o` moved to (omega, a) in 20 Newton steps along the straight line, or nullopt.
std::optional<PeriodicOrbit> MovedTo(const DriftingOscillator& model, Propagator& prop,
                                     PeriodicOrbit o, double omega, double a) {
  const double w0 = o.params[DriftingOscillator::kOmega], a0 = o.params[DriftingOscillator::kA];
  for (int k = 1; k <= 20; ++k) {
    const double f = k / 20.0;
    const double w = w0 + f * (omega - w0);
    for (double& tau : o.durations) tau *= o.params[DriftingOscillator::kOmega] / w;
    o.params[DriftingOscillator::kOmega] = w;
    o.params[DriftingOscillator::kA] = a0 + f * (a - a0);
    if (SolveOrbit(model, prop, {}, &o).termination != Termination::kCompleted) return std::nullopt;
  }
  return o;
}

// The two stable orbits that coexist at (omega, a): the pure-contact one and the one with a flight
// (found by SampleAttractors; exactly these two).
void ContactAndFlight(const DriftingOscillator& model, Propagator& prop, double omega, double a,
                      PeriodicOrbit* contact, PeriodicOrbit* flight) {
  Params at = testing::ReferenceParams();
  at[DriftingOscillator::kOmega] = omega, at[DriftingOscillator::kA] = a;
  const StatusOr<AttractorSample> there =
      SampleAttractors(model, prop, at, DriftingOscillator::SpreadStates(at));
  ASSERT_TRUE(there.ok()) << there.status().ToString();
  ASSERT_EQ(there->attractors.size(), 2u);
  const bool contact_first =
      SignatureString(model, there->attractors[0].orbit.signature) == "CwoP|";
  *contact = there->attractors[contact_first ? 0 : 1].orbit;
  *flight = there->attractors[contact_first ? 1 : 0].orbit;
}

// The region of `start` in the box (TracedRegion) has untraced edges, every one a seam, and no
// polygon vertex left untraced.
void AllUntracedAreSeams(const DriftingOscillator& model, Propagator& prop,
                         const PeriodicOrbit& start, double min1, double max1, double min2,
                         double max2, int n1, int n2, StabilityRegion* region) {
  *region = TracedRegion(model, prop, start, min1, max1, min2, max2, n1, n2);
  ASSERT_TRUE(region->summary.status.ok()) << region->summary.status.ToString();
  EXPECT_GT(region->summary.untraced_edges, 0) << region->summary.message;
  EXPECT_EQ(region->summary.seam_edges, region->summary.untraced_edges) << region->summary.message;
  for (const RegionPolygon& ring : region->polygons) {
    for (const RegionVertex& v : ring.vertices) {
      EXPECT_NE(v.curve, RegionVertex::kUntraced) << "(" << v.value1 << ", " << v.value2 << ")";
    }
  }
}

// A seam of the fill: where two stable orbits coexist the fill labels each node with the one it
// reached, and where its two labels meet no curve is crossed. In omega in [0.8, 1], a in
// [0.01, 0.03] (21 x 11 nodes), from the pure-contact orbit at (0.9, 0.02) (which coexists there
// with an orbit with a flight: tests/orbit/attractors_test.cc), two boundary edges are crossed by
// no traced curve, and both are seams: the pure-contact orbit goes on, stable, to the node across.
// Checked independently at each seam vertex of the polygons (bisected to the far node): both
// orbits, moved there by Newton from (0.9, 0.02), are attractors by direct simulation (500 periods
// from their start perturbed by 1e-6 settle on an orbit of the same signature). The 8 spread
// initial states all settle on the pure-contact orbit there: a sample misses the flight orbit's
// basin.
TEST(StabilityRegion, SeamsBetweenCoexistingOrbitsAreToldApart) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  PeriodicOrbit start, flight;
  ASSERT_NO_FATAL_FAILURE(ContactAndFlight(model, prop, 0.9, 0.02, &start, &flight));
  StabilityRegion region;
  ASSERT_NO_FATAL_FAILURE(
      AllUntracedAreSeams(model, prop, start, 0.8, 1.0, 0.01, 0.03, 21, 11, &region));
  int checked = 0;
  for (const RegionPolygon& ring : region.polygons) {
    for (const RegionVertex& v : ring.vertices) {
      if (v.curve != RegionVertex::kSeam) continue;
      for (const PeriodicOrbit* o : {&start, &flight}) {
        const std::optional<PeriodicOrbit> moved = MovedTo(model, prop, *o, v.value1, v.value2);
        ASSERT_TRUE(moved.has_value()) << SignatureString(model, o->signature);
        StateVector x0 = moved->starts[0];
        x0[DriftingOscillator::kY] += 1e-6;
        const StatusOr<PeriodicOrbit> settled = OrbitFromSimulation(model, prop, moved->params, x0);
        ASSERT_TRUE(settled.ok()) << settled.status().ToString();
        EXPECT_TRUE(SameUpToSection(settled->signature, o->signature))
            << SignatureString(model, settled->signature) << " at (" << v.value1 << ", " << v.value2
            << ")";
      }
      ++checked;
    }
  }
  EXPECT_GT(checked, 0);
}

// The two orbits coexisting at (0.87, 0.03) and the region in omega in [0.85, 0.89], a in
// [0.01, 0.04] (5 x 4 nodes) from the one with a flight (or the pure-contact one), whose untraced
// edges are all seams (AllUntracedAreSeams).
void SectionSeamBox(const DriftingOscillator& model, Propagator& prop, bool from_flight,
                    PeriodicOrbit* contact, PeriodicOrbit* flight, StabilityRegion* region) {
  ASSERT_NO_FATAL_FAILURE(ContactAndFlight(model, prop, 0.87, 0.03, contact, flight));
  ASSERT_NO_FATAL_FAILURE(AllUntracedAreSeams(model, prop, from_flight ? *flight : *contact, 0.85,
                                              0.89, 0.01, 0.04, 5, 4, region));
}

// A seam reached across a Poincare-section crossing: in omega in [0.85, 0.89], a in [0.01, 0.04]
// (5 x 4 nodes), from the orbit with a flight at (0.87, 0.03), the fill labels (0.87, 0.02) with
// the pure-contact orbit; the flight orbit goes on, stable, down to that node, but its
// representation rotates on the way (an event crosses the section at a = 0.0213), so Newton with
// its signature fixed gives an inadmissible orbit there. The one-parameter branch along the edge
// carries it across (stability_region.cc, CarriedStable): every untraced edge is a seam (3 of 4
// before). Checked independently at (0.87, 0.02): the branch's orbit there, perturbed by 1e-6,
// settles on itself in 500 periods of direct simulation (an attractor, so stable and there),
// as does the pure-contact orbit of the node's label.
TEST(StabilityRegion, ASeamReachedAcrossASectionCrossingIsToldApart) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  PeriodicOrbit contact, flight;
  StabilityRegion region;
  ASSERT_NO_FATAL_FAILURE(SectionSeamBox(model, prop, true, &contact, &flight, &region));
  // The case: with its signature fixed the flight orbit at (0.87, 0.02) is not admissible.
  PeriodicOrbit fixed = flight;
  fixed.params[DriftingOscillator::kA] = 0.02;
  ASSERT_EQ(SolveOrbit(model, prop, {}, &fixed).termination, Termination::kCompleted);
  EXPECT_FALSE(CheckAdmissible(model, prop, fixed).admissible);
  ContinuationOptions down;
  down.param = "a", down.min = 0.02, down.max = 0.03;
  down.direction = ContinuationDirection::kDecreasing;
  const ContinuationResult branch = Continue(model, prop, flight, down);
  const auto at_node =
      std::find_if(branch.points.begin(), branch.points.end(),
                   [](const ContinuationPoint& p) { return std::abs(p.value - 0.02) <= 1e-12; });
  ASSERT_NE(at_node, branch.points.end()) << branch.summary.message;
  EXPECT_NE(at_node->orbit.signature, flight.signature);  // rotated on the way
  const std::optional<PeriodicOrbit> contact_there = MovedTo(model, prop, contact, 0.87, 0.02);
  ASSERT_TRUE(contact_there.has_value());
  for (const PeriodicOrbit* o : {&at_node->orbit, &*contact_there}) {
    const PeriodicOrbit& moved = *o;
    StateVector x0 = moved.starts[0];
    x0[DriftingOscillator::kY] += 1e-6;
    const StatusOr<PeriodicOrbit> settled = OrbitFromSimulation(model, prop, moved.params, x0);
    ASSERT_TRUE(settled.ok()) << settled.status().ToString();
    EXPECT_TRUE(SameUpToSection(settled->signature, moved.signature))
        << SignatureString(model, settled->signature) << " from "
        << SignatureString(model, moved.signature);
  }
}

// The optimum names a seam as its nearest obstacle (RobustOptimum::nearest_curve kSeam): in the
// box above, from the pure-contact orbit (ROP 0 at every node: no progression phase), with a
// scaled margin of 0.01. Checked against the polygons directly: the nearest of their edges that
// do not lie along the box, by box-scaled Euclidean distance from the optimum, is at the distance
// reported (to rounding) and joins vertices on no traced curve, one of them a seam vertex.
TEST(StabilityRegion, TheOptimumNamesASeamAsItsNearestObstacle) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  PeriodicOrbit contact, flight;
  StabilityRegion region;
  ASSERT_NO_FATAL_FAILURE(SectionSeamBox(model, prop, false, &contact, &flight, &region));
  OptimumOptions scaled;
  scaled.scaled = true, scaled.margin = {0.01};
  const RobustOptimum best = FindRobustOptimum(region, scaled);
  ASSERT_TRUE(best.summary.status.ok()) << best.summary.status.ToString();
  EXPECT_EQ(best.nearest_curve, RegionVertex::kSeam);
  const double w1 = region.max1 - region.min1, w2 = region.max2 - region.min2;
  double nearest = 1e300;
  const RegionVertex* ends[2] = {nullptr, nullptr};
  for (const RegionPolygon& ring : region.polygons) {
    for (size_t i = 0; i < ring.vertices.size(); ++i) {
      const RegionVertex& a = ring.vertices[i];
      const RegionVertex& b = ring.vertices[(i + 1) % ring.vertices.size()];
      const bool along_box =
          (a.value1 == b.value1 && (a.value1 == region.min1 || a.value1 == region.max1)) ||
          (a.value2 == b.value2 && (a.value2 == region.min2 || a.value2 == region.max2));
      if (along_box) continue;
      const double ax = (a.value1 - best.value1) / w1, ay = (a.value2 - best.value2) / w2;
      const double dx = (b.value1 - a.value1) / w1, dy = (b.value2 - a.value2) / w2;
      const double l2 = dx * dx + dy * dy;
      const double t = l2 > 0.0 ? std::clamp(-(ax * dx + ay * dy) / l2, 0.0, 1.0) : 0.0;
      const double d = std::hypot(ax + t * dx, ay + t * dy);
      if (d < nearest) nearest = d, ends[0] = &a, ends[1] = &b;
    }
  }
  ASSERT_NE(ends[0], nullptr);
  EXPECT_NEAR(best.distance_scaled, nearest, 1e-12);
  EXPECT_LT(ends[0]->curve, 0);
  EXPECT_LT(ends[1]->curve, 0);
  EXPECT_TRUE(ends[0]->curve == RegionVertex::kSeam || ends[1]->curve == RegionVertex::kSeam);
}

TEST(StabilityRegion, BadRequestsAreClearErrors) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const PeriodicOrbit& start = Shared().start;
  RegionOptions ro;
  ro.param1 = std::string("omega"), ro.param2 = std::string("a");
  ro.min1 = 0.05, ro.max1 = 0.15, ro.min2 = 0.25, ro.max2 = 0.6;
  RegionOptions bad = ro;
  bad.n1 = 2;
  const StabilityRegion coarse = ComputeStabilityRegion(model, prop, start, {}, bad);
  EXPECT_EQ(coarse.summary.termination, Termination::kFailed);
  EXPECT_EQ(coarse.summary.status.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(coarse.summary.solves, 0);
  bad = ro;
  bad.param2 = std::string("zeta");
  EXPECT_NE(
      ComputeStabilityRegion(model, prop, start, {}, bad).summary.status.message().find("zeta"),
      std::string::npos);
  bad = ro;
  bad.min1 = 0.2, bad.max1 = 0.3;  // the start (omega = 0.1) is outside
  EXPECT_EQ(ComputeStabilityRegion(model, prop, start, {}, bad).summary.status.code(),
            StatusCode::kInvalidArgument);
  bad = ro;
  bad.max2 = NAN;
  EXPECT_EQ(ComputeStabilityRegion(model, prop, start, {}, bad).summary.status.code(),
            StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace drillbif
