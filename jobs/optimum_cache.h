// What an optimum job computes before its query, kept for later optimum jobs of the same box:
// the traced curves (as the region and the answer use them) by the trace request, and the
// stability region by trace request and grid. For the reference (omega, a) box (omega in
// [0.05, 2], a in [0.01, 8] at b = 0.15) the curves take tens of seconds and the region seconds
// (docs/performance.md); the query alone takes milliseconds, so another margin (or `scaled`) over
// the same curves and grid is answered from here in milliseconds, and another grid without
// tracing again.
// Trace jobs of period-1 curves put theirs here too (and their region), for an optimum asked
// after the map was drawn. The server's worker pool owns one; `drillctl --local` runs one job per
// process and has none.
#ifndef DRILLBIF_JOBS_OPTIMUM_CACHE_H_
#define DRILLBIF_JOBS_OPTIMUM_CACHE_H_

#include <list>
#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "drillbif/continuation/trace.h"
#include "drillbif/region/stability_region.h"
#include "drillbif/v1/trace.pb.h"

namespace drillbif::jobs {

// A trace as the optimum uses it: the start orbit, the box, the curves' polylines and kinds.
struct OptimumCurves {
  PeriodicOrbit start;
  TraceOptions options;
  std::vector<RegionCurve> region_curves;  // RegionCurvesOf the traced curves, in their order
  std::vector<CurveKind> kinds;            // each traced curve's kind, in the same order
  bool failed = false;                     // a curve or a branch of the trace failed
};

// The curves of a trace as the optimum uses them.
std::shared_ptr<const OptimumCurves> OptimumCurvesOf(const PeriodicOrbit& start,
                                                     const TraceOptions& options,
                                                     const TraceResult& trace);

// Thread-safe. Holds the curves of at most `capacity` trace requests (least recently used
// dropped first), each with the regions of at most `regions_per_curves` grids. Only complete
// (not cancelled) curves and regions are to be put.
class OptimumCache {
 public:
  explicit OptimumCache(size_t capacity = 4, size_t regions_per_curves = 2);

  // The cache's key of a trace request: its deterministic serialization without `region` (which
  // does not change the curves; an optimum's trace has none).
  static std::string KeyOf(const v1::TraceRequest& request);

  // Null when not held.
  std::shared_ptr<const OptimumCurves> FindCurves(const std::string& key);
  std::shared_ptr<const StabilityRegion> FindRegion(const std::string& key, int n1, int n2);

  void PutCurves(const std::string& key, std::shared_ptr<const OptimumCurves> curves);
  // Kept only while the curves of `key` are held.
  void PutRegion(const std::string& key, int n1, int n2,
                 std::shared_ptr<const StabilityRegion> region);

 private:
  struct Entry {
    std::string key;
    std::shared_ptr<const OptimumCurves> curves;
    // (grid, region), most recently used first.
    std::list<std::pair<std::pair<int, int>, std::shared_ptr<const StabilityRegion>>> regions;
  };
  // The entry of `key` moved to the front, or entries_.end(). Call with mutex_ held.
  std::list<Entry>::iterator Touch(const std::string& key);

  const size_t capacity_, regions_per_curves_;
  std::mutex mutex_;
  std::list<Entry> entries_;  // most recently used first
};

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_OPTIMUM_CACHE_H_
