#include "jobs/optimum_map_query.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>
#include <tuple>
#include <utility>
#include <vector>

#include "drillbif/flow/exact_propagator.h"
#include "drillbif/orbit/periodic_orbit.h"
#include "drillbif/region/robust_optimum.h"
#include "jobs/job_common.h"
#include "jobs/request_bytes.h"
#include "jobs/trace_task_codec.h"

namespace drillbif::jobs {
namespace {

using internal::Model;
using internal::Num;

// A checked point must lie within this many margins of each neighbouring cell's optimum: the cells
// keep their boundary segments within four (optimum_map.proto), so one left out is more than one
// margin from the point.
constexpr double kMaxDistanceFromCell = 3.0;

struct Neighbour {
  int64_t cell = 0;
  double weight = 0.0;
};

// The cells around `conditions` with their (bi)linear weights > 0, heaviest first.
std::vector<Neighbour> NeighboursOf(const OptimumMapPlan& plan,
                                    const std::vector<double>& conditions) {
  std::vector<Neighbour> out = {{0, 1.0}};
  int64_t stride = 1;
  for (size_t k = 0; k < conditions.size(); ++k) {
    const int last = plan.steps[k] - 1;
    const double s = std::clamp((conditions[k] - plan.from[k]) / (plan.to[k] - plan.from[k]) * last,
                                0.0, 1.0 * last);
    const int i0 = std::min(static_cast<int>(std::floor(s)), last - 1);
    const double w = s - i0;
    std::vector<Neighbour> next;
    for (const Neighbour& n : out) {
      next.push_back({n.cell + i0 * stride, n.weight * (1.0 - w)});
      next.push_back({n.cell + (i0 + 1) * stride, n.weight * w});
    }
    out = std::move(next);
    stride *= plan.steps[k];
  }
  // A weight of rounding size is a cell the point does not depend on.
  std::erase_if(out, [](const Neighbour& n) { return n.weight <= 1e-12; });
  double sum = 0.0;
  for (const Neighbour& n : out) sum += n.weight;
  for (Neighbour& n : out) n.weight /= sum;  // one cell left: weight 1 exactly
  std::stable_sort(out.begin(), out.end(),
                   [](const Neighbour& a, const Neighbour& b) { return a.weight > b.weight; });
  return out;
}

// What the checks of one point found.
struct Check {
  bool passed = false;
  std::string reason;  // the first check that failed
  // The margin at the conditions asked, estimated from the cells' boundaries: the weighted mean
  // of the distances (in margins) from the point to each neighbouring cell's nearest segment.
  double margin = 0.0;
  const v1::BoundarySegment* nearest = nullptr;  // the nearest segment of the heaviest cell
  double distance_scaled = std::numeric_limits<double>::infinity();
  double rop = 0.0;
  double max_multiplier = 0.0;
  int64_t iterations = 0;  // Newton iterations at the point
  int samples = 0;         // points of the margin's outline checked
  Params params;
};

// An orbit at `params` by Newton from `orbit`: "" when it converged, admissible and stable, else
// why not. *max_multiplier gets the largest multiplier modulus.
std::string SolveStable(Propagator& propagator, const Params& params, PeriodicOrbit* orbit,
                        int64_t* iterations, double* max_multiplier) {
  const auto& model = Model();
  orbit->params = params;
  const OrbitSolveSummary solved = SolveOrbit(model, propagator, OrbitSolverOptions(), orbit);
  if (iterations != nullptr) *iterations = solved.iterations;
  if (!solved.completed()) return "Newton did not converge: " + solved.BriefReport();
  if (const Admissibility a = CheckAdmissible(model, propagator, *orbit); !a.admissible) {
    return "the orbit is not admissible: " + a.message;
  }
  const Stability stability = OrbitStability(model, propagator, *orbit);
  *max_multiplier = 0.0;
  for (const auto& mu : stability.multipliers) {
    *max_multiplier = std::max(*max_multiplier, std::abs(mu));
  }
  if (!stability.stable) return "the orbit is unstable (max |mu| = " + Num(*max_multiplier) + ")";
  return "";
}

// The margin's outline around (v1, v2): the rectangle's corners and edge midpoints (per
// parameter), or eight points on the ellipse (scaled), inside the box.
std::vector<std::pair<double, double>> MarginOutline(const v1::TraceRequest& trace,
                                                     const OptimumOptions& options, double v1,
                                                     double v2) {
  const double w1 = trace.max(0) - trace.min(0), w2 = trace.max(1) - trace.min(1);
  const double m1 = options.scaled ? options.margin[0] * w1 : options.margin.front();
  const double m2 = options.scaled ? options.margin[0] * w2 : options.margin.back();
  std::vector<std::pair<double, double>> out;
  for (int k = 0; k < 8; ++k) {
    const double angle = k * M_PI / 4;
    double d1 = std::cos(angle), d2 = std::sin(angle);
    if (!options.scaled) {  // onto the square: corners at the diagonals
      const double s = std::max(std::abs(d1), std::abs(d2));
      d1 /= s, d2 /= s;
    }
    const double p1 = v1 + m1 * d1, p2 = v2 + m2 * d2;
    if (p1 < trace.min(0) || p1 > trace.max(0) || p2 < trace.min(1) || p2 > trace.max(1)) continue;
    out.emplace_back(p1, p2);
  }
  return out;
}

// The checks of the point (v1, v2) at the query's conditions (see the header), the orbit from
// the first neighbour's.
Check CheckPoint(const LoadedMap& map, const std::vector<Neighbour>& neighbours,
                 const v1::OptimumRequest& query, const OptimumOptions& options, double v1,
                 double v2) {
  Check c;
  const auto& model = Model();
  const v1::TraceRequest& trace = query.trace();
  const double w1 = trace.max(0) - trace.min(0), w2 = trace.max(1) - trace.min(1);
  const MarginMetric metric(options, w1, w2);
  OptimumOptions unit;  // Euclidean distance in the box's unit square
  unit.scaled = true;
  unit.margin = {1.0};
  const MarginMetric unit_metric(unit, w1, w2);
  for (const Neighbour& n : neighbours) {
    const v1::OptimumMapCell& cell = *map.cells[n.cell];
    const auto [c1, c2] = TracePoint(query, cell.optimum().params());
    const double from_cell = metric.Distance(v1, v2, c1, c2);
    if (from_cell > kMaxDistanceFromCell) {
      c.reason = "the point is " + Num(from_cell) + " margins from the optimum of cell " +
                 std::to_string(n.cell) + ", more than " + Num(kMaxDistanceFromCell);
      return c;
    }
    // No segment within four margins of the cell's optimum: none within one of the point.
    double nearest = kMaxDistanceFromCell + 1.0;
    for (const v1::BoundarySegment& s : cell.boundary()) {
      const BoundarySegment segment{s.a1(), s.a2(), s.b1(), s.b2(), s.curve()};
      const double d = metric.Distance(v1, v2, segment);
      if (d < nearest) {
        nearest = d;
        if (&n == &neighbours.front()) c.nearest = &s;
      }
      c.distance_scaled = std::min(c.distance_scaled, unit_metric.Distance(v1, v2, segment));
    }
    c.margin += n.weight * nearest;
  }
  if (c.margin < 1.0) {
    c.reason = "the cells' boundaries put the point " + Num(c.margin) + " margins from the " +
               "boundary at these conditions, less than one";
    return c;
  }
  PeriodicOrbit orbit;
  if (Status s = DecodeOrbit(map.cells[neighbours.front().cell]->orbit(), &orbit); !s.ok()) {
    c.reason = "the cell's orbit does not decode: " + s.message();
    return c;
  }
  c.params = internal::ToEngineParams(trace.params());
  const int k1 = model.ParamIndex(trace.trace_params(0)).value();
  const int k2 = model.ParamIndex(trace.trace_params(1)).value();
  c.params[k1] = v1;
  c.params[k2] = v2;
  ExactPropagator propagator(model);
  if (std::string why = SolveStable(propagator, c.params, &orbit, &c.iterations, &c.max_multiplier);
      !why.empty()) {
    c.reason = "at the point: " + why;
    return c;
  }
  c.rop = OrbitMeasures(model, propagator, orbit, 1u << 0)[0];  // ROP is measure 0
  // The margin's outline at the conditions asked: stable on the same orbit all round.
  for (const auto& [p1, p2] : MarginOutline(trace, options, v1, v2)) {
    Params at = c.params;
    at[k1] = p1;
    at[k2] = p2;
    PeriodicOrbit sample = orbit;
    double mu = 0.0;
    if (std::string why = SolveStable(propagator, at, &sample, nullptr, &mu); !why.empty()) {
      c.reason = "one margin away, at " + trace.trace_params(0) + " = " + Num(p1) + ", " +
                 trace.trace_params(1) + " = " + Num(p2) + ": " + why;
      return c;
    }
    ++c.samples;
  }
  c.passed = true;
  return c;
}

// The answer's OptimumResult for a checked point.
void FillOptimum(const LoadedMap& map, const Neighbour& nearest, const OptimumOptions& options,
                 const Check& c, v1::OptimumResult* out) {
  const v1::OptimumResult& cell = map.cells[nearest.cell]->optimum();
  *out->mutable_params() = internal::ToProtoParams(c.params);
  out->set_rop(c.rop);
  if (c.margin > 0.0) {
    if (options.scaled) {
      out->add_margin(c.margin * options.margin[0]);
    } else {
      out->add_margin(c.margin * options.margin.front());
      out->add_margin(c.margin * options.margin.back());
    }
    out->set_distance_scaled(c.distance_scaled);
  }
  out->set_nearest_curve(c.nearest != nullptr ? c.nearest->curve() : cell.nearest_curve());
  out->set_nearest_curve_kind(c.nearest != nullptr ? c.nearest->kind() : cell.nearest_curve_kind());
  out->set_near_box_edge(cell.near_box_edge());
  out->set_signature(cell.signature());
  *out->mutable_grid() = cell.grid();
  *out->mutable_spacing() = cell.spacing();
  out->set_curves(cell.curves());
  out->set_engine_version(cell.engine_version());
  out->set_status(c.passed ? "COMPLETED" : "FAILED");
}

}  // namespace

StatusOr<LoadedMap> LoadMap(std::string operation, const v1::OptimumMapRequest& request,
                            std::vector<v1::OptimumMapCell> cells) {
  LoadedMap map;
  map.operation = std::move(operation);
  map.request = request;
  DRILLBIF_ASSIGN_OR_RETURN(map.plan, PlanOptimumMap(request));
  map.cells.resize(static_cast<size_t>(map.plan.cells));
  for (v1::OptimumMapCell& cell : cells) {
    if (cell.index_size() != static_cast<int>(map.plan.steps.size())) {
      return InvalidArgument("cells: a cell's index has the wrong length");
    }
    int64_t flat = 0, stride = 1;
    for (int k = 0; k < cell.index_size(); ++k) {
      if (cell.index(k) < 0 || cell.index(k) >= map.plan.steps[k]) {
        return InvalidArgument("cells: a cell's index lies outside the map");
      }
      flat += cell.index(k) * stride;
      stride *= map.plan.steps[k];
    }
    map.bytes += static_cast<int64_t>(cell.ByteSizeLong());
    map.cells[flat] = std::move(cell);
  }
  return map;
}

std::string MapQueryKey(const v1::OptimumRequest& optimum, const std::vector<std::string>& over) {
  v1::OptimumRequest r = optimum;
  v1::TraceRequest* trace = r.mutable_trace();
  *trace->mutable_params() = internal::ToProtoParams(internal::ToEngineParams(trace->params()));
  const auto* reflection = trace->params().GetReflection();
  for (const std::string& name : over) {
    const auto* field = v1::ModelParams::descriptor()->FindFieldByName(name);
    if (field != nullptr) reflection->ClearField(trace->mutable_params(), field);
  }
  trace->clear_threads();
  std::string key;
  for (const std::string& name : over) key += name + ",";
  return key + ";" + DeterministicBytes(r);
}

std::vector<double> QueryConditions(const LoadedMap& map, const v1::OptimumRequest& query) {
  const Params params = internal::ToEngineParams(query.trace().params());
  std::vector<double> out;
  for (const std::string& name : map.plan.over) {
    out.push_back(params[Model().ParamIndex(name).value()]);
  }
  return out;
}

double CellsOutside(const LoadedMap& map, const std::vector<double>& conditions) {
  double outside = 0.0;
  for (size_t k = 0; k < conditions.size(); ++k) {
    const double cell = (map.plan.to[k] - map.plan.from[k]) / (map.plan.steps[k] - 1);
    const double below = map.plan.from[k] - conditions[k];
    const double above = conditions[k] - map.plan.to[k];
    outside = std::max({outside, below / cell, above / cell});
  }
  return outside;
}

MapQueryAnswer AnswerFromMap(const LoadedMap& map, const v1::OptimumRequest& query,
                             bool nearest_on_failure) {
  MapQueryAnswer answer;
  v1::MapAnswer& from = answer.from_map;
  from.set_map(map.operation);
  const std::vector<double> conditions = QueryConditions(map, query);
  const std::vector<Neighbour> neighbours = NeighboursOf(map.plan, conditions);
  for (const Neighbour& n : neighbours) {
    v1::MapCellWeight* w = from.add_cells();
    for (int i : CellIndex(map.plan, n.cell)) w->add_index(i);
    for (double v : CellCondition(map.plan, n.cell)) w->add_condition(v);
    w->set_weight(n.weight);
  }
  auto fail = [&](const std::string& why) {
    answer.optimum.set_status("FAILED");
    answer.optimum.set_message(why);
    from.set_verification(why);
    return answer;
  };
  // The neighbours with an optimum to start from, heaviest first; the interpolation needs every
  // neighbour, all on one orbit (else `why_not` says why it is not tried).
  std::vector<Neighbour> usable;
  std::string why_not;
  for (const Neighbour& n : neighbours) {
    const std::optional<v1::OptimumMapCell>& cell = map.cells[n.cell];
    if (!cell || cell->optimum().status() != "COMPLETED" || !cell->has_orbit()) {
      if (why_not.empty()) {
        why_not = "cell " + std::to_string(n.cell) + " has no verified optimum to start from" +
                  (cell ? ": " + cell->optimum().message() : std::string());
      }
      continue;
    }
    if (!usable.empty() && why_not.empty() &&
        cell->optimum().signature() != map.cells[usable.front().cell]->optimum().signature()) {
      why_not = "the neighbouring cells' optima lie on other orbits";
    }
    usable.push_back(n);
  }
  if (usable.empty() || (!why_not.empty() && !nearest_on_failure)) return fail(why_not);
  const StatusOr<OptimumPlan> plan = PlanOptimum(query);
  if (!plan.ok()) return fail(plan.status().message());
  const auto cell_point = [&](const Neighbour& n) {
    return TracePoint(query, map.cells[n.cell]->optimum().params());
  };
  Check c;
  double v1 = 0.0, v2 = 0.0;
  if (why_not.empty()) {
    for (const Neighbour& n : neighbours) {
      const auto [c1, c2] = cell_point(n);
      v1 += n.weight * c1;
      v2 += n.weight * c2;
    }
    c = CheckPoint(map, neighbours, query, plan->options, v1, v2);
    from.set_interpolated(true);
  } else {
    c.reason = why_not;
  }
  if (!c.passed && nearest_on_failure && (!why_not.empty() || neighbours.size() > 1)) {
    // The nearest cell with an optimum: its point, checked at the conditions asked.
    const std::string first = c.reason;
    std::tie(v1, v2) = cell_point(usable.front());
    c = CheckPoint(map, {{usable.front().cell, 1.0}}, query, plan->options, v1, v2);
    from.set_interpolated(false);
    c.reason = "interpolation: " + first + (c.passed ? "" : "; nearest cell: " + c.reason);
  }
  if (!c.passed && c.params.size() == 0) return fail(c.reason);
  FillOptimum(map, usable.front(), plan->options, c, &answer.optimum);
  from.set_verified(c.passed);
  from.set_max_multiplier(c.max_multiplier);
  const std::string what = from.interpolated()
                               ? "interpolated from " + std::to_string(neighbours.size()) +
                                     " cell(s) of " + map.operation
                               : "the optimum of cell " + std::to_string(usable.front().cell) +
                                     " of " + map.operation + " (the nearest with one)";
  if (c.passed) {
    from.set_verification(what + "; verified: Newton converged in " + std::to_string(c.iterations) +
                          " iterations, stable (max |mu| = " + Num(c.max_multiplier) +
                          "), stable on the same orbit at " + std::to_string(c.samples) +
                          " points one margin away, " + Num(c.margin) +
                          " margins from the boundary by the cells' curves" +
                          (c.reason.empty() ? "" : " (" + c.reason + ")"));
  } else {
    from.set_verification(what + "; not verified: " + c.reason);
  }
  answer.optimum.set_message("ROP " + Num(c.rop) + " at " + query.trace().trace_params(0) + " = " +
                             Num(v1) + ", " + query.trace().trace_params(1) + " = " + Num(v2) +
                             "; " + from.verification());
  return answer;
}

}  // namespace drillbif::jobs
