// The period-2n grazing curves that leave period-n flip-grazing points
// (continuation/trace_internal.h).
//
// At a flip-grazing point a period-n PD curve ends on a period-n grazing curve. The period-2n
// orbit born along the PD curve has two passes x0 +- eps v, eps ~ sqrt(distance from the PD
// curve); the pass moved towards the boundary grazes where eps is of the order of the period-1
// orbit's distance from grazing, which vanishes at the flip-grazing point: a period-2n grazing
// curve leaves that point, tangent to the PD curve. It is found from a PD-curve vertex a little
// away from the point: algebraic switching onto the period-2n branch there, continuation in one
// parameter to the branch's first grazing, and the grazing curve through it, kept when it comes
// closer to the point than the vertex it was found from.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "continuation/trace_internal.h"

namespace drillbif::internal {

namespace {

// Scaled distance of the PD-curve vertex the period-2 branch is started from: far enough that
// the period-2 orbit's passes can differ by more than the corrector's tolerance without either
// grazing at once, near enough that the first grazing is the one leaving the point.
constexpr double kSeedDistance = 2e-3;
// A PD curve passes through the point when one of its vertices or codimension-2 points is this
// close (scaled). PD curve ends located only to a wider bracket give no seed (named in a note).
constexpr double kOnCurve = 1e-4;
// Two flip-grazings this close (scaled) are one (the same point found as a grazing curve's root
// and as a PD curve's end agree to ~1e-11 when both converged).
constexpr double kSamePoint = 1e-5;

struct Seed {
  const CurvePoint* point;
  double distance;  // scaled, from the flip-grazing point
};

// The vertices of period-n PD curves through (u, v), about kSeedDistance from it along each
// curve on either side.
std::vector<Seed> SeedsNear(const TraceResult& result, int n, double u, double v, double w1,
                            double w2) {
  std::vector<Seed> seeds;
  auto distance = [&](const CurvePoint& p) {
    return std::hypot((p.value1 - u) / w1, (p.value2 - v) / w2);
  };
  for (const TracedCurve& t : result.curves) {
    const std::vector<CurvePoint>& pts = t.curve.points;
    if (t.curve.kind != CurveKind::kPeriodDoubling || pts.empty() ||
        pts.front().orbit.signature.periods != n) {
      continue;
    }
    size_t nearest = 0;
    for (size_t i = 1; i < pts.size(); ++i) {
      if (distance(pts[i]) < distance(pts[nearest])) nearest = i;
    }
    // A curve ending at the point has it as a codimension-2 point, off its last vertex by up to
    // a step.
    const bool ends_there =
        std::any_of(t.curve.codim2.begin(), t.curve.codim2.end(), [&](const Codim2Point& z) {
          return std::hypot((z.point.value1 - u) / w1, (z.point.value2 - v) / w2) <= kOnCurve;
        });
    if (distance(pts[nearest]) > kOnCurve && !ends_there) continue;
    for (int step : {-1, 1}) {
      for (long i = static_cast<long>(nearest); i >= 0 && i < static_cast<long>(pts.size());
           i += step) {
        if (distance(pts[i]) >= kSeedDistance) {
          seeds.push_back({&pts[i], distance(pts[i])});
          break;
        }
      }
    }
  }
  return seeds;
}

}  // namespace

bool GrazingCurvesAtFlipGrazings(const HybridModel& model, Propagator& propagator,
                                 const TraceOptions& options,
                                 const std::function<bool(double)>& report, size_t first_curve,
                                 TraceResult* result) {
  const double w1 = options.max1 - options.min1, w2 = options.max2 - options.min2;
  const std::string* names[2] = {&options.param1, &options.param2};
  const double lo[2] = {options.min1, options.min2}, hi[2] = {options.max1, options.max2};
  const double width[2] = {w1, w2};
  const int index[2] = {model.ParamIndex(options.param1).value(),
                        model.ParamIndex(options.param2).value()};
  struct Handled {
    int periods;
    double u, v;  // scaled
  };
  std::vector<Handled> handled;  // flip-grazings tried
  std::vector<int> found(options.max_period + 1, 0), tried(options.max_period + 1, 0);
  // result->curves grows while it is walked (the curves added here have flip-grazings too):
  // index, not iterator.
  for (size_t c = first_curve; c < result->curves.size(); ++c) {
    for (size_t q = 0; q < result->curves[c].curve.codim2.size(); ++q) {
      const Codim2Point& point = result->curves[c].curve.codim2[q];
      const int n = point.point.orbit.signature.periods;
      if (point.kind != Codim2Kind::kFlipGrazing || 2 * n > options.max_period) continue;
      const double u = point.point.value1, v = point.point.value2;
      if (std::any_of(handled.begin(), handled.end(), [&](const Handled& h) {
            return h.periods == n && std::hypot(h.u - u / w1, h.v - v / w2) <= kSamePoint;
          })) {
        continue;
      }
      handled.push_back({n, u / w1, v / w2});
      ++tried[n];
      if (!report(0.995)) return false;
      const std::string where = PeriodPrefix(n) + "FLIP_GRAZING at " + options.param1 + " = " +
                                std::to_string(u) + ", " + options.param2 + " = " +
                                std::to_string(v);
      const std::vector<Seed> seeds = SeedsNear(*result, n, u, v, w1, w2);
      std::string why = seeds.empty() ? "no PD curve vertex within 1e-4 of it" : "";
      bool done = false;
      for (const Seed& seed : seeds) {
        const PeriodicOrbit& pd = seed.point->orbit;
        // First the parameter along which the seed lies farther from the point: continued in
        // it, the period-2 branch heads along the PD curve towards the point.
        const double along[2] = {std::abs(pd.params[index[0]] - u) / w1,
                                 std::abs(pd.params[index[1]] - v) / w2};
        const int first = along[0] >= along[1] ? 0 : 1;
        for (int a : {first, 1 - first}) {
          const StatusOr<PeriodicOrbit> doubled =
              SwitchAtPeriodDoublingAlgebraic(model, propagator, pd, *names[a]);
          if (!doubled.ok()) {
            why = doubled.status().message();
            continue;
          }
          ContinuationOptions branch = options.branch;
          branch.locate_measure_maxima = false;
          branch.point_measures = 0u;
          branch.param = *names[a];
          branch.min = lo[a];
          branch.max = hi[a];
          branch.direction = doubled->params[index[a]] > pd.params[index[a]]
                                 ? ContinuationDirection::kIncreasing
                                 : ContinuationDirection::kDecreasing;
          branch.stop_at = {SpecialPointKind::kGrazingL1, SpecialPointKind::kGrazingL2,
                            SpecialPointKind::kGrazingPi};
          // The grazing sought lies within ~ the seed's distance; give up well beyond it.
          const double start_value = pd.params[index[a]];
          const ContinuationResult r = Continue(
              model, propagator, *doubled, branch, [&](const ContinuationPoint& p, double) {
                return std::abs(p.value - start_value) / width[a] <= 4.0 * seed.distance;
              });
          const auto graze = std::find_if(r.special_points.begin(), r.special_points.end(),
                                          [](const SpecialPoint& s) { return IsGrazing(s.kind); });
          if (graze == r.special_points.end()) {
            why = "the period-" + std::to_string(2 * n) + " branch in " + *names[a] +
                  " does not graze near it";
            continue;
          }
          const double gu = graze->point.orbit.params[index[0]];
          const double gv = graze->point.orbit.params[index[1]];
          const bool known =
              std::any_of(result->curves.begin(), result->curves.end(), [&](const TracedCurve& t) {
                return t.curve.kind == CurveKind::kGrazing && !t.curve.points.empty() &&
                       t.curve.points.front().orbit.signature.periods == 2 * n &&
                       DistanceToCurve(t.curve, gu, gv, w1, w2) <= options.duplicate_distance;
              });
          if (known) {
            done = true;
            break;
          }
          CurveOptions co = options.curve;
          co.param1 = *names[a], co.min1 = lo[a], co.max1 = hi[a];
          co.param2 = *names[1 - a], co.min2 = lo[1 - a], co.max2 = hi[1 - a];
          if (a == 1) std::swap(co.crossings1, co.crossings2);
          if (propagator.stopped()) return false;
          CurveResult curve = ContinueCurve(model, propagator, *graze, co);
          if (propagator.stopped()) {
            // Cut short by a stop: kept with what it has (termination kCancelled), if anything.
            if (a == 1) SwapValues(&curve);
            if (!curve.points.empty()) {
              result->curves.push_back(
                  {*graze, "", std::move(curve), static_cast<int>(c), static_cast<int>(q)});
            }
            return false;
          }
          if (curve.summary.termination == Termination::kFailed) {
            why = "the grazing curve failed: " + curve.summary.message;
            continue;
          }
          if (a == 1) SwapValues(&curve);
          double closest = DistanceToCurve(curve, u, v, w1, w2);
          for (const Codim2Point& z : curve.codim2) {
            closest =
                std::min(closest, std::hypot((z.point.value1 - u) / w1, (z.point.value2 - v) / w2));
          }
          if (closest >= seed.distance) {
            why = "the grazing curve found does not approach it";
            continue;
          }
          result->curves.push_back(
              {*graze, "", std::move(curve), static_cast<int>(c), static_cast<int>(q)});
          done = true;
          break;
        }
        if (done) break;
      }
      if (propagator.stopped()) return false;  // `why` is not to be trusted
      if (done) {
        ++found[n];
      } else {
        result->summary.notes.push_back(where + ": no period-" + std::to_string(2 * n) +
                                        " grazing curve leaving it: " + why);
      }
    }
  }
  for (int n = 1; 2 * n <= options.max_period; n *= 2) {
    if (tried[n] == 0) continue;
    result->summary.notes.push_back("period-" + std::to_string(2 * n) + " grazing curves leave " +
                                    std::to_string(found[n]) + " of " + std::to_string(tried[n]) +
                                    " period-" + std::to_string(n) + " flip-grazing points");
  }
  return true;
}

namespace {

// The required location tolerance: ends within it are left as they are by EndsAtFlipGrazings.
constexpr double kLocated = 1e-8;

// Whether EndsAtFlipGrazings looks at the point: an end of even period beyond kLocated.
bool MergeCandidate(const Codim2Point& z) {
  return z.bracket > kLocated && !z.violation.admissible &&
         z.point.orbit.signature.periods % 2 == 0;
}

}  // namespace

bool MayMergeAtFlipGrazing(const TracedCurve& curve) {
  return std::any_of(curve.curve.codim2.begin(), curve.curve.codim2.end(), MergeCandidate);
}

int EndsAtFlipGrazings(const HybridModel& model, const TraceOptions& options, TraceResult* result) {
  // The passes of a period-2n orbit born at a PD differ by eps ~ sqrt(mu), mu the distance from
  // the PD curve; at the box's 405 such ends the section state's largest component difference
  // from the period-n orbit's is at most 3.9 sqrt(d) (d: their scaled parameter distance,
  // 1e-12 .. 1e-5; over the three components, so the distance at most 6.8 sqrt(d)), while
  // the period-2n ends that are not such merges lie 2e-4 or more from any period-n
  // flip-grazing. 10 allows for the constant of other orbits; 1e-9 for the corrector's rounding.
  constexpr double kPassSplit = 10.0;
  const double w1 = options.max1 - options.min1, w2 = options.max2 - options.min2;
  struct Flip {
    size_t curve;
    Codim2Point point;
  };
  std::vector<Flip> flips;
  for (size_t c = 0; c < result->curves.size(); ++c) {
    for (const Codim2Point& q : result->curves[c].curve.codim2) {
      if (q.kind == Codim2Kind::kFlipGrazing && q.bracket <= kLocated) flips.push_back({c, q});
    }
  }
  int merged = 0;
  for (TracedCurve& t : result->curves) {
    for (Codim2Point& z : t.curve.codim2) {
      const int periods = z.point.orbit.signature.periods;
      if (!MergeCandidate(z)) continue;
      const Flip* nearest = nullptr;
      double d = kOnCurve;
      for (const Flip& f : flips) {
        const double df = std::hypot((f.point.point.value1 - z.point.value1) / w1,
                                     (f.point.point.value2 - z.point.value2) / w2);
        if (f.point.point.orbit.signature.periods == periods / 2 && df <= d) nearest = &f, d = df;
      }
      if (nearest == nullptr || DistanceWithoutPhase(model, z.point.orbit.starts[0],
                                                     nearest->point.point.orbit.starts[0]) >
                                    kPassSplit * std::sqrt(d) + 1e-9) {
        continue;
      }
      char beyond[64];
      std::snprintf(beyond, sizeof beyond, " (%.1e away in arclength)", z.bracket);
      z.detail = "the period-" + std::to_string(periods) + " orbit becomes the period-" +
                 std::to_string(periods / 2) + " orbit traversed twice: the " +
                 PeriodPrefix(periods / 2) + "FLIP_GRAZING of curve " +
                 std::to_string(nearest->curve) + "; beyond the last admissible point" + beyond +
                 ": " + z.detail;
      z.kind = Codim2Kind::kFlipGrazing;
      z.point = nearest->point.point;
      z.bracket = nearest->point.bracket;
      ++merged;
    }
  }
  return merged;
}

}  // namespace drillbif::internal
