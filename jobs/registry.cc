#include "jobs/registry.h"

#include <google/protobuf/message.h>
#include <google/protobuf/reflection.h>

#include <cmath>
#include <string>
#include <string_view>
#include <utility>

#include "jobs/continue_job.h"
#include "jobs/optimum_job.h"
#include "jobs/optimum_map_job.h"
#include "jobs/request_bytes.h"
#include "jobs/simulate_job.h"
#include "jobs/sweep_job.h"
#include "jobs/trace_job.h"
#include "jobs/trace_task_job.h"

namespace drillbif::jobs {
namespace {

using google::protobuf::FieldDescriptor;
using google::protobuf::Message;
using google::protobuf::Reflection;

// An entry whose plan and run are typed: Plan(request) -> StatusOr<PlanT>, Cost(plan) -> JobCost,
// Run(request, context) -> StatusOr<Result>.
template <typename Request, typename Result, typename PlanT>
JobKindSpec Entry(v1::JobKind kind, std::string name, std::string submit_method,
                  std::vector<std::string> paged_fields, StatusOr<PlanT> (*plan)(const Request&),
                  JobCost (*cost)(const PlanT&),
                  StatusOr<Result> (*run)(const Request&, const RunContext&)) {
  JobKindSpec spec;
  spec.kind = kind;
  spec.name = std::move(name);
  spec.submit_method = std::move(submit_method);
  spec.request_type = Request::descriptor();
  spec.result_type = Result::descriptor();
  spec.paged_fields = std::move(paged_fields);
  spec.plan = [plan, cost](const Message& request) -> StatusOr<JobCost> {
    DRILLBIF_ASSIGN_OR_RETURN(const PlanT checked, plan(static_cast<const Request&>(request)));
    return cost(checked);
  };
  spec.run = [run](const Message& request,
                   const RunContext& context) -> StatusOr<std::unique_ptr<Message>> {
    DRILLBIF_ASSIGN_OR_RETURN(Result result, run(static_cast<const Request&>(request), context));
    return std::unique_ptr<Message>(std::make_unique<Result>(std::move(result)));
  };
  return spec;
}

// Default limits (docs/service.md, "Admission control"). Results up to 256 MB (a million Poincare
// samples with events, or a period-2 map); memory up to 1 GB per job. Times: a simulation or a
// continuation that runs longer than minutes is a request error more often than a need; a trace
// or an optimum of a whole box takes ~30 s at period 1 and ~9 min at period 2.
constexpr int64_t kResultBytes = 256'000'000;
constexpr int64_t kMemoryBytes = 1'000'000'000;
KindLimits Limits(double seconds) { return {seconds, kResultBytes, kMemoryBytes}; }

std::vector<JobKindSpec> BuildKinds() {
  std::vector<JobKindSpec> kinds;
  kinds.push_back(Entry(v1::SIMULATE, "simulate", "SubmitSimulate",
                        {"poincare", "events", "period_modes", "trajectory"}, PlanSimulate,
                        SimulateCost, RunSimulate));
  kinds.back().default_limits = Limits(300);
  kinds.push_back(
      Entry(v1::SWEEP, "sweep", "SubmitSweep", {"up", "down"}, PlanSweep, SweepCost, RunSweep));
  kinds.back().default_limits = Limits(1800);
  kinds.back().key_neutral_fields = {"threads"};  // continuity does not depend on them (chunks do)
  kinds.push_back(Entry(v1::CONTINUE, "continue", "SubmitContinue", {"points"}, PlanContinue,
                        ContinueCost, RunContinue));
  kinds.back().first_page_fields = {"period_doubled_branch"};
  kinds.back().default_limits = Limits(600);
  kinds.push_back(
      Entry(v1::TRACE, "trace", "SubmitTrace", {"curves"}, PlanTrace, TraceCost, RunTrace));
  kinds.back().first_page_fields = {"region"};
  kinds.back().default_limits = Limits(1800);
  kinds.back().key_neutral_fields = {"threads"};  // the same curves on any number
  kinds.push_back(
      Entry(v1::OPTIMUM, "optimum", "SubmitOptimum", {}, PlanOptimum, OptimumCost, RunOptimum));
  kinds.back().default_limits = Limits(1800);
  kinds.back().key_neutral_fields = {"trace.threads"};
  kinds.push_back(Entry(v1::OPTIMUM_MAP, "optimum-map", "SubmitOptimumMap", {"cells"},
                        PlanOptimumMap, OptimumMapCost, RunOptimumMap));
  // A map of many cells, each an optimum of up to ~30 s on one core.
  kinds.back().default_limits = Limits(4 * 3600);
  kinds.back().key_neutral_fields = {"threads", "optimum.trace.threads"};
  return kinds;
}

// Clears the field at a dotted path of `message` (nothing when a message on the way is unset).
void ClearPath(Message* message, std::string_view path) {
  for (;;) {
    const size_t dot = path.find('.');
    const FieldDescriptor* field =
        message->GetDescriptor()->FindFieldByName(std::string(path.substr(0, dot)));
    if (field == nullptr) return;
    const Reflection* reflection = message->GetReflection();
    if (dot == std::string_view::npos) {
      reflection->ClearField(message, field);
      return;
    }
    if (field->is_repeated() || field->cpp_type() != FieldDescriptor::CPPTYPE_MESSAGE ||
        !reflection->HasField(*message, field)) {
      return;
    }
    message = reflection->MutableMessage(message, field);
    path.remove_prefix(dot + 1);
  }
}

// The kinds of child jobs: run by workers, never submitted by clients (not in Kinds()).
std::vector<JobKindSpec> BuildChildKinds() {
  std::vector<JobKindSpec> kinds;
  kinds.push_back(Entry(v1::JOB_KIND_UNSPECIFIED, kTraceTaskKind, "", {}, PlanTraceTask,
                        TraceTaskCost, RunTraceTaskJob));
  // As long as the parent may run: a task is a part of it.
  kinds.back().default_limits = Limits(1800);
  kinds.push_back(Entry(v1::JOB_KIND_UNSPECIFIED, kMapCellKind, "", {}, PlanOptimum, OptimumCost,
                        RunMapCellJob));
  kinds.back().default_limits = Limits(1800);  // an optimum's
  kinds.push_back(Entry(v1::JOB_KIND_UNSPECIFIED, kSweepPartKind, "", {}, PlanSweepPart,
                        SweepPartCost, RunSweepPart));
  kinds.back().default_limits = Limits(1800);  // a sweep's
  return kinds;
}

const std::vector<JobKindSpec>& Kinds() {
  static const std::vector<JobKindSpec> kinds = BuildKinds();
  return kinds;
}

// The first non-finite float or double field of `message` at any depth, as a dotted path below
// `prefix`; empty when all are finite.
std::string NonFiniteField(const Message& message, const std::string& prefix) {
  const Reflection* reflection = message.GetReflection();
  std::vector<const FieldDescriptor*> fields;
  reflection->ListFields(message, &fields);
  for (const FieldDescriptor* field : fields) {
    const std::string path = prefix + field->name();
    const bool repeated = field->is_repeated();
    const int n = repeated ? reflection->FieldSize(message, field) : 1;
    for (int i = 0; i < n; ++i) {
      const std::string at = repeated ? path + "[" + std::to_string(i) + "]" : path;
      switch (field->cpp_type()) {
        case FieldDescriptor::CPPTYPE_DOUBLE: {
          const double v = repeated ? reflection->GetRepeatedDouble(message, field, i)
                                    : reflection->GetDouble(message, field);
          if (!std::isfinite(v)) return at;
          break;
        }
        case FieldDescriptor::CPPTYPE_FLOAT: {
          const float v = repeated ? reflection->GetRepeatedFloat(message, field, i)
                                   : reflection->GetFloat(message, field);
          if (!std::isfinite(v)) return at;
          break;
        }
        case FieldDescriptor::CPPTYPE_MESSAGE: {
          const Message& sub = repeated ? reflection->GetRepeatedMessage(message, field, i)
                                        : reflection->GetMessage(message, field);
          std::string bad = NonFiniteField(sub, at + ".");
          if (!bad.empty()) return bad;
          break;
        }
        default:
          break;
      }
    }
  }
  return {};
}

// Counts what passes to the run's sink.
class CountingSink final : public ResultSink {
 public:
  explicit CountingSink(ResultSink* next) : next_(next) {}
  Status Append(const Message& items, int64_t count) override {
    DRILLBIF_RETURN_IF_ERROR(next_->Append(items, count));
    items_ += count;
    return Status::Ok();
  }
  int64_t items() const { return items_; }

 private:
  ResultSink* const next_;
  int64_t items_ = 0;
};

}  // namespace

std::unique_ptr<Message> JobKindSpec::NewRequest() const {
  return std::unique_ptr<Message>(
      google::protobuf::MessageFactory::generated_factory()->GetPrototype(request_type)->New());
}

std::unique_ptr<Message> JobKindSpec::NewResult() const {
  return std::unique_ptr<Message>(
      google::protobuf::MessageFactory::generated_factory()->GetPrototype(result_type)->New());
}

int64_t JobKindSpec::ItemsOf(const Message& result) const {
  int64_t items = 0;
  for (const std::string& field_name : paged_fields) {
    const FieldDescriptor* field = result.GetDescriptor()->FindFieldByName(field_name);
    items += result.GetReflection()->FieldSize(result, field);
  }
  return items;
}

const std::vector<const JobKindSpec*>& AllKinds() {
  static const std::vector<const JobKindSpec*> all = [] {
    std::vector<const JobKindSpec*> out;
    for (const JobKindSpec& kind : Kinds()) out.push_back(&kind);
    return out;
  }();
  return all;
}

const JobKindSpec* FindKind(v1::JobKind kind) {
  for (const JobKindSpec& k : Kinds()) {
    if (k.kind == kind) return &k;
  }
  return nullptr;
}

const JobKindSpec* FindKind(std::string_view name) {
  for (const JobKindSpec& k : Kinds()) {
    if (k.name == name) return &k;
  }
  return nullptr;
}

const JobKindSpec* FindChildKind(std::string_view name) {
  static const std::vector<JobKindSpec> kinds = BuildChildKinds();
  for (const JobKindSpec& k : kinds) {
    if (k.name == name) return &k;
  }
  return nullptr;
}

const JobKindSpec* FindKind(const google::protobuf::Descriptor* type) {
  for (const JobKindSpec& k : Kinds()) {
    if (k.request_type == type || k.result_type == type) return &k;
  }
  return nullptr;
}

StatusOr<JobCost> CheckRequest(const JobKindSpec& kind, const Message& request,
                               std::string_view prefix) {
  if (request.GetDescriptor() != kind.request_type) {
    return InvalidArgument("request: a " + request.GetTypeName() + " is not a " +
                           kind.request_type->full_name());
  }
  if (std::string bad = NonFiniteField(request, std::string(prefix)); !bad.empty()) {
    return InvalidArgument(bad + ": must be a finite number (NaN and infinities are refused)");
  }
  return kind.plan(request);
}

StatusOr<JobOutput> RunJob(const JobKindSpec& kind, std::string_view request_bytes,
                           const RunContext& context) {
  std::unique_ptr<Message> request = kind.NewRequest();
  if (!request->ParseFromArray(request_bytes.data(), static_cast<int>(request_bytes.size()))) {
    return InvalidArgument("the stored request is not a valid " + request->GetTypeName());
  }
  RunContext counted = context;
  std::unique_ptr<CountingSink> counter;
  if (context.sink != nullptr) {
    counter = std::make_unique<CountingSink>(context.sink);
    counted.sink = counter.get();
  }
  JobOutput out;
  DRILLBIF_ASSIGN_OR_RETURN(out.result, kind.run(*request, counted));
  out.streamed_items = counter ? counter->items() : 0;
  const FieldDescriptor* status = out.result->GetDescriptor()->FindFieldByName("status");
  if (status != nullptr) out.status = out.result->GetReflection()->GetString(*out.result, status);
  return out;
}

std::string CacheKeyOf(const JobKindSpec& spec, const Message& request) {
  if (spec.key_neutral_fields.empty()) return CacheKey(spec.name, DeterministicBytes(request));
  std::unique_ptr<Message> keyed(request.New());
  keyed->CopyFrom(request);
  for (const std::string& path : spec.key_neutral_fields) ClearPath(keyed.get(), path);
  return CacheKey(spec.name, DeterministicBytes(*keyed));
}

}  // namespace drillbif::jobs
