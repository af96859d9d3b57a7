// The robust optimum: the grid node of maximal ROP inside a stability region
// (region/stability_region.h) whose distance to the region's boundary curves is at least a margin.
//
// Distance is measured in one of two metrics, both normalised so that the margin is 1:
//   per parameter: max(|d1| / m1, |d2| / m2): the rectangle [p1 +- m1] x [p2 +- m2] (m1 = m2 = m
//                  when one value is given);
//   scaled:        sqrt((d1 / (m w1))^2 + (d2 / (m w2))^2), w the box widths: a disk of radius
//                  m in the box's unit-square coordinates.
// The obstacles are the polygons' edges that are not box edges: the traced curves (and untraced
// boundary pieces) that bound the region. A node whose margin neighbourhood meets no obstacle lies
// inside with that whole neighbourhood inside the region (or beyond the box, where nothing is
// known: `near_box_edge` says so).
//
// Search: the inside nodes by decreasing ROP, each checked against the obstacle segments in the
// buckets of a uniform grid that its neighbourhood overlaps; the first that passes is the optimum.
// The answer is resolved to one grid spacing (the region's grid); its cost is one sort plus a few
// bucket lookups per rejected node.
#ifndef DRILLBIF_REGION_ROBUST_OPTIMUM_H_
#define DRILLBIF_REGION_ROBUST_OPTIMUM_H_

#include <string>
#include <vector>

#include "drillbif/common/progress.h"
#include "drillbif/common/status.h"
#include "drillbif/region/stability_region.h"

namespace drillbif {

struct OptimumOptions {
  // Per parameter (scaled = false): m1, m2 in the units of param1, param2 (> 0 each; one value
  // stands for both). Scaled: one value m, a fraction of the box in (0, 0.5].
  std::vector<double> margin = {0.02};
  bool scaled = false;

  Status Validate() const;
};

// How the search ended (common/termination.h): kCompleted when the optimum was found; kFailed
// with NOT_FOUND when no inside node has the margin (the message says the largest any has), with
// INVALID_ARGUMENT / FAILED_PRECONDITION for bad options or region; kCancelled when stopped.
struct OptimumSummary : RunSummary {
  int64_t candidates = 0;  // inside nodes checked (rejected ones + the optimum)
  // "completed: 12 candidates" (RunSummary::BriefReport).
  std::string BriefReport() const;
};

struct RobustOptimum {
  OptimumSummary summary;
  int node = -1;        // the optimum's grid node (flat index)
  double value1 = 0.0;  // the optimum's param1
  double value2 = 0.0;  // and param2
  double rop = 0.0;     // its ROP
  // The margin achieved, in the form asked: {k m1, k m2} (per parameter) or {k m} (scaled), k >= 1
  // the distance to the nearest obstacle in the normalised metric; infinite when the region has
  // no bounding curve at all.
  std::vector<double> margin;
  double distance_scaled = 0.0;  // Euclidean distance to the nearest obstacle, box-scaled units
  // The curve of that obstacle (index), or kUntraced / kSeam.
  int nearest_curve = RegionVertex::kUntraced;
  bool near_box_edge = false;  // the margin neighbourhood reaches beyond the box
};

// An edge of a stability region's boundary that is not on the box: an obstacle of the search, in
// the trace parameters' units, from (a1, a2) to (b1, b2).
struct BoundarySegment {
  double a1 = 0.0, a2 = 0.0, b1 = 0.0, b2 = 0.0;
  // The curve both ends lie on (or the one either end lies on), else RegionVertex::kSeam or
  // kUntraced.
  int curve = RegionVertex::kUntraced;
};

// The obstacles of `region`: every polygon edge that is not along the box, in polygon order.
std::vector<BoundarySegment> RegionObstacles(const StabilityRegion& region);

// The search's metric over a box of widths (width1, width2): distances normalised so that the
// margin of `options` (valid) is 1, the max norm of (d1 / m1, d2 / m2) per parameter, the Euclidean
// norm of (d1 / (m w1), d2 / (m w2)) scaled.
class MarginMetric {
 public:
  MarginMetric(const OptimumOptions& options, double width1, double width2);
  // From the point (v1, v2) to the segment.
  double Distance(double v1, double v2, const BoundarySegment& s) const;
  // Between two points.
  double Distance(double v1, double v2, double w1, double w2) const;

 private:
  double scale1_, scale2_;
  bool max_norm_;
};

// INVALID_ARGUMENT for bad options or a region without a grid; FAILED_PRECONDITION for a region
// whose computation did not succeed. `progress` (optional, common/progress.h; through a
// ProgressThrottle) receives the fraction of the nodes checked and can stop the search:
// termination kCancelled, `candidates` the nodes checked until then, nothing else set.
RobustOptimum FindRobustOptimum(const StabilityRegion& region, const OptimumOptions& options,
                                const ProgressCallback& progress = {});

}  // namespace drillbif

#endif  // DRILLBIF_REGION_ROBUST_OPTIMUM_H_
