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

#include <cstdint>
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
// dropped first), each with the regions of at most `regions_per_curves` grids, and at most
// `max_bytes` of them in all (ApproximateBytes): the least recently used are dropped first, and
// curves or a region larger than `max_bytes` on their own are not kept. The byte bound is what
// keeps a server's memory between jobs independent of the jobs it ran: the largest admitted
// region alone is ~20 MB, and a count bound would let eight of them stay. Only complete (not
// cancelled) curves and regions are to be put.
class OptimumCache {
 public:
  // 256 MiB: a whole-box trace's curves take ~10 MB and a 1000 x 1000 region ~12 MB, so the
  // default keeps every entry the count allows for usual grids, and far less than a job's memory
  // limit for the largest.
  static constexpr int64_t kDefaultMaxBytes = int64_t{256} << 20;

  explicit OptimumCache(size_t capacity = 4, size_t regions_per_curves = 2,
                        int64_t max_bytes = kDefaultMaxBytes);

  // What curves or a region hold in memory, approximately (their vectors' payloads).
  static int64_t ApproximateBytes(const OptimumCurves& curves);
  static int64_t ApproximateBytes(const StabilityRegion& region);

  // The approximate bytes held now.
  int64_t bytes() const;

  // The cache's key of a trace request: its deterministic serialization without `region` (which
  // does not change the curves; an optimum's trace has none) and `threads` (nor do they).
  static std::string KeyOf(const v1::TraceRequest& request);

  // Null when not held.
  std::shared_ptr<const OptimumCurves> FindCurves(const std::string& key);
  std::shared_ptr<const StabilityRegion> FindRegion(const std::string& key, int n1, int n2);

  void PutCurves(const std::string& key, std::shared_ptr<const OptimumCurves> curves);
  // Kept only while the curves of `key` are held.
  void PutRegion(const std::string& key, int n1, int n2,
                 std::shared_ptr<const StabilityRegion> region);

 private:
  struct HeldRegion {
    std::pair<int, int> grid;
    std::shared_ptr<const StabilityRegion> region;
    int64_t bytes = 0;
  };
  struct Entry {
    std::string key;
    std::shared_ptr<const OptimumCurves> curves;
    int64_t curves_bytes = 0;
    std::list<HeldRegion> regions;  // most recently used first
  };
  // The entry of `key` moved to the front, or entries_.end(). Call with mutex_ held.
  std::list<Entry>::iterator Touch(const std::string& key);
  // Drops the least recently used regions and entries until bytes_ <= max_bytes_. With mutex_.
  void Shrink();
  void DropRegion(Entry& entry);  // its least recently used region; with mutex_ held
  void DropEntry();               // the least recently used entry; with mutex_ held

  const size_t capacity_, regions_per_curves_;
  const int64_t max_bytes_;
  mutable std::mutex mutex_;
  std::list<Entry> entries_;  // most recently used first
  int64_t bytes_ = 0;         // approximate bytes of every entry's curves and regions
};

}  // namespace drillbif::jobs

#endif  // DRILLBIF_JOBS_OPTIMUM_CACHE_H_
