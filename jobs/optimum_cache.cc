#include "jobs/optimum_cache.h"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>

#include <algorithm>

#include "jobs/trace_job.h"

namespace drillbif::jobs {

OptimumCache::OptimumCache(size_t capacity, size_t regions_per_curves)
    : capacity_(std::max<size_t>(capacity, 1)),
      regions_per_curves_(std::max<size_t>(regions_per_curves, 1)) {}

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
  const auto r = std::find_if(regions.begin(), regions.end(),
                              [&](const auto& g) { return g.first == std::make_pair(n1, n2); });
  if (r == regions.end()) return nullptr;
  regions.splice(regions.begin(), regions, r);
  return regions.front().second;
}

void OptimumCache::PutCurves(const std::string& key, std::shared_ptr<const OptimumCurves> curves) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = Touch(key);
  if (it != entries_.end()) {
    it->curves = std::move(curves);
    it->regions.clear();  // made from the curves replaced
    return;
  }
  entries_.push_front({key, std::move(curves), {}});
  if (entries_.size() > capacity_) entries_.pop_back();
}

void OptimumCache::PutRegion(const std::string& key, int n1, int n2,
                             std::shared_ptr<const StabilityRegion> region) {
  std::lock_guard<std::mutex> lock(mutex_);
  const auto it = Touch(key);
  if (it == entries_.end()) return;
  auto& regions = it->regions;
  regions.remove_if([&](const auto& g) { return g.first == std::make_pair(n1, n2); });
  regions.emplace_front(std::make_pair(n1, n2), std::move(region));
  if (regions.size() > regions_per_curves_) regions.pop_back();
}

}  // namespace drillbif::jobs
