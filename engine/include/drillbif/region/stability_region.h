// The stability region of period-1 motion in a box of two parameters: where a stable, admissible
// period-1 orbit exists, on a grid and as polygons bounded by the traced bifurcation curves
// (continuation/trace.h), one set of polygons per orbit signature, with the orbit's ROP at every
// grid node inside.
//
// Grid: n1 x n2 nodes spanning the box. The region is filled from the nodes around the start
// orbit, breadth first: each neighbour of an inside node is solved by Newton from that node's
// orbit (a natural-parameter continuation step of one grid spacing) and is inside when Newton
// converges to an admissible, stable orbit of the same signature. Where the orbit converges but is
// not admissible (a grazing lies between the nodes), the motion is followed by simulation from the
// inside node's orbit at the new parameters (switch_transient_periods), and the node is inside with
// the new signature when that leads to a stable period-1 orbit of a different signature. Where
// Newton fails or the orbit is unstable (a fold, period doubling or Neimark-Sacker lies between
// them) the node stays outside from that neighbour, so that a jump to another branch never joins
// two regions. A node that fails from one neighbour is tried again from each other inside
// neighbour. The result is the connected set of stable period-1 motion around the start, as
// resolved by the grid; where two stable orbits coexist, the node holds the one reached first.
//
// Polygons: marching squares on each signature's nodes. Where a grid edge joins a node of the
// signature and one that is not (outside, or another signature), the boundary crosses it at the
// intersection with a traced curve nearest the node of the signature; when no traced curve crosses
// the edge, by bisection on the edge (Newton in that signature from its node; the vertex is then
// "untraced"). Between two consecutive vertices on the same curve the curve's own vertices are
// inserted, so that the polygon follows the traced curve rather than its chord. Outside the box
// counts as outside: where the region reaches the box, the polygon runs along the box edge (those
// edges are not bifurcation curves). Diagonal (saddle) cells are resolved as separated, which
// never adds area the grid did not see.
#ifndef DRILLBIF_REGION_STABILITY_REGION_H_
#define DRILLBIF_REGION_STABILITY_REGION_H_

#include <functional>
#include <string>
#include <vector>

#include "drillbif/common/parameter_box.h"
#include "drillbif/common/status.h"
#include "drillbif/continuation/trace.h"
#include "drillbif/orbit/periodic_orbit.h"

namespace drillbif {

// A bifurcation curve as a polyline in (param1, param2).
struct RegionCurve {
  std::vector<double> values1, values2;  // vertices in order, same length
};

// The traced curves' polylines (their outlines, TracedCurve::outline), in the same order (so a
// vertex's `curve` indexes both); curves of period-n orbits (n > 1) are left empty: they do not
// bound period-1 motion, and a crossing of one would be taken for the boundary.
std::vector<RegionCurve> RegionCurvesOf(const std::vector<TracedCurve>& curves);

// The box (ParameterBox): finite, min < max.
struct RegionOptions : ParameterBox {
  // Grid nodes per parameter, >= 3 each. The region and the optimum are resolved to one spacing
  // (box width / (n - 1)); the cost grows with n1 * n2 (one Newton solve per node inside, plus
  // the failed ones around it). 101 resolves the reference (omega, a) box (omega in [0.05, 2],
  // a in [0.01, 8]) to ~2% in a, 1% in omega.
  int n1 = 101, n2 = 101;
  // Halvings of a grid edge when the boundary is located by bisection (no traced curve crosses
  // it): 12 gives 1/4096 of a spacing.
  int bisections = 12;
  // Forcing periods simulated, from the orbit of an inside neighbour, to find the orbit of a new
  // signature beyond a grazing (0: no switching; the region is then the start's signature only).
  // 200 periods shrink a perturbation by 0.9^200 ~ 1e-9 for multipliers up to 0.9 in modulus.
  int switch_transient_periods = 200;
  OrbitSolverOptions solver;  // Newton at each node

  Status Validate() const;
};

// Where a polygon vertex lies: on traced curve `curve` (index into the curves given), on a
// boundary no traced curve explains (kUntraced: located by bisection), on the box (kBox), or on a
// seam between two coexisting stable orbits (kSeam: RegionSummary::seam_edges; no bifurcation).
struct RegionVertex {
  static constexpr int kUntraced = -1;
  static constexpr int kBox = -2;
  static constexpr int kSeam = -3;
  double value1 = 0.0, value2 = 0.0;
  int curve = kBox;
};

// A closed ring (the last vertex joins the first) around the nodes of one signature. Outer
// boundaries run counterclockwise in (param1, param2), holes clockwise; a signature's region is
// the even-odd union of its rings.
struct RegionPolygon {
  int signature = 0;  // index into StabilityRegion::signatures
  std::vector<RegionVertex> vertices;
};

// Node (i, j) is values1[i], values2[j]; flat index i + n1 * j.
struct RegionGrid {
  static constexpr int kOutside = -1;
  int n1 = 0, n2 = 0;
  std::vector<double> values1, values2;
  // The signature (index into StabilityRegion::signatures) of the stable period-1 orbit reached
  // there, or kOutside.
  std::vector<int> label;
  std::vector<double> rop;  // the orbit's ROP where inside, 0 elsewhere
  int Index(int i, int j) const { return i + n1 * j; }
  bool Inside(int node) const { return label[node] != kOutside; }
};

// How a region's computation ended (common/termination.h): kFailed when it could not be
// computed (status says why), kCancelled when stopped (the grid is what was filled until then),
// else kCompleted with a message summing up the region.
struct RegionSummary : RunSummary {
  int64_t solves = 0;      // Newton solves (nodes and bisection points)
  int inside_nodes = 0;    // grid nodes inside
  int switches = 0;        // nodes reached in a new signature by simulation
  int boundary_edges = 0;  // grid edges joining nodes of different labels (each side counted)
  int untraced_edges = 0;  // of which crossed by no traced curve (located by bisection)
  // Of those, seams between coexisting stable orbits: the node across is inside in another
  // signature and the orbit of this side goes on, stable and admissible, to that node too (the
  // fill labels each node with one orbit; there are two). No bifurcation is crossed there; the
  // edge still bounds this signature's polygon (and is an obstacle for the optimum: the motion
  // may settle on either orbit).
  int seam_edges = 0;
  // "completed: 4000 Newton solves, 1200 inside nodes (3 switched), 80 boundary edges (2
  // untraced, 0 seams); ..." (RunSummary::BriefReport).
  std::string BriefReport() const;
};

// The box (ParameterBox) is the options'.
struct StabilityRegion : ParameterBox {
  std::vector<Signature> signatures;  // of the orbits inside; [0] is the start's
  RegionGrid grid;
  std::vector<RegionPolygon> polygons;
  RegionSummary summary;
};

// Called with the fraction done in [0, 1] (a ProgressCallback, common/progress.h) through a
// ProgressThrottle: about every 5 ms of computation (every Newton solve, simulation and boundary
// location polls it) and at every percent of the nodes. The fill reports kRegionFillShare times
// the fraction of grid nodes filled (always below kRegionFillShare), the location of the boundary
// exactly kRegionFillShare (its number of edges is not known in advance). Returning false cancels
// within milliseconds: termination kCancelled, the grid nodes filled until then and no polygons
// (also when the stop comes while the boundary is located).
using RegionProgress = std::function<bool(double fraction)>;
inline constexpr double kRegionFillShare = 0.9;

// The region around `start` (a stable period-1 orbit), `curves` its candidate boundaries (every
// traced curve may be given; those that bound the region are the ones its edges cross).
// FAILED_PRECONDITION when the start orbit is not a stable period-1 orbit or no grid node next to
// it is inside; INVALID_ARGUMENT for bad options or a start outside the box.
StabilityRegion ComputeStabilityRegion(const HybridModel& model, Propagator& propagator,
                                       const PeriodicOrbit& start,
                                       const std::vector<RegionCurve>& curves,
                                       const RegionOptions& options,
                                       const RegionProgress& progress = {});

}  // namespace drillbif

#endif  // DRILLBIF_REGION_STABILITY_REGION_H_
