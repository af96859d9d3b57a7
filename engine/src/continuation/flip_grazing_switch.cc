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
#include <map>
#include <set>
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
  const double w1 = options.width1(), w2 = options.width2();
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
          ContinuationOptions branch = options.BranchOptions(doubled->signature.periods);
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
                       OnTracedCurve(t, gu, gv, w1, w2, options.duplicate_distance);
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
              AppendCurve(*graze, "", std::move(curve), result, static_cast<int>(c),
                          static_cast<int>(q));
            }
            return false;
          }
          if (curve.summary.termination == Termination::kFailed) {
            why = "the grazing curve failed: " + curve.summary.message;
            continue;
          }
          if (a == 1) SwapValues(&curve);
          double closest = DistanceToCurve(OutlineOf(curve), u, v, w1, w2);
          for (const Codim2Point& z : curve.codim2) {
            closest =
                std::min(closest, std::hypot((z.point.value1 - u) / w1, (z.point.value2 - v) / w2));
          }
          if (closest >= seed.distance) {
            why = "the grazing curve found does not approach it";
            continue;
          }
          AppendCurve(*graze, "", std::move(curve), result, static_cast<int>(c),
                      static_cast<int>(q));
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

// The required location tolerance: ends within it are left as they are by EndsAtFlipGrazings
// (unless they are the points below).
constexpr double kLocated = 1e-8;
// A root of det(M - I) along a period-2n curve, or an end bisected but not solved, that lies this
// close (box-scaled) to a located period-n FLIP_GRAZING, its orbit the period-n orbit's to the
// passes' split: that flip-grazing. There the period-2n orbit is the period-n orbit traversed
// twice, whose multiplier -1 squared is the +1 the root saw, and the curve's system is singular
// (its roots and ends are located only to where Newton still converges). In the reference box
// with max_period 2 such roots of the period-2 grazing curves lie up to 1.1e-7 from their
// flip-grazing, bisected ends of period-2 fold and grazing curves up to 5.6e-8; the nearest
// root found on two curves alike (a distinct point) lies 7.3e-7 away.
constexpr double kIndistinct = 3e-7;
// Two entries of one kind and period this close (box-scaled) are one point: the copies of a
// point met from several curves agree to ~1e-11 where each was solved (in the reference box the
// count of entries taken as copies grows by 0.3% from 1e-12 to 1e-9, and by 0.2% more up to
// 1e-8).
constexpr double kCopy = 1e-9;
// kPassSplit: see EndsAtFlipGrazings.
constexpr double kPassSplit = 10.0;

bool HasSolvedEnd(const Codim2Point& z) {
  return z.detail.find("(solved ") != std::string::npos ||
         z.detail.find("(extrapolated ") != std::string::npos;
}

// A root of a test function along the curve (no violation beyond, no detail).
bool IsRoot(const Codim2Point& z) { return z.violation.admissible && z.detail.empty(); }

// A curve's end bisected but not solved as the point it is (its bracket the bisection's).
bool IsBisectedEnd(const Codim2Point& z) { return !z.violation.admissible && !HasSolvedEnd(z); }

// Whether EndsAtFlipGrazings looks at the point of a curve of even period: an end beyond
// kLocated (the orbit merging into the period-n one traversed twice), or a point that may be the
// period-n flip-grazing itself: a root of det(M - I) (FOLD_GRAZING on a grazing curve, FOLD_FLIP
// on a PD curve) or an end bisected but not solved.
bool MergeCandidate(const Codim2Point& z) {
  if (z.point.orbit.signature.periods % 2 != 0) return false;
  if (!z.violation.admissible && z.bracket > kLocated) return true;
  const bool det_root =
      IsRoot(z) && (z.kind == Codim2Kind::kFoldGrazing || z.kind == Codim2Kind::kFoldFlip);
  return det_root || IsBisectedEnd(z);
}

// A switched curve that made no step either way: its ends are its start.
bool NoStep(const TracedCurve& t) { return t.from_curve >= 0 && t.curve.points.size() == 1; }

// The curve's message with the end's description `before` (EndAtBoundary: "ended at a KIND
// point: detail") replaced by the entry's as it is now.
void RenameEnd(const std::string& before, const Codim2Point& z, std::string* message) {
  const std::string after =
      std::string("ended at a ") + Codim2KindName(z.kind) + " point: " + z.detail;
  const size_t at = message->find(before);
  if (at != std::string::npos) message->replace(at, before.size(), after);
}

std::string EndText(const Codim2Point& z) {
  return std::string("ended at a ") + Codim2KindName(z.kind) + " point: " + z.detail;
}

}  // namespace

bool MayMergeAtFlipGrazing(const TracedCurve& curve) {
  if (curve.curve.points.empty()) return false;
  if (NoStep(curve) && curve.curve.points.front().orbit.signature.periods % 2 == 0) return true;
  return std::any_of(curve.curve.codim2.begin(), curve.curve.codim2.end(), MergeCandidate);
}

int EndsAtFlipGrazings(const HybridModel& model, const TraceOptions& options, TraceResult* result) {
  // The passes of a period-2n orbit born at a PD differ by eps ~ sqrt(mu), mu the distance from
  // the PD curve; at the box's 405 such ends the section state's largest component difference
  // from the period-n orbit's is at most 3.9 sqrt(d) (d: their scaled parameter distance,
  // 1e-12 .. 1e-5; over the three components, so the distance at most 6.8 sqrt(d)), while
  // the period-2n ends that are not such merges lie 2e-4 or more from any period-n
  // flip-grazing. kPassSplit = 10 allows for the constant of other orbits; 1e-9 for the
  // corrector's rounding.
  const double w1 = options.width1(), w2 = options.width2();
  auto distance = [&](const Codim2Point& a, const Codim2Point& b) {
    return std::hypot((a.point.value1 - b.point.value1) / w1,
                      (a.point.value2 - b.point.value2) / w2);
  };
  struct Flip {
    size_t curve;
    size_t index;
    Codim2Point point;
  };
  std::vector<Flip> flips;
  for (size_t c = 0; c < result->curves.size(); ++c) {
    const std::vector<Codim2Point>& codim2 = result->curves[c].curve.codim2;
    for (size_t i = 0; i < codim2.size(); ++i) {
      const Codim2Point& q = codim2[i];
      if (q.kind != Codim2Kind::kFlipGrazing || q.bracket > kLocated) continue;
      // Copies of one point (found from several curves): the first, which reports it (below).
      const bool copy = std::any_of(flips.begin(), flips.end(), [&](const Flip& f) {
        return f.point.point.orbit.signature.periods == q.point.orbit.signature.periods &&
               distance(f.point, q) <= kCopy;
      });
      if (!copy) flips.push_back({c, i, q});
    }
  }
  int merged = 0, merged_roots = 0;
  std::set<const Codim2Point*> done;  // merged entries
  // Merges z into the flip-grazing f (d: their box-scaled distance).
  auto merge = [&](const Flip& f, double d, Codim2Point* z, std::string* message) {
    done.insert(z);
    const int periods = z->point.orbit.signature.periods;
    const std::string before = EndText(*z);
    const bool root = IsRoot(*z);
    char how[96];
    if (root) {
      std::snprintf(how, sizeof how, "; the root of det(M - I) along the curve (%.1e away)", d);
    } else {
      std::snprintf(how, sizeof how, "; beyond the last admissible point (%.1e away in arclength)",
                    z->bracket);
    }
    z->detail = "the period-" + std::to_string(periods) + " orbit becomes the period-" +
                std::to_string(periods / 2) + " orbit traversed twice: the " +
                PeriodPrefix(periods / 2) + "FLIP_GRAZING of curve " + std::to_string(f.curve) +
                how + (z->detail.empty() ? "" : ": " + z->detail);
    z->kind = Codim2Kind::kFlipGrazing;
    z->point = f.point.point;
    z->bracket = f.point.bracket;
    if (!root) RenameEnd(before, *z, message);
    ++(root ? merged_roots : merged);
  };
  // The flip-grazing of half the period within `radius` of z, nearest (the first of equals),
  // whose section state z's is within the passes' split of; nullptr if none.
  auto flip_at = [&](const Codim2Point& z, double radius, double* d) -> const Flip* {
    const Flip* nearest = nullptr;
    *d = radius;
    for (const Flip& f : flips) {
      const double df = distance(f.point, z);
      if (f.point.point.orbit.signature.periods == z.point.orbit.signature.periods / 2 &&
          (nearest == nullptr ? df <= *d : df < *d)) {
        nearest = &f, *d = df;
      }
    }
    if (nearest == nullptr ||
        DistanceWithoutPhase(model, z.point.orbit.starts[0], nearest->point.point.orbit.starts[0]) >
            kPassSplit * std::sqrt(*d) + 1e-9) {
      return nullptr;
    }
    return nearest;
  };
  for (TracedCurve& t : result->curves) {
    std::string& message = t.curve.summary.message;
    // Ends first: an end beyond kLocated within kOnCurve, a bisected end within kIndistinct. Each
    // merged end is kept as it was (its last admissible point and bracket) for the roots below.
    struct MergedEnd {
      const Flip* flip;
      CurvePoint last;
      double bracket;
    };
    std::vector<MergedEnd> ends;
    for (Codim2Point& z : t.curve.codim2) {
      if (!MergeCandidate(z) || IsRoot(z)) continue;
      double d = 0.0;
      const bool wide = z.bracket > kLocated;
      const Flip* f = flip_at(z, wide ? kOnCurve : kIndistinct, &d);
      if (f == nullptr) continue;
      ends.push_back({f, z.point, z.bracket});
      merge(*f, d, &z, &message);
    }
    // Then the roots of det(M - I): where the curve ends at the flip-grazing, its orbit is the
    // period-n orbit traversed twice, whose multiplier -1 squared is +1, so det(M - I) changes
    // sign at the end: a root within the end's bracket (arclength, parameters included) of its
    // last admissible point is not told apart from the end (where Newton fails beyond the last
    // admissible point: bisections that corrected every midpoint in full left the end at the
    // flip-grazing (0.4734, 0.1616) of the reference box bracketed to 3.9e-6, with a root 6.5e-8
    // from it). Else within kIndistinct of a flip-grazing.
    for (Codim2Point& z : t.curve.codim2) {
      if (!MergeCandidate(z) || !IsRoot(z)) continue;
      // FOLD_FLIP is det(M - I)'s root on a PD curve only (det(M + I)'s on a fold curve).
      if (z.kind == Codim2Kind::kFoldFlip && t.curve.kind != CurveKind::kPeriodDoubling) continue;
      const MergedEnd* at_end = nullptr;
      for (const MergedEnd& e : ends) {
        if (std::hypot(z.point.value1 - e.last.value1, z.point.value2 - e.last.value2) <=
            e.bracket) {
          at_end = &e;
          break;
        }
      }
      double d = 0.0;
      const Flip* f = at_end != nullptr ? at_end->flip : flip_at(z, kIndistinct, &d);
      if (f == nullptr) continue;
      if (at_end != nullptr) d = distance(f->point, z);
      merge(*f, d, &z, &message);
    }
  }
  if (merged_roots > 0) {
    result->summary.notes.push_back(
        std::to_string(merged_roots) +
        " roots of det(M - I) on period-2n curves where the orbit is the period-n orbit traversed "
        "twice, reported as that period-n FLIP_GRAZING");
  }
  // A switched curve of even period that made no step either way (its start, corrected onto the
  // curve, is next to the point it leaves, where the period-2n system is singular: the period-n
  // orbit traversed twice) ends at its start in both directions. Its ends' bisection brackets
  // measure how far its start lies from its own boundary, not where the point is: the ends are
  // the point it leaves (after the merges above), reported there.
  int restarted = 0;
  for (size_t c = 0; c < result->curves.size(); ++c) {
    TracedCurve& t = result->curves[c];
    if (!NoStep(t) || t.from_codim2 < 0 ||
        t.curve.points.front().orbit.signature.periods % 2 != 0) {
      continue;
    }
    const Codim2Point& left = result->curves[t.from_curve].curve.codim2[t.from_codim2];
    for (Codim2Point& z : t.curve.codim2) {
      if (!IsBisectedEnd(z) || done.count(&z) > 0) continue;
      const std::string before = EndText(z);
      char beyond[64];
      std::snprintf(beyond, sizeof beyond, " (%.1e away in arclength)", z.bracket);
      z.detail = std::string("no step from the start: the ") + Codim2KindName(left.kind) +
                 " of curve " + std::to_string(t.from_curve) +
                 " this curve leaves; beyond the start" + beyond + ": " + z.detail;
      z.kind = left.kind;
      z.point = left.point;
      z.bracket = left.bracket;
      RenameEnd(before, z, &t.curve.summary.message);
      ++restarted;
    }
  }
  if (restarted > 0) {
    result->summary.notes.push_back(
        std::to_string(restarted) +
        " ends of switched curves that made no step reported as the point each leaves");
  }
  // Each point once: an entry of the same kind and period as one before it in curve order (and
  // in its curve's list), within kCopy, refers to that one.
  // The reported entries in curve order, looked up by their scaled param1 (O(log n) per entry:
  // the period-2 box has ~12600 entries).
  struct Reported {
    int curve, index;
    Codim2Kind kind;
    int periods;
    double u, v;  // box-scaled
  };
  std::vector<Reported> reported;
  std::multimap<double, size_t> by_u;  // u -> index in `reported`
  int repeated = 0;
  for (size_t c = 0; c < result->curves.size(); ++c) {
    std::vector<Codim2Point>& codim2 = result->curves[c].curve.codim2;
    for (size_t i = 0; i < codim2.size(); ++i) {
      Codim2Point& z = codim2[i];
      const double u = z.point.value1 / w1, v = z.point.value2 / w2;
      const int periods = z.point.orbit.signature.periods;
      size_t first = reported.size();  // the earliest copy, if any
      for (auto it = by_u.lower_bound(u - kCopy); it != by_u.end() && it->first <= u + kCopy;
           ++it) {
        const Reported& r = reported[it->second];
        if (r.kind == z.kind && r.periods == periods && std::hypot(r.u - u, r.v - v) <= kCopy) {
          first = std::min(first, it->second);
        }
      }
      if (first < reported.size()) {
        z.same_as_curve = reported[first].curve, z.same_as_index = reported[first].index;
        ++repeated;
      } else {
        z.same_as_curve = z.same_as_index = -1;
        by_u.emplace(u, reported.size());
        reported.push_back({static_cast<int>(c), static_cast<int>(i), z.kind, periods, u, v});
      }
    }
  }
  if (repeated > 0) {
    result->summary.notes.push_back(std::to_string(repeated) +
                                    " codimension-2 entries are points reported on an earlier "
                                    "curve (met from several curves: listed once)");
  }
  return merged;
}

}  // namespace drillbif::internal
