#include "jobs/optimum_cache.h"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>

#include <algorithm>

#include "jobs/trace_job.h"

namespace drillbif::jobs {

OptimumCache::OptimumCache(size_t capacity, size_t regions_per_curves, int64_t max_bytes)
    : capacity_(std::max<size_t>(capacity, 1)),
      regions_per_curves_(std::max<size_t>(regions_per_curves, 1)),
      max_bytes_(std::max<int64_t>(max_bytes, 0)) {}

namespace {

template <typename T>
int64_t PayloadBytes(const std::vector<T>& v) {
  return static_cast<int64_t>(v.size() * sizeof(T));
}

}  // namespace

int64_t OptimumCache::ApproximateBytes(const OptimumCurves& curves) {
  int64_t bytes = static_cast<int64_t>(sizeof(OptimumCurves)) + PayloadBytes(curves.kinds);
  for (const RegionCurve& c : curves.region_curves) {
    bytes += PayloadBytes(c.values1) + PayloadBytes(c.values2);
  }
  return bytes;
}

int64_t OptimumCache::ApproximateBytes(const StabilityRegion& region) {
  const RegionGrid& g = region.grid;
  int64_t bytes = static_cast<int64_t>(sizeof(StabilityRegion)) + PayloadBytes(g.values1) +
                  PayloadBytes(g.values2) + PayloadBytes(g.label) + PayloadBytes(g.rop) +
                  PayloadBytes(region.signatures);
  for (const RegionPolygon& p : region.polygons) bytes += PayloadBytes(p.vertices);
  return bytes;
}

int64_t OptimumCache::bytes() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return bytes_;
}

void OptimumCache::DropRegion(Entry& entry) {
  bytes_ -= entry.regions.back().bytes;
  entry.regions.pop_back();
}

void OptimumCache::DropEntry() {
  Entry& last = entries_.back();
  while (!last.regions.empty()) DropRegion(last);
  bytes_ -= last.curves_bytes;
  entries_.pop_back();
}

void OptimumCache::Shrink() {
  while (entries_.size() > capacity_) DropEntry();
  while (bytes_ > max_bytes_ && !entries_.empty()) {
    if (entries_.size() > 1) {
      DropEntry();
    } else if (!entries_.front().regions.empty()) {
      DropRegion(entries_.front());
    } else {
      DropEntry();
    }
  }
}

std::shared_ptr<const OptimumCurves> OptimumCurvesOf(const PeriodicOrbit& start,
                                                     const TraceOptions& options,
                                                     const TraceResult& trace) {
  auto curves = std::make_shared<OptimumCurves>();
  curves->start = start;
  curves->options = options;
  curves->region_curves = RegionCurvesOf(trace.curves);
  for (const TracedCurve& c : trace.curves) curves->kinds.push_back(c.curve.kind);
  curves->failed = internal::TraceFailed(trace);
  return curves;
}

std::string OptimumCache::KeyOf(const v1::TraceRequest& request) {
  v1::TraceRequest curves_only = request;
  curves_only.clear_region();
  curves_only.clear_threads();  // the same curves on any number
  std::string bytes;
  {
    google::protobuf::io::StringOutputStream stream(&bytes);
    google::protobuf::io::CodedOutputStream out(&stream);
    out.SetSerializationDeterministic(true);
    curves_only.SerializeToCodedStream(&out);
  }
  return bytes;
}

std::list<OptimumCache::Entry>::iterator OptimumCache::Touch(const std::string& key) {
  auto it =
      std::find_if(entries_.begin(), entries_.end(), [&](const Entry& e) { return e.key == key; });
  if (it != entries_.end()) entries_.splice(entries_.begin(), entries_, it);
  return it == entries_.end() ? it : entries_.begin();
}

std::shared_ptr<const OptimumCurves> OptimumCache::FindCurves(const std::string& key) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = Touch(key);
  return it == entries_.end() ? nullptr : it->curves;
}

std::shared_ptr<const StabilityRegion> OptimumCache::FindRegion(const std::string& key, int n1,
                                                                int n2) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = Touch(key);
  if (it == entries_.end()) return nullptr;
  auto& regions = it->regions;
  const auto r = std::find_if(regions.begin(), regions.end(), [&](const HeldRegion& g) {
    return g.grid == std::make_pair(n1, n2);
  });
  if (r == regions.end()) return nullptr;
  regions.splice(regions.begin(), regions, r);
  return regions.front().region;
}

void OptimumCache::PutCurves(const std::string& key, std::shared_ptr<const OptimumCurves> curves) {
  const int64_t size = ApproximateBytes(*curves);
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = Touch(key);
  if (it != entries_.end()) {
    while (!it->regions.empty()) DropRegion(*it);  // made from the curves replaced
    bytes_ -= it->curves_bytes;
    entries_.erase(it);
  }
  if (size > max_bytes_) return;
  entries_.push_front({key, std::move(curves), size, {}});
  bytes_ += size;
  Shrink();
}

void OptimumCache::PutRegion(const std::string& key, int n1, int n2,
                             std::shared_ptr<const StabilityRegion> region) {
  const int64_t size = ApproximateBytes(*region);
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = Touch(key);
  if (it == entries_.end()) return;
  auto& regions = it->regions;
  for (auto r = regions.begin(); r != regions.end();) {
    if (r->grid == std::make_pair(n1, n2)) {
      bytes_ -= r->bytes;
      r = regions.erase(r);
    } else {
      ++r;
    }
  }
  if (size > max_bytes_) return;
  regions.push_front({std::make_pair(n1, n2), std::move(region), size});
  bytes_ += size;
  while (regions.size() > regions_per_curves_) DropRegion(*it);
  Shrink();
}

}  // namespace drillbif::jobs
