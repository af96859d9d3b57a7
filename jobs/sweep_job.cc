#include "jobs/sweep_job.h"

#include <chrono>
#include <exception>
#include <memory>
#include <new>
#include <optional>
#include <string>

#include "drillbif/common/checked.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/version.h"
#include "jobs/item_batcher.h"
#include "jobs/job_common.h"

namespace drillbif::jobs {
namespace {

using internal::Model;
using internal::Num;
using internal::Seconds;

// Cost model (docs/performance.md, "Admission control"): as a simulation with the exact
// propagator, 1e-5 s per forcing period, and 40 bytes per Poincare sample in the result.
constexpr double kSecondsPerPeriod = 1e-5;
constexpr double kSampleBytes = 40;
constexpr double kValueBytes = 30;  // a grid value's own fields (value, status)
// A grid value's own work beyond its periods (its simulation's setup, the result item, its
// stream and progress): 3571428 values of one period each ran 87 s on the server on a loaded
// 2-core machine (bench/largest_jobs.sh), ~24 us a value, of which ~5 us is the period.
constexpr double kSecondsPerValue = 2.5e-5;

StatusOr<SweepOptions> ToSweepOptions(const v1::SweepRequest& request) {
  SweepOptions options;
  options.param = request.param();
  options.min = request.min();
  options.max = request.max();
  if (request.has_steps()) options.steps = request.steps();
  switch (request.direction()) {
    case v1::SweepRequest::DIRECTION_UNSPECIFIED:
    case v1::SweepRequest::UP:
      options.direction = SweepDirection::kUp;
      break;
    case v1::SweepRequest::DOWN:
      options.direction = SweepDirection::kDown;
      break;
    case v1::SweepRequest::BOTH:
      options.direction = SweepDirection::kBoth;
      break;
    default:
      return InvalidArgument("direction: unknown value " + std::to_string(request.direction()));
  }
  if (request.has_transient_periods()) options.transient_periods = request.transient_periods();
  if (request.has_sample_periods()) options.sample_periods = request.sample_periods();
  options.threads = request.threads();
  if (request.has_chunks()) options.chunks = request.chunks();
  DRILLBIF_RETURN_IF_ERROR(options.Validate());
  if (options.threads > kMaxSweepThreads) {
    return InvalidArgument("threads must be <= " + std::to_string(kMaxSweepThreads) + ", got " +
                           std::to_string(options.threads));
  }
  const int64_t directions = options.direction == SweepDirection::kBoth ? 2 : 1;
  const std::optional<int64_t> samples =
      CheckedMul(CheckedMul(int64_t{options.steps}, int64_t{options.sample_periods}), directions);
  if (!samples || *samples > kMaxSweepSamples) {
    return InvalidArgument("steps * sample_periods * directions = " +
                           (samples ? std::to_string(*samples) : std::string("(overflow)")) +
                           " Poincare samples, more than the " + std::to_string(kMaxSweepSamples) +
                           " one sweep may record");
  }
  return options;
}

v1::SweepPoint::Start ToProto(SweepStart start) {
  switch (start) {
    case SweepStart::kFromInitialState:
      return v1::SweepPoint::FROM_INITIAL_STATE;
    case SweepStart::kFromPreviousValue:
      return v1::SweepPoint::FROM_PREVIOUS_VALUE;
    case SweepStart::kFromEarlierValue:
      return v1::SweepPoint::FROM_EARLIER_VALUE;
    case SweepStart::kNotStarted:
      break;
  }
  return v1::SweepPoint::START_UNSPECIFIED;
}

void ToProto(const SweepPoint& in, bool sweep_cancelled, v1::SweepPoint* out) {
  out->set_value(in.value);
  out->set_start(ToProto(in.start));
  out->set_transient_periods(in.transient_periods);
  if (sweep_cancelled && in.start == SweepStart::kNotStarted) {
    internal::SetRunEnd(Termination::kCancelled, "not reached before the sweep was cancelled", out);
    return;
  }
  internal::SetRunEnd(in.summary, out);
  out->mutable_samples()->Reserve(static_cast<int>(in.samples.size()));
  for (const PoincareSample& smp : in.samples) internal::ToProto(smp, out->add_samples());
}

}  // namespace

StatusOr<SweepPlan> PlanSweep(const v1::SweepRequest& request) {
  SweepPlan plan;
  DRILLBIF_ASSIGN_OR_RETURN(plan.options, ToSweepOptions(request));
  plan.params = internal::ToEngineParams(request.params());
  StatusOr<int> index = Model().ParamIndex(plan.options.param);
  if (!index.ok()) return InvalidArgument("param: " + index.status().message());
  DRILLBIF_RETURN_IF_ERROR(internal::CheckParamValues(
      plan.params, *index, {{"min", plan.options.min}, {"max", plan.options.max}}));
  plan.x0 = internal::ToEngineState(request.has_initial_state(), request.initial_state());
  DRILLBIF_RETURN_IF_ERROR(
      Model().ValidateState(plan.x0, plan.params, SimulationOptions().state_tolerance));
  return plan;
}

JobCost SweepCost(const SweepPlan& plan) {
  const SweepOptions& o = plan.options;
  const int64_t directions = o.direction == SweepDirection::kBoth ? 2 : 1;
  const std::optional<int64_t> values = CheckedMul(int64_t{o.steps}, directions);
  // Each value runs its transient and its window; the first value of each chunk after the first
  // (chunks - 1 per direction) factor - 1 more transients.
  const double periods =
      CountOrInfinity(
          CheckedMul(values, CheckedAdd(int64_t{o.transient_periods}, int64_t{o.sample_periods}))) +
      CountOrInfinity(CheckedMul(
          CheckedMul(int64_t{o.chunk_start_transient_factor - 1}, int64_t{o.transient_periods}),
          CheckedMul(int64_t{o.chunks - 1}, directions)));
  JobCost cost;
  cost.seconds.amount = periods * kSecondsPerPeriod + CountOrInfinity(values) * kSecondsPerValue;
  cost.seconds.driver =
      "request.steps * directions * (request.transient_periods + request.sample_periods) + "
      "directions * (request.chunks - 1) * 3 * request.transient_periods = " +
      Num(periods) + " forcing periods";
  const double samples = CountOrInfinity(CheckedMul(values, int64_t{o.sample_periods}));
  cost.result_bytes.amount = samples * kSampleBytes + CountOrInfinity(values) * kValueBytes;
  cost.result_bytes.driver =
      "request.steps * directions * request.sample_periods = " + Num(samples) + " Poincare samples";
  // Values finished out of order wait for their predecessors; the engine holds the rest.
  cost.memory_bytes = {cost.result_bytes.amount * 4, cost.result_bytes.driver};
  return cost;
}

StatusOr<SweepPlan> PlanSweepPart(const v1::SweepPartRequest& request) {
  DRILLBIF_ASSIGN_OR_RETURN(SweepPlan plan, PlanSweep(request.sweep()));
  plan.options.piece = request.piece();
  DRILLBIF_RETURN_IF_ERROR(plan.options.Validate());
  return plan;
}

JobCost SweepPartCost(const SweepPlan& plan) {
  SweepPlan whole = plan;
  whole.options.piece = -1;
  JobCost cost = SweepCost(whole);
  const std::vector<SweepPiece> pieces = SweepPieces(whole.options);
  if (plan.options.piece < 0 || plan.options.piece >= static_cast<int>(pieces.size())) return cost;
  const SweepPiece& piece = pieces[static_cast<size_t>(plan.options.piece)];
  const double directions = whole.options.direction == SweepDirection::kBoth ? 2 : 1;
  const double share = (piece.last - piece.first + 1) / (directions * whole.options.steps);
  for (CostTerm* item : {&cost.seconds, &cost.result_bytes, &cost.memory_bytes}) {
    item->amount *= share;
    item->driver = "the piece's share of the sweep's values, of " + item->driver;
  }
  return cost;
}

namespace {

using Clock = std::chrono::steady_clock;

// The sweep (or the piece) of `plan` on this process's threads; values stream to context.sink
// when there is one.
StatusOr<v1::SweepResult> RunHere(const SweepPlan& plan, const RunContext& context,
                                  Clock::time_point start) {
  const auto& model = Model();
  const PropagatorFactory make_propagator = [&model] {
    return std::unique_ptr<Propagator>(std::make_unique<ExactPropagator>(model));
  };
  // Streamed: each value goes to the sink as it is final (in grid order per direction).
  std::optional<ItemBatcher<v1::SweepResult>> up, down;
  SweepPointCallback on_point;
  if (context.sink != nullptr) {
    up.emplace(context.sink);
    down.emplace(context.sink);
    on_point = [&](SweepDirection direction, int, SweepPoint&& point) {
      if (direction == SweepDirection::kDown) {
        return down->Add([&](v1::SweepResult* r) { ToProto(point, false, r->add_down()); });
      }
      return up->Add([&](v1::SweepResult* r) { ToProto(point, false, r->add_up()); });
    };
  }
  const SweepResult r = Sweep(model, make_propagator, plan.params, plan.x0, plan.options,
                              context.progress, context.on_value, on_point);
  for (auto* batcher : {&up, &down}) {
    if (*batcher && !(*batcher)->Flush()) return (*batcher)->status();
  }
  // Sweep validates everything (parameter name, range ends, initial state) before it starts;
  // once started it always completes or is cancelled, single values failing on their own.
  if (r.summary.failed()) {
    return r.summary.status.ok() ? Internal("sweep failed without a reason") : r.summary.status;
  }
  const bool cancelled = r.summary.cancelled();
  v1::SweepResult out;
  internal::SetRunEnd(r.summary, &out);
  for (const SweepPoint& pt : r.up) ToProto(pt, cancelled, out.add_up());
  for (const SweepPoint& pt : r.down) ToProto(pt, cancelled, out.add_down());
  out.set_periods_total(r.summary.periods);
  out.set_events_total(r.summary.events);
  out.set_engine_version(EngineVersion());
  out.set_wall_seconds(Seconds(start));
  return out;
}

// The pieces of `plan`'s sweep on `context.sweep_parts`. The parts finish in any order; each
// direction's values are handed on in grid order (a part waits for the parts before it in its
// direction), to the sink in the batches of a local run, so that the result (concatenated
// with what was streamed) is the local run's.
StatusOr<v1::SweepResult> RunParts(const v1::SweepRequest& request, const SweepPlan& plan,
                                   const RunContext& context, Clock::time_point start) {
  const std::vector<SweepPiece> pieces = SweepPieces(plan.options);
  std::vector<v1::SweepPartRequest> parts(pieces.size());
  std::vector<int> order[2];  // per direction (0: up), its pieces in grid order
  for (size_t k = 0; k < pieces.size(); ++k) {
    *parts[k].mutable_sweep() = request;
    parts[k].set_piece(static_cast<int>(k));
    order[pieces[k].direction == SweepDirection::kUp ? 0 : 1].push_back(static_cast<int>(k));
  }
  std::optional<ItemBatcher<v1::SweepResult>> batchers[2];
  if (context.sink != nullptr) {
    for (auto& b : batchers) b.emplace(context.sink);
  }
  v1::SweepResult out;
  SweepSummary sum;
  std::vector<std::optional<v1::SweepResult>> held(pieces.size());
  size_t next[2] = {0, 0};  // per direction: the position in order[] of the next part to hand on
  // Hands on one part's values in order; false when the sink refused them.
  auto hand = [&](int d, v1::SweepResult& part) {
    auto* points = d == 0 ? part.mutable_up() : part.mutable_down();
    // Read before the values move on.
    const std::optional<double> last =
        points->empty() ? std::nullopt : std::optional<double>(points->rbegin()->value());
    for (v1::SweepPoint& point : *points) {
      ++sum.values;
      if (!batchers[d]) {
        (d == 0 ? out.add_up() : out.add_down())->Swap(&point);
        continue;
      }
      const bool taken = batchers[d]->Add(
          [&](v1::SweepResult* r) { (d == 0 ? r->add_up() : r->add_down())->Swap(&point); });
      if (!taken) return false;
    }
    sum.periods += part.periods_total();
    sum.events += part.events_total();
    if (context.on_value && last) context.on_value(*last);
    return true;
  };
  auto done = [&](int k, v1::SweepResult part) -> Status {
    if (part.status() != "COMPLETED") {
      // A part stops only when asked to (a part's values fail on their own).
      return Status(StatusCode::kCancelled, "sweep part " + std::to_string(k) + " ended " +
                                                part.status() + ": " + part.message());
    }
    held[static_cast<size_t>(k)] = std::move(part);
    for (int d = 0; d < 2; ++d) {
      while (next[d] < order[d].size() && held[static_cast<size_t>(order[d][next[d]])]) {
        std::optional<v1::SweepResult>& ready = held[static_cast<size_t>(order[d][next[d]])];
        if (!hand(d, *ready)) return batchers[d]->status();
        ready.reset();
        ++next[d];
      }
    }
    return Status::Ok();
  };
  const Status s = context.sweep_parts->Run(parts, done, context.progress);
  for (auto& b : batchers) {
    if (b && !b->Flush()) return b->status();
  }
  if (s.code() == StatusCode::kCancelled) {
    sum.Cancel("sweep cancelled");
  } else if (!s.ok()) {
    return s;
  } else {
    sum.Complete();
  }
  internal::SetRunEnd(sum, &out);
  out.set_periods_total(sum.periods);
  out.set_events_total(sum.events);
  out.set_engine_version(EngineVersion());
  out.set_wall_seconds(Seconds(start));
  return out;
}

}  // namespace

StatusOr<v1::SweepResult> RunSweep(const v1::SweepRequest& request, const RunContext& context) {
  const auto start = Clock::now();
  DRILLBIF_ASSIGN_OR_RETURN(const SweepPlan plan, PlanSweep(request));
  try {
    if (context.sweep_parts != nullptr && SweepPieces(plan.options).size() > 1) {
      return RunParts(request, plan, context, start);
    }
    return RunHere(plan, context, start);
  } catch (const std::bad_alloc&) {
    return Internal("out of memory while sweeping");
  } catch (const std::exception& e) {
    return Internal(std::string("sweep failed: ") + e.what());
  }
}

StatusOr<v1::SweepResult> RunSweepPart(const v1::SweepPartRequest& request,
                                       const RunContext& context) {
  const auto start = Clock::now();
  DRILLBIF_ASSIGN_OR_RETURN(const SweepPlan plan, PlanSweepPart(request));
  RunContext here = context;
  here.sink = nullptr;  // the parent reads the part's values from its result
  try {
    return RunHere(plan, here, start);
  } catch (const std::bad_alloc&) {
    return Internal("out of memory while sweeping");
  } catch (const std::exception& e) {
    return Internal(std::string("sweep part failed: ") + e.what());
  }
}

}  // namespace drillbif::jobs
