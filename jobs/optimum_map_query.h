// Optimum queries answered from a stored optimum map (optimum_map_job.h): at conditions between
// the map's cells, the operating point interpolated from the neighbouring cells' optima
// (linearly in one condition, bilinearly in two), then verified at the conditions asked:
//   - the neighbouring cells' optima lie on the same orbit (signature), so interpolating them
//     means something;
//   - the point is within three margins of each neighbouring cell's optimum, so every boundary
//     segment a cell left out (beyond four margins) is more than a margin away;
//   - the point is at least the margin from every neighbouring cell's boundary segments;
//   - Newton from the nearest cell's orbit converges at the conditions asked, and the orbit is
//     admissible and stable; its ROP is the answer's.
// When a check fails, the nearest cell's operating point is checked the same way instead (or the
// caller computes a fresh optimum, as the query asks).
#ifndef DRILLBIF_JOBS_OPTIMUM_MAP_QUERY_H_
#define DRILLBIF_JOBS_OPTIMUM_MAP_QUERY_H_

#include <optional>
#include <string>
#include <vector>

#include "drillbif/common/status.h"
#include "drillbif/v1/optimum_map.pb.h"
#include "drillbif/v1/service.pb.h"
#include "jobs/optimum_map_job.h"

namespace drillbif::jobs {

// A stored map as queries use it.
struct LoadedMap {
  std::string operation;  // "operations/{id}"
  v1::OptimumMapRequest request;
  OptimumMapPlan plan;
  std::vector<std::optional<v1::OptimumMapCell>> cells;  // by flat index (CellIndex)
  int64_t bytes = 0;                                     // the cells' serialized size
};

// A map from its stored request and cells. INVALID_ARGUMENT when the request does not plan or a
// cell's index lies outside it.
StatusOr<LoadedMap> LoadMap(std::string operation, const v1::OptimumMapRequest& request,
                            std::vector<v1::OptimumMapCell> cells);

// What a map and the optimum requests it answers share: the request with every model parameter
// made explicit, the conditions' values and the threads cleared, and the conditions' names.
std::string MapQueryKey(const v1::OptimumRequest& optimum, const std::vector<std::string>& over);

// The query's value of each of the map's conditions.
std::vector<double> QueryConditions(const LoadedMap& map, const v1::OptimumRequest& query);
// How far the conditions lie outside the map, in cells (0: inside).
double CellsOutside(const LoadedMap& map, const std::vector<double>& conditions);

// The answer at the query's conditions (inside the map, same MapQueryKey). `optimum` is set
// (status COMPLETED) whenever `from_map.verified`; with `nearest_on_failure` the nearest cell's
// point is tried when the interpolated one fails (from_map.interpolated false then), and set
// (unverified, status FAILED with the reason) when it fails too. Without it, a failed
// interpolation leaves `optimum` with status FAILED and the reason.
struct MapQueryAnswer {
  v1::OptimumResult optimum;
  v1::MapAnswer from_map;
};
MapQueryAnswer AnswerFromMap(const LoadedMap& map, const v1::OptimumRequest& query,
                             bool nearest_on_failure);

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_OPTIMUM_MAP_QUERY_H_
