// Marching squares on a stability region's grid: the closed rings between inside and outside
// nodes (region/stability_region.h explains the construction). Internal to the engine.
#ifndef DRILLBIF_REGION_REGION_BOUNDARY_H_
#define DRILLBIF_REGION_REGION_BOUNDARY_H_

#include <functional>
#include <vector>

#include "drillbif/region/stability_region.h"

namespace drillbif::internal {

// Where the boundary crosses the grid edge from an inside node to an outside node: the point and,
// when it lies on a traced curve, that curve and its position there (segment index + fraction).
struct EdgeCrossing {
  double value1 = 0.0, value2 = 0.0;
  int curve = RegionVertex::kUntraced;
  double curve_position = 0.0;
};

// (node of the label, node of another label or outside) as flat grid indices -> the crossing;
// called once per such edge.
using CrossingFunction = std::function<EdgeCrossing(int inside, int outside)>;

// The rings around the grid's nodes of `label`, outer ones counterclockwise and holes clockwise,
// outside the grid counting as outside; vertices between two crossings of one curve follow that
// curve's polyline where it stays near their chord.
std::vector<RegionPolygon> TraceBoundary(const RegionGrid& grid, int label,
                                         const CrossingFunction& crossing,
                                         const std::vector<RegionCurve>& curves);

}  // namespace drillbif::internal

#endif  // DRILLBIF_REGION_REGION_BOUNDARY_H_
