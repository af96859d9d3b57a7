#include "drillbif/region/robust_optimum.h"

#include <Eigen/Core>
#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <string>

#include "common/format.h"
#include "region/segment_index.h"

namespace drillbif {
namespace {

std::string Num(double v) { return internal::FormatNumber(v, 6); }

// A polygon edge lies along the box when both its ends lie on the same side of it.
bool AlongBox(const RegionVertex& a, const RegionVertex& b, const StabilityRegion& r) {
  return (a.value1 == r.min1 && b.value1 == r.min1) || (a.value1 == r.max1 && b.value1 == r.max1) ||
         (a.value2 == r.min2 && b.value2 == r.min2) || (a.value2 == r.max2 && b.value2 == r.max2);
}

// The curve an obstacle edge belongs to: the one both ends share, else whichever end is on one;
// with neither end on a curve, a seam where an end is on one (else untraced).
int EdgeCurve(const RegionVertex& a, const RegionVertex& b) {
  if (a.curve >= 0 && (b.curve == a.curve || b.curve < 0)) return a.curve;
  if (b.curve >= 0 && a.curve < 0) return b.curve;
  if (a.curve >= 0) return a.curve;
  const bool seam = a.curve == RegionVertex::kSeam || b.curve == RegionVertex::kSeam;
  return seam ? RegionVertex::kSeam : RegionVertex::kUntraced;
}

// Coordinates in which the margin neighbourhood is the unit ball of the metric: u = (x - min) / s.
struct Metric {
  Eigen::Vector2d min, scale;
  bool max_norm = false;
  Eigen::Vector2d U(double v1, double v2) const {
    return (Eigen::Vector2d(v1, v2) - min).cwiseQuotient(scale);
  }
  double Distance(const Eigen::Vector2d& u, const internal::Segment& s) const {
    return max_norm ? internal::DistanceLinf(u, s.p, s.q) : internal::DistanceL2(u, s.p, s.q);
  }
};

Metric MetricOf(const OptimumOptions& options, const Eigen::Vector2d& min,
                const Eigen::Vector2d& width) {
  Metric metric;
  metric.min = min;
  if (options.scaled) {
    metric.scale = options.margin[0] * width;
  } else {
    metric.scale = Eigen::Vector2d(options.margin.front(), options.margin.back());
    metric.max_norm = true;
  }
  return metric;
}

}  // namespace

Status OptimumOptions::Validate() const {
  if (scaled) {
    if (margin.size() != 1) {
      return InvalidArgument("margin: a scaled margin is one value, got " +
                             std::to_string(margin.size()));
    }
    if (!(margin[0] > 0.0 && margin[0] <= 0.5)) {
      return InvalidArgument(
          "margin: a scaled margin must be in (0, 0.5] (a fraction of the box), got " +
          Num(margin[0]));
    }
    return Status::Ok();
  }
  if (margin.size() == 1 || margin.size() == 2) {
    for (double m : margin) {
      if (!(m > 0.0 && std::isfinite(m))) {
        return InvalidArgument("margin: per-parameter margins must be finite and > 0, got " +
                               Num(m));
      }
    }
    return Status::Ok();
  }
  return InvalidArgument("margin: give one value (both parameters) or one per parameter, got " +
                         std::to_string(margin.size()) + " values");
}

RobustOptimum FindRobustOptimum(const StabilityRegion& region, const OptimumOptions& options,
                                const ProgressCallback& progress) {
  RobustOptimum best;
  ProgressThrottle throttle(progress);
  auto cancelled = [&] {
    RobustOptimum out;
    out.summary.Cancel("robust optimum cancelled");
    out.summary.candidates = best.summary.candidates;
    return out;
  };
  if (Status s = options.Validate(); !s.ok()) {
    best.summary.Fail(s);
    return best;
  }
  // (Not `completed()`: a region assembled by hand, with its summary left as constructed, is
  // searched too; a failed one always has a status saying why.)
  if (region.summary.cancelled() || !region.summary.status.ok()) {
    best.summary.Fail(FailedPrecondition(
        "the stability region was not computed: " +
        (region.summary.cancelled() ? std::string("cancelled") : region.summary.status.message())));
    return best;
  }
  const RegionGrid& g = region.grid;
  if (g.n1 < 2 || g.n2 < 2 || g.label.size() != static_cast<size_t>(g.n1) * g.n2 ||
      g.rop.size() != g.label.size()) {
    best.summary.Fail(InvalidArgument("region: no grid"));
    return best;
  }
  const Eigen::Vector2d width(region.width1(), region.width2());
  const Metric metric = MetricOf(options, Eigen::Vector2d(region.min1, region.min2), width);
  const Eigen::Vector2d extent = width.cwiseQuotient(metric.scale);  // box size in metric units

  // Obstacles in metric coordinates, bucketed in cells of about one margin (at most 256 a side).
  const int nx = std::clamp(static_cast<int>(std::ceil(extent[0])), 1, 256);
  const int ny = std::clamp(static_cast<int>(std::ceil(extent[1])), 1, 256);
  internal::SegmentIndex obstacles(Eigen::Vector2d::Zero(), extent, nx, ny);
  if (!throttle.Tick()) return cancelled();
  for (const BoundarySegment& e : RegionObstacles(region)) {
    obstacles.Add({metric.U(e.a1, e.a2), metric.U(e.b1, e.b2), e.curve});
  }
  if (!throttle.Tick()) return cancelled();

  std::vector<int> order;
  for (size_t k = 0; k < g.label.size(); ++k) {
    if (g.Inside(static_cast<int>(k))) order.push_back(static_cast<int>(k));
  }
  const std::vector<int> inside = order;
  // By decreasing ROP, ties by increasing index, taken from a heap: the search usually ends
  // after a few nodes, and building the heap (linear) leaves no long step without a poll, as
  // sorting 4e6 nodes would (~0.3 s).
  const auto after = [&](int x, int y) {
    return g.rop[x] < g.rop[y] || (g.rop[x] == g.rop[y] && x > y);
  };
  std::make_heap(order.begin(), order.end(), after);
  if (!throttle.Continue()) return cancelled();
  const Eigen::Vector2d one(1.0, 1.0);
  int found = -1;
  // Progress: the candidates checked of all inside nodes (the search ends at the first that
  // passes), then, where none does, those whose largest margin is known.
  const double total = 2.0 * std::max<size_t>(inside.size(), 1);
  while (!order.empty()) {
    if (!throttle.Tick(static_cast<double>(best.summary.candidates) / total)) return cancelled();
    std::pop_heap(order.begin(), order.end(), after);
    const int node = order.back();
    order.pop_back();
    ++best.summary.candidates;
    const Eigen::Vector2d u = metric.U(g.values1[node % g.n1], g.values2[node / g.n1]);
    bool clear = true;
    obstacles.ForEachNear(u - one, u + one, [&](const internal::Segment& s) {
      if (clear && metric.Distance(u, s) < 1.0) clear = false;
    });
    if (clear) {
      found = node;
      break;
    }
  }

  auto nearest = [&](const Eigen::Vector2d& u, int* curve) {
    double d = std::numeric_limits<double>::infinity();
    for (const internal::Segment& s : obstacles.segments()) {
      const double ds = metric.Distance(u, s);
      if (ds < d) d = ds, *curve = s.tag;
    }
    return d;
  };
  if (found < 0) {
    double largest = 0.0;
    int curve = 0;
    double measured = 0.0;
    for (int node : inside) {
      // One nearest() is a pass over every obstacle: the clock read each time is nothing.
      if (!throttle.Continue(0.5 + measured++ / total)) return cancelled();
      largest = std::max(largest,
                         nearest(metric.U(g.values1[node % g.n1], g.values2[node / g.n1]), &curve));
    }
    best.summary.Fail(NotFound(
        inside.empty() ? std::string("the stability region has no grid node inside")
                       : "no grid node of the stability region is that far from its boundary "
                         "curves: the largest margin any node has is " +
                             Num(largest) + " times the one asked"));
    return best;
  }
  best.node = found;
  best.value1 = g.values1[found % g.n1];
  best.value2 = g.values2[found / g.n1];
  best.rop = g.rop[found];
  const Eigen::Vector2d u = metric.U(best.value1, best.value2);
  const double k = nearest(u, &best.nearest_curve);
  if (options.scaled) {
    best.margin = {k * options.margin[0]};
  } else {
    best.margin = {k * metric.scale[0], k * metric.scale[1]};
  }
  // Euclidean distance in the box's unit square (the metric scaled back).
  const Eigen::Vector2d to_unit = metric.scale.cwiseQuotient(width);
  best.distance_scaled = std::numeric_limits<double>::infinity();
  for (const internal::Segment& s : obstacles.segments()) {
    best.distance_scaled =
        std::min(best.distance_scaled,
                 internal::DistanceL2(u.cwiseProduct(to_unit), s.p.cwiseProduct(to_unit),
                                      s.q.cwiseProduct(to_unit)));
  }
  best.near_box_edge = (u.array() < 1.0).any() || (u.array() > extent.array() - 1.0).any();
  best.summary.Complete();
  return best;
}

std::vector<BoundarySegment> RegionObstacles(const StabilityRegion& region) {
  std::vector<BoundarySegment> out;
  for (const RegionPolygon& ring : region.polygons) {
    const size_t n = ring.vertices.size();
    for (size_t k = 0; k < n; ++k) {
      const RegionVertex& a = ring.vertices[k];
      const RegionVertex& b = ring.vertices[(k + 1) % n];
      if (AlongBox(a, b, region)) continue;
      out.push_back({a.value1, a.value2, b.value1, b.value2, EdgeCurve(a, b)});
    }
  }
  return out;
}

MarginMetric::MarginMetric(const OptimumOptions& options, double width1, double width2) {
  const Metric metric = MetricOf(options, Eigen::Vector2d::Zero(), Eigen::Vector2d(width1, width2));
  scale1_ = metric.scale[0];
  scale2_ = metric.scale[1];
  max_norm_ = metric.max_norm;
}

double MarginMetric::Distance(double v1, double v2, const BoundarySegment& s) const {
  const Eigen::Vector2d scale(scale1_, scale2_);
  const Eigen::Vector2d u = Eigen::Vector2d(v1, v2).cwiseQuotient(scale);
  const Eigen::Vector2d p = Eigen::Vector2d(s.a1, s.a2).cwiseQuotient(scale);
  const Eigen::Vector2d q = Eigen::Vector2d(s.b1, s.b2).cwiseQuotient(scale);
  return max_norm_ ? internal::DistanceLinf(u, p, q) : internal::DistanceL2(u, p, q);
}

double MarginMetric::Distance(double v1, double v2, double w1, double w2) const {
  const double d1 = (v1 - w1) / scale1_, d2 = (v2 - w2) / scale2_;
  return max_norm_ ? std::max(std::abs(d1), std::abs(d2)) : std::hypot(d1, d2);
}

std::string OptimumSummary::BriefReport() const {
  return RunSummary::BriefReport(CountOf(candidates, "candidate"));
}

}  // namespace drillbif
