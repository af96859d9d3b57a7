#include "jobs/optimum_map_job.h"

#include <google/protobuf/descriptor.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <new>
#include <set>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "drillbif/common/threads.h"
#include "drillbif/version.h"
#include "jobs/job_common.h"
#include "jobs/region_output.h"
#include "jobs/trace_task_codec.h"

namespace drillbif::jobs {
namespace {

using google::protobuf::FieldDescriptor;
using internal::Num;
using internal::Seconds;

constexpr int kMaxMapThreads = 256;
// The boundary a cell keeps: segments within this many margins of its optimum (optimum_map.proto).
constexpr double kBoundaryReach = 4.0;

// The ModelParams field of a condition, or null.
const FieldDescriptor* ParamField(const std::string& name) {
  const FieldDescriptor* f = v1::ModelParams::descriptor()->FindFieldByName(name);
  return f != nullptr && f->cpp_type() == FieldDescriptor::CPPTYPE_DOUBLE ? f : nullptr;
}

void SetParam(const std::string& name, double value, v1::ModelParams* params) {
  params->GetReflection()->SetDouble(params, ParamField(name), value);
}

double GetParam(const std::string& name, const v1::ModelParams& params) {
  return params.GetReflection()->GetDouble(params, ParamField(name));
}

Status CheckConditions(const v1::OptimumMapRequest& request) {
  const int n = request.over_size();
  if (n < 1 || n > 2) {
    return InvalidArgument("over: give one or two conditions (ModelParams field names), got " +
                           std::to_string(n));
  }
  const auto& traced = request.optimum().trace().trace_params();
  for (int k = 0; k < n; ++k) {
    const std::string& name = request.over(k);
    const std::string at = "over[" + std::to_string(k) + "]";
    if (ParamField(name) == nullptr) {
      return InvalidArgument(at + ": not a model parameter (one of a, b, omega, xi, g, phi0)");
    }
    if (std::find(traced.begin(), traced.end(), name) != traced.end()) {
      return InvalidArgument(at + ": '" + name + "' is a trace parameter of optimum.trace");
    }
    if (k == 1 && name == request.over(0)) return InvalidArgument(at + ": '" + name + "' twice");
  }
  if (request.from_size() != n || request.to_size() != n || request.steps_size() != n) {
    return InvalidArgument("from, to, steps: give one value per condition of over (" +
                           std::to_string(n) + ")");
  }
  int64_t cells = 1;
  for (int k = 0; k < n; ++k) {
    const std::string at = "[" + std::to_string(k) + "]";
    if (!(request.from(k) < request.to(k))) {
      return InvalidArgument("from" + at + ", to" + at + ": need from < to, got " +
                             Num(request.from(k)) + " and " + Num(request.to(k)));
    }
    if (request.steps(k) < 2) {
      return InvalidArgument("steps" + at + ": need at least 2 cells, got " +
                             std::to_string(request.steps(k)));
    }
    cells *= request.steps(k);  // <= 2^31 * 2^31: no overflow in 64 bits
  }
  if (cells > kMaxMapCells) {
    return InvalidArgument("steps: " + std::to_string(cells) + " cells, more than " +
                           std::to_string(kMaxMapCells));
  }
  if (request.threads() < 0 || request.threads() > kMaxMapThreads) {
    return InvalidArgument("threads: need 0 (every core) .. " + std::to_string(kMaxMapThreads) +
                           ", got " + std::to_string(request.threads()));
  }
  return Status::Ok();
}

// PlanOptimum of a cell's request, its errors naming the cell.
StatusOr<OptimumPlan> PlanCell(const v1::OptimumMapRequest& request, const OptimumMapPlan& plan,
                               int64_t cell) {
  StatusOr<OptimumPlan> planned = PlanOptimum(CellRequest(request, plan, cell));
  if (planned.ok()) return planned;
  std::string at;
  const std::vector<double> condition = CellCondition(plan, cell);
  for (size_t k = 0; k < condition.size(); ++k) {
    at += (k ? ", " : "") + plan.over[k] + " = " + Num(condition[k]);
  }
  return Status(planned.status().code(),
                "from, to: the cell at " + at + ": optimum." + planned.status().message());
}

// The kind of a boundary segment's curve, as OptimumResult.nearest_curve_kind names it.
std::string BoundaryKind(int curve, const std::vector<CurveKind>& kinds) {
  if (curve >= 0 && curve < static_cast<int>(kinds.size())) return CurveKindName(kinds[curve]);
  return curve == RegionVertex::kSeam ? "SEAM" : "UNTRACED";
}

// The cell's stability region without its grid, and the curves its polygons lie on.
void AddRegion(const OptimumDetail& detail, v1::OptimumMapCell* cell) {
  v1::StabilityRegion* region = cell->mutable_region();
  ToProto(internal::Model(), *detail.region, region);
  region->clear_values1();
  region->clear_values2();
  region->clear_label();
  region->clear_rop();
  std::set<int> bounding;
  for (const RegionPolygon& ring : detail.region->polygons) {
    for (const RegionVertex& v : ring.vertices) {
      if (v.curve >= 0) bounding.insert(v.curve);
    }
  }
  const std::vector<RegionCurve>& polylines = detail.curves->region_curves;
  for (int k : bounding) {
    if (k >= static_cast<int>(polylines.size())) continue;
    v1::BoundingCurve* c = cell->add_curves();
    c->set_curve(k);
    c->set_kind(BoundaryKind(k, detail.kinds));
    *c->mutable_values1() = {polylines[k].values1.begin(), polylines[k].values1.end()};
    *c->mutable_values2() = {polylines[k].values2.begin(), polylines[k].values2.end()};
  }
}

// Runs the cells on the job's own threads; the calling thread hands them on and reports progress.
class ThreadCells final : public MapCellRunner {
 public:
  explicit ThreadCells(int threads) : threads_(threads) {}

  Status Run(const std::vector<v1::OptimumRequest>& requests, const CellDone& done,
             const ProgressCallback& progress) override {
    const int64_t n = static_cast<int64_t>(requests.size());
    // Of each running cell (0 once it finished), under mutex_.
    std::vector<double> fraction(requests.size(), 0.0);
    std::vector<std::thread> pool;
    for (int t = 0; t < std::min<int64_t>(threads_, n); ++t) {
      pool.emplace_back([&] {
        for (int64_t k; !stop_ && (k = next_++) < n;) {
          v1::OptimumMapCell cell = RunMapCell(requests[k], [&, k](double f) {
            std::lock_guard<std::mutex> lock(mutex_);
            fraction[k] = f;
            return !stop_.load();
          });
          std::lock_guard<std::mutex> lock(mutex_);
          fraction[k] = 0.0;  // counted as a whole cell once handed on
          finished_.emplace_back(k, std::move(cell));
          wake_.notify_one();
        }
      });
    }
    Status status = Hand(n, done, progress, fraction);
    stop_ = true;
    for (std::thread& t : pool) t.join();
    return status;
  }

 private:
  // Hands the finished cells on until every one is, or a stop or an error.
  Status Hand(int64_t n, const CellDone& done, const ProgressCallback& progress,
              const std::vector<double>& fraction) {
    int64_t handed = 0;
    std::unique_lock<std::mutex> lock(mutex_);
    while (handed < n) {
      wake_.wait_for(lock, std::chrono::milliseconds(20), [&] { return !finished_.empty(); });
      while (!finished_.empty()) {
        auto [k, cell] = std::move(finished_.front());
        finished_.pop_front();
        lock.unlock();
        const bool cancelled = cell.optimum().status() == "CANCELLED";
        Status s = cancelled ? Status::Ok() : done(k, std::move(cell), false);
        lock.lock();
        if (!s.ok()) return s;
        if (cancelled) return Cancelled("cancelled");
        ++handed;
      }
      double sum = static_cast<double>(handed);
      for (double f : fraction) sum += f;  // the cells running
      lock.unlock();
      const bool go_on = !progress || progress(std::min(sum / n, 1.0));
      lock.lock();
      if (!go_on) return Cancelled("cancelled");
    }
    return Status::Ok();
  }

  const int threads_;
  std::atomic<bool> stop_{false};
  std::atomic<int64_t> next_{0};
  std::mutex mutex_;
  std::condition_variable wake_;
  std::deque<std::pair<int64_t, v1::OptimumMapCell>> finished_;
};

StatusOr<v1::OptimumMapResult> Map(const v1::OptimumMapRequest& request,
                                   const RunContext& context) {
  const auto start = std::chrono::steady_clock::now();
  DRILLBIF_ASSIGN_OR_RETURN(const OptimumMapPlan plan, PlanOptimumMap(request));
  std::vector<v1::OptimumRequest> requests;
  for (int64_t k = 0; k < plan.cells; ++k) requests.push_back(CellRequest(request, plan, k));
  v1::OptimumMapResult out;
  *out.mutable_over() = request.over();
  *out.mutable_from() = request.from();
  *out.mutable_to() = request.to();
  *out.mutable_steps() = request.steps();
  *out.mutable_optimum() = request.optimum();
  out.set_engine_version(EngineVersion());
  auto done = [&](int64_t k, v1::OptimumMapCell cell, bool resumed) -> Status {
    for (int i : CellIndex(plan, k)) cell.add_index(i);
    for (double v : CellCondition(plan, k)) cell.add_condition(v);
    const std::string& status = cell.optimum().status();
    if (status == "COMPLETED") {
      out.set_cells_found(out.cells_found() + 1);
    } else if (status == "NOT_FOUND") {
      out.set_cells_not_found(out.cells_not_found() + 1);
    } else {
      out.set_cells_failed(out.cells_failed() + 1);
    }
    if (resumed) out.set_cells_resumed(out.cells_resumed() + 1);
    if (context.sink == nullptr) {
      *out.add_cells() = std::move(cell);
      return Status::Ok();
    }
    v1::OptimumMapResult items;
    *items.add_cells() = std::move(cell);
    return context.sink->Append(items, 1);
  };
  ThreadCells threads(plan.threads);
  MapCellRunner* runner = context.map_cells != nullptr ? context.map_cells : &threads;
  const Status s = runner->Run(requests, done, context.progress);
  out.set_wall_seconds(Seconds(start));
  const int64_t computed = out.cells_found() + out.cells_not_found() + out.cells_failed();
  std::string counts = std::to_string(computed) + " of " + std::to_string(plan.cells) +
                       " cells: " + std::to_string(out.cells_found()) + " optima found, " +
                       std::to_string(out.cells_not_found()) + " without the margin, " +
                       std::to_string(out.cells_failed()) + " failed";
  if (out.cells_resumed() > 0) {
    counts += "; " + std::to_string(out.cells_resumed()) + " from an earlier run";
  }
  if (s.code() == StatusCode::kCancelled) {
    internal::SetRunEnd(Termination::kCancelled, "cancelled after " + counts, &out);
    return out;
  }
  if (!s.ok()) return s;
  internal::SetRunEnd(Termination::kCompleted, counts, &out);
  return out;
}

}  // namespace

StatusOr<OptimumMapPlan> PlanOptimumMap(const v1::OptimumMapRequest& request) {
  DRILLBIF_RETURN_IF_ERROR(CheckConditions(request));
  OptimumMapPlan plan;
  plan.over.assign(request.over().begin(), request.over().end());
  plan.from.assign(request.from().begin(), request.from().end());
  plan.to.assign(request.to().begin(), request.to().end());
  plan.steps.assign(request.steps().begin(), request.steps().end());
  plan.cells = 1;
  for (int s : plan.steps) plan.cells *= s;
  if (StatusOr<OptimumPlan> base = PlanOptimum(request.optimum()); !base.ok()) {
    const Status& s = base.status();
    return Status(s.code(), "optimum." + s.message());
  }
  DRILLBIF_ASSIGN_OR_RETURN(plan.cell, PlanCell(request, plan, 0));
  DRILLBIF_RETURN_IF_ERROR(PlanCell(request, plan, plan.cells - 1).status());
  plan.threads = static_cast<int>(
      std::min<int64_t>(std::min(ThreadsOrCores(request.threads()), Cores()), plan.cells));
  return plan;
}

JobCost OptimumMapCost(const OptimumMapPlan& plan) {
  const JobCost cell = OptimumCost(plan.cell);
  const double cells = static_cast<double>(plan.cells);
  const std::string driver = "request.steps: " + std::to_string(plan.cells) + " cells of ";
  JobCost cost;
  cost.seconds = {cells * cell.seconds.amount, driver + cell.seconds.driver};
  cost.memory_bytes = {plan.threads * cell.memory_bytes.amount,
                       "request.threads: " + std::to_string(plan.threads) + " cells at once of " +
                           cell.memory_bytes.driver};
  // A cell: the optimum and its orbit (a few kB), the boundary segments near it, the region's
  // polygons and the bounding curves' polylines, growing with the grid's perimeter: ~1.4 MB of
  // JSON (~0.5 MB of proto) in the reference box with its default 196 x 800 grid, ~0.3 MB of JSON
  // in the small test box with a 41 x 41 grid.
  const auto [n1, n2] = plan.cell.grid;
  const double per_cell = 1e5 + 400.0 * (n1 + n2);
  cost.result_bytes = {cells * per_cell,
                       driver + HumanBytes(per_cell) + " (request.optimum.grid: the region)"};
  return cost;
}

std::vector<int> CellIndex(const OptimumMapPlan& plan, int64_t cell) {
  std::vector<int> index;
  for (int s : plan.steps) {
    index.push_back(static_cast<int>(cell % s));
    cell /= s;
  }
  return index;
}

std::vector<double> CellCondition(const OptimumMapPlan& plan, int64_t cell) {
  const std::vector<int> index = CellIndex(plan, cell);
  std::vector<double> values;
  for (size_t k = 0; k < index.size(); ++k) {
    const int last = plan.steps[k] - 1;
    values.push_back(index[k] == last
                         ? plan.to[k]
                         : plan.from[k] + index[k] * (plan.to[k] - plan.from[k]) / last);
  }
  return values;
}

v1::OptimumRequest CellRequest(const v1::OptimumMapRequest& request, const OptimumMapPlan& plan,
                               int64_t cell) {
  v1::OptimumRequest r = request.optimum();
  const std::vector<double> condition = CellCondition(plan, cell);
  for (size_t k = 0; k < condition.size(); ++k) {
    SetParam(plan.over[k], condition[k], r.mutable_trace()->mutable_params());
  }
  r.mutable_trace()->set_threads(1);  // the cells are the tasks
  return r;
}

v1::OptimumMapCell RunMapCell(const v1::OptimumRequest& request, const ProgressCallback& progress) {
  const auto start = std::chrono::steady_clock::now();
  v1::OptimumMapCell cell;
  RunContext context;
  context.progress = progress;
  OptimumDetail detail;
  StatusOr<v1::OptimumResult> result = RunOptimumWithDetail(request, context, &detail);
  if (!result.ok()) {
    cell.mutable_optimum()->set_status("FAILED");
    cell.mutable_optimum()->set_message(result.status().message());
  } else {
    *cell.mutable_optimum() = *std::move(result);
  }
  const v1::OptimumResult& optimum = cell.optimum();
  if (optimum.has_params() && detail.width1 > 0.0) {
    if (detail.orbit) EncodeOrbit(*detail.orbit, cell.mutable_orbit());
    const auto [v1, v2] = TracePoint(request, optimum.params());
    const MarginMetric metric(detail.options, detail.width1, detail.width2);
    for (const BoundarySegment& s : detail.obstacles) {
      if (metric.Distance(v1, v2, s) > kBoundaryReach) continue;
      v1::BoundarySegment* b = cell.add_boundary();
      b->set_a1(s.a1), b->set_a2(s.a2), b->set_b1(s.b1), b->set_b2(s.b2), b->set_curve(s.curve);
      b->set_kind(BoundaryKind(s.curve, detail.kinds));
    }
  }
  if (detail.region != nullptr && optimum.has_params()) AddRegion(detail, &cell);
  cell.set_wall_seconds(Seconds(start));
  return cell;
}

std::pair<double, double> TracePoint(const v1::OptimumRequest& request,
                                     const v1::ModelParams& params) {
  return {GetParam(request.trace().trace_params(0), params),
          GetParam(request.trace().trace_params(1), params)};
}

StatusOr<v1::OptimumMapCell> RunMapCellJob(const v1::OptimumRequest& request,
                                           const RunContext& context) {
  return RunMapCell(request, context.progress);
}

StatusOr<v1::OptimumMapResult> RunOptimumMap(const v1::OptimumMapRequest& request,
                                             const RunContext& context) {
  try {
    return Map(request, context);
  } catch (const std::bad_alloc&) {
    return Internal("out of memory while computing the optimum map");
  } catch (const std::exception& e) {
    return Internal(std::string("optimum map failed: ") + e.what());
  }
}

}  // namespace drillbif::jobs
