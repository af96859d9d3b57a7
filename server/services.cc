#include "server/services.h"

#include <google/protobuf/util/time_util.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <optional>
#include <string_view>
#include <utility>
#include <vector>

#include "jobs/registry.h"
#include "jobs/request_bytes.h"
#include "jobs/result_pages.h"
#include "server/stored_results.h"

namespace drillbif::server {
namespace {

using google::longrunning::Operation;
using google::protobuf::util::TimeUtil;
using Clock = std::chrono::steady_clock;

constexpr std::string_view kOperationsPrefix = "operations/";
// Longest a WaitOperation or a computing QueryOptimum waits (when the client set no shorter
// deadline or timeout): an rpc must end some time, and the client can wait again.
constexpr std::chrono::minutes kMaxWait{10};
// A wait ends this much before the client's deadline, so that the client receives the current
// operation rather than DEADLINE_EXCEEDED.
constexpr std::chrono::milliseconds kDeadlineMargin{50};
// Longest request_id.
constexpr size_t kMaxRequestIdBytes = 128;

grpc::Status Error(grpc::StatusCode code, std::string message) {
  return grpc::Status(code, std::move(message));
}

// The client the call's bearer token identifies ("" without tokens); UNAUTHENTICATED unless the
// call carries "authorization: Bearer <token>" with a known token (or no token is configured).
StatusOr<std::string> Authorize(const ServiceState& state,
                                const grpc::CallbackServerContext* context) {
  const auto& metadata = context->client_metadata();
  auto it = metadata.find("authorization");
  if (it == metadata.end()) return state.tokens->Authenticate(false, {});
  return state.tokens->Authenticate(true, std::string_view(it->second.data(), it->second.size()));
}

// The job id of an operation name; INVALID_ARGUMENT naming the field otherwise.
StatusOr<std::string> IdOf(const std::string& name, const char* field = "name") {
  if (name.size() != kOperationsPrefix.size() + 32 ||
      name.compare(0, kOperationsPrefix.size(), kOperationsPrefix) != 0) {
    return InvalidArgument(std::string(field) +
                           ": not an operation name (\"operations/\" and 32 "
                           "hex digits): '" +
                           name.substr(0, 100) + "'");
  }
  std::string id = name.substr(kOperationsPrefix.size());
  for (char c : id) {
    if (!((c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'))) {
      return InvalidArgument(std::string(field) + ": not an operation name: '" + name + "'");
    }
  }
  return id;
}

google::protobuf::Timestamp TimestampOfMs(int64_t ms) {
  return TimeUtil::MillisecondsToTimestamp(ms);
}

v1::JobState StateOf(JobState state) {
  switch (state) {
    case JobState::kQueued:
      return v1::QUEUED;
    case JobState::kRunning:
      return v1::RUNNING;
    case JobState::kSucceeded:
      return v1::SUCCEEDED;
    case JobState::kFailed:
      return v1::FAILED;
    case JobState::kCancelled:
      return v1::CANCELLED;
  }
  return v1::JOB_STATE_UNSPECIFIED;
}

// The Operation of a job. With include_response, a SUCCEEDED job's result goes into `response` as
// it is stored (no parse: the Any carries the serialized message): whole when it is at most
// max_inline_result_bytes, else its summary (JobMetadata.response_summary_only).
StatusOr<Operation> OperationOf(const ServiceState& state, const JobRecord& record,
                                bool include_response) {
  Operation op;
  op.set_name(OperationName(record.id));
  v1::JobMetadata metadata = MetadataOf(record);
  op.set_done(IsFinished(record.state));
  if (record.state == JobState::kFailed) {
    op.mutable_error()->set_code(static_cast<int>(record.error_code));
    op.mutable_error()->set_message(record.error_message);
  } else if (record.state == JobState::kCancelled) {
    op.mutable_error()->set_code(static_cast<int>(StatusCode::kCancelled));
    op.mutable_error()->set_message("the operation was cancelled");
  } else if (record.state == JobState::kSucceeded && include_response) {
    const jobs::JobKindSpec* kind = jobs::FindKind(record.kind);
    if (kind == nullptr) return Internal("job " + record.id + " has an unknown kind");
    bool summary_only = false;
    StatusOr<std::string> bytes = ResultForOperation(
        *state.store, record.id, state.options.max_inline_result_bytes, &summary_only);
    if (!bytes.ok()) return bytes.status();
    google::protobuf::Any* any = op.mutable_response();
    any->set_type_url("type.googleapis.com/" + kind->result_type->full_name());
    any->set_value(std::move(bytes).value());
    metadata.set_response_summary_only(summary_only);
  }
  op.mutable_metadata()->PackFrom(metadata);
  return op;
}

// Checks the token, then runs `work` (given the caller's client) on the executor and finishes the
// call with its status.
template <typename Call>
void Offload(ServiceState* state, Call* call,
             std::function<grpc::Status(const std::string& client)> work) {
  StatusOr<std::string> client = Authorize(*state, call->context());
  if (!client.ok()) return call->Finish(ToGrpc(client.status()));
  auto task = [call, client = std::move(client).value(), work = std::move(work)]() {
    call->Finish(work(client));
  };
  if (!state->executor->TrySubmit(std::move(task))) {
    call->Finish(Error(grpc::StatusCode::RESOURCE_EXHAUSTED,
                       "the server is busy: its request queue is full; retry later"));
  }
}

// Validates, keys and submits a request of `kind` for `client`; fills `op`. Runs on the executor.
grpc::Status Submit(ServiceState& state, v1::JobKind kind, const google::protobuf::Message& request,
                    const std::string& request_id, const std::string& client, Operation* op,
                    std::string* id_out = nullptr) {
  if (state.shutting_down.load()) {
    return Error(grpc::StatusCode::UNAVAILABLE, "the server is shutting down");
  }
  if (request_id.size() > kMaxRequestIdBytes) {
    return Error(grpc::StatusCode::INVALID_ARGUMENT,
                 "request_id: at most 128 bytes, got " + std::to_string(request_id.size()));
  }
  const jobs::JobKindSpec& spec = *jobs::FindKind(kind);
  const auto refuse = [&](const Status& s, const char* reason) {
    if (state.metrics != nullptr) state.metrics->CountAdmissionRefusal(spec.name, reason);
    return ToGrpc(s);
  };
  StatusOr<jobs::JobCost> cost = jobs::CheckRequest(spec, request);
  if (!cost.ok()) return refuse(cost.status(), "invalid_argument");
  if (Status s = jobs::CheckCost(*cost, state.options.LimitsOf(spec), spec.name.c_str()); !s.ok()) {
    return refuse(s, "resource_exhausted");
  }
  SubmitRequest submit;
  submit.kind = spec.name;
  submit.request = jobs::DeterministicBytes(request);
  submit.cache_key = jobs::CacheKeyOf(spec, request);
  submit.request_id = request_id;
  submit.client = client;
  submit.lane = cost->seconds.amount <= state.options.short_job_seconds ? kLaneShort : kLaneLong;
  submit.max_queued = state.options.max_queued_jobs;
  submit.max_queued_per_client = state.options.max_queued_per_client;
  StatusOr<SubmitResult> submitted = state.store->Submit(submit);
  if (!submitted.ok()) {
    // RESOURCE_EXHAUSTED from a healthy store is a queue limit; from a faulty one, its disk.
    return submitted.status().code() == StatusCode::kResourceExhausted && state.store->Health().ok()
               ? refuse(submitted.status(), "queue_full")
               : ToGrpc(submitted.status());
  }
  if (!submitted->cache_hit && !submitted->deduplicated && submitted->shared_with.empty()) {
    state.pool->Wake();
  }
  state.hub->Notify();
  StatusOr<JobRecord> record = state.store->Get(submitted->id);
  if (!record.ok()) return ToGrpc(record.status());
  StatusOr<Operation> operation = OperationOf(state, *record, /*include_response=*/true);
  if (!operation.ok()) return ToGrpc(operation.status());
  *op = std::move(operation).value();
  if (id_out != nullptr) *id_out = submitted->id;
  spdlog::debug("submit {} -> job {}{}{}", submit.kind, submitted->id,
                submitted->cache_hit ? " (cache hit)" : "",
                submitted->deduplicated ? " (repeated request_id)" : "");
  return grpc::Status::OK;
}

// A JobWatcher that calls `done` once, when the job is finished, unreadable, or the deadline
// passed (`timed_out`), or with UNAVAILABLE at shutdown.
class WaitWatcher : public JobWatcher {
 public:
  using Done = std::function<void(const StatusOr<JobRecord>& record, bool timed_out)>;
  WaitWatcher(Clock::time_point deadline, Done done)
      : deadline_(deadline), done_(std::move(done)) {}

  bool OnRecord(const StatusOr<JobRecord>& record, Clock::time_point now) override {
    const bool finished = !record.ok() || IsFinished(record->state);
    if (!finished && now < deadline_) return false;
    done_(record, !finished);
    return true;
  }
  void OnShutdown() override {
    done_(Status(StatusCode::kUnavailable, "the server is shutting down"), false);
  }
  Clock::time_point deadline() const override { return deadline_; }

 private:
  const Clock::time_point deadline_;
  const Done done_;
};

// When a wait started now must end: the earliest of the timeout (if > 0), the client's deadline
// (less a margin) and kMaxWait.
Clock::time_point WaitDeadline(const grpc::CallbackServerContext* context,
                               const google::protobuf::Duration* timeout) {
  const Clock::time_point now = Clock::now();
  Clock::time_point deadline = now + kMaxWait;
  if (timeout != nullptr && (timeout->seconds() > 0 || timeout->nanos() > 0)) {
    // Compared in seconds before any conversion: a timeout of up to 2^63 s (any int64, valid
    // Duration or not) overflows the milliseconds and the clock's nanoseconds, and an overflowed
    // deadline lies in the past, ending the wait at once.
    const double seconds = static_cast<double>(timeout->seconds()) + timeout->nanos() * 1e-9;
    if (seconds < std::chrono::duration<double>(kMaxWait).count()) {
      deadline = std::min(deadline, now + std::chrono::duration_cast<Clock::duration>(
                                              std::chrono::duration<double>(seconds)));
    }
  }
  const auto client = context->deadline();
  if (client != std::chrono::system_clock::time_point::max()) {
    const auto left = client - std::chrono::system_clock::now();
    deadline = std::min(deadline,
                        now + std::chrono::duration_cast<Clock::duration>(left) - kDeadlineMargin);
  }
  return deadline;
}

// Streams a job's metadata (Watch). The hub delivers records; the reactor writes the newest one
// not yet written, one write at a time, and finishes after writing a final state.
class WatchReactor : public grpc::ServerWriteReactor<grpc::ByteBuffer> {
 public:
  // The hub's side: shared so that it survives the reactor (which gRPC deletes in OnDone).
  class Sink : public JobWatcher {
   public:
    explicit Sink(WatchReactor* reactor) : reactor_(reactor) {}

    bool OnRecord(const StatusOr<JobRecord>& record, Clock::time_point) override {
      std::lock_guard<std::mutex> lock(mutex_);
      if (reactor_ == nullptr || finishing_) return true;
      if (!record.ok()) {
        FinishLocked(ToGrpc(record.status()));
        return true;
      }
      const bool final = IsFinished(record->state);
      std::string bytes = MetadataOf(*record).SerializeAsString();
      if (bytes != last_bytes_) {
        last_bytes_ = bytes;
        pending_ = std::move(bytes);
        pending_final_ = final;
        if (!writing_) WriteLocked();
      }
      return final;
    }

    void OnShutdown() override {
      std::lock_guard<std::mutex> lock(mutex_);
      if (reactor_ != nullptr && !finishing_) {
        FinishLocked(Error(grpc::StatusCode::UNAVAILABLE, "the server is shutting down"));
      }
    }

    void WriteDone(bool ok) {
      std::lock_guard<std::mutex> lock(mutex_);
      writing_ = false;
      if (reactor_ == nullptr) return;
      if (!ok) {
        // The stream broke (client gone): end the call.
        FinishLocked(Error(grpc::StatusCode::CANCELLED, "the stream was cancelled"));
        return;
      }
      if (finish_wanted_) {
        reactor_->Finish(*finish_wanted_);
        finish_wanted_.reset();
        return;
      }
      if (pending_) WriteLocked();
    }

    void Cancelled() {
      std::lock_guard<std::mutex> lock(mutex_);
      if (reactor_ != nullptr && !finishing_) {
        FinishLocked(Error(grpc::StatusCode::CANCELLED, "the call was cancelled"));
      }
    }

    void Detach() {
      std::lock_guard<std::mutex> lock(mutex_);
      reactor_ = nullptr;
    }

   private:
    void WriteLocked() {
      grpc::Slice slice(*pending_);
      current_ = grpc::ByteBuffer(&slice, 1);
      pending_.reset();
      writing_ = true;
      if (pending_final_) {
        finishing_ = true;
        reactor_->StartWriteAndFinish(&current_, grpc::WriteOptions(), grpc::Status::OK);
      } else {
        reactor_->StartWrite(&current_);
      }
    }

    // Finishes once; after a write in flight completes if there is one (gRPC allows one
    // operation of each kind at a time, and a finish must not overtake its last write).
    void FinishLocked(grpc::Status status) {
      status = BoundedStatus(std::move(status));
      finishing_ = true;
      if (writing_) {
        finish_wanted_ = std::move(status);
      } else {
        reactor_->Finish(std::move(status));
      }
    }

    std::mutex mutex_;
    WatchReactor* reactor_;
    bool writing_ = false;
    bool finishing_ = false;
    bool pending_final_ = false;
    std::optional<grpc::Status> finish_wanted_;
    std::optional<std::string> pending_;  // a serialized JobMetadata
    grpc::ByteBuffer current_;
    std::string last_bytes_;
  };

  WatchReactor() : sink_(std::make_shared<Sink>(this)) {}

  std::shared_ptr<Sink> sink() { return sink_; }

  void OnWriteDone(bool ok) override { sink_->WriteDone(ok); }
  void OnCancel() override { sink_->Cancelled(); }
  void OnDone() override {
    sink_->Detach();
    delete this;
  }

 private:
  std::shared_ptr<Sink> sink_;
};

// The filter of ListOperations: "" or terms "state=NAME" / "kind=name" joined by " AND ".
Status ParseFilter(const std::string& filter, ListRequest* list) {
  std::string_view rest(filter);
  while (!rest.empty()) {
    const size_t and_at = rest.find(" AND ");
    std::string_view term = rest.substr(0, and_at);
    rest = and_at == std::string_view::npos ? std::string_view() : rest.substr(and_at + 5);
    while (!term.empty() && term.front() == ' ') term.remove_prefix(1);
    while (!term.empty() && term.back() == ' ') term.remove_suffix(1);
    const size_t eq = term.find('=');
    const std::string key(term.substr(0, eq));
    const std::string value(eq == std::string_view::npos ? "" : term.substr(eq + 1));
    if (key == "state") {
      v1::JobState state;
      if (!v1::JobState_Parse(value, &state) || state == v1::JOB_STATE_UNSPECIFIED) {
        return InvalidArgument("filter: unknown state '" + value + "'");
      }
      list->state = static_cast<JobState>(static_cast<int>(state) - 1);
    } else if (key == "kind") {
      if (jobs::FindKind(value) == nullptr) {
        return InvalidArgument("filter: unknown kind '" + value + "'");
      }
      list->kind = value;
    } else {
      return InvalidArgument(
          "filter: expected terms state=STATE or kind=KIND joined by \" AND \", "
          "got '" +
          std::string(term) + "'");
    }
  }
  return Status::Ok();
}

// Fills a QueryOptimum response from the stored result of job `id`.
grpc::Status AnswerFromStore(ServiceState& state, const std::string& key, const std::string& id,
                             bool stored, v1::QueryOptimumResponse* response) {
  StatusOr<std::string> bytes = state.store->GetResult(id);
  if (!bytes.ok()) return ToGrpc(bytes.status());
  auto result = std::make_shared<v1::OptimumResult>();
  if (!result->ParseFromString(*bytes)) {
    return Error(grpc::StatusCode::INTERNAL, "the stored optimum result does not parse");
  }
  state.optimum_index.Add(key, id);
  state.optimum_index.SetResult(key, result);
  *response->mutable_optimum() = *result;
  response->set_operation(OperationName(id));
  response->set_stored(stored);
  return grpc::Status::OK;
}

// Answers `request` from the stored optimum maps into `response` (`optimum` set) when one covers
// its conditions; a verification failure with on_map_failure COMPUTE sets *compute instead.
// *nearest names the nearest map of the same box when none covers them. On the executor: a
// refresh reads the store and the verification runs the engine (~1 ms).
grpc::Status AnswerFromMaps(ServiceState& state, const v1::QueryOptimumRequest& request,
                            const std::string& key, v1::QueryOptimumResponse* response,
                            bool* compute, std::string* nearest) {
  std::shared_ptr<const jobs::LoadedMap> map = state.map_index.Find(request.request(), nearest);
  if (map == nullptr) {
    if (Status s = state.map_index.Refresh(*state.store, state.options.pages); !s.ok()) {
      return ToGrpc(s);
    }
    map = state.map_index.Find(request.request(), nearest);
    if (map == nullptr) return grpc::Status::OK;
  }
  const bool nearest_cell = request.on_map_failure() == v1::QueryOptimumRequest::NEAREST_CELL;
  jobs::MapQueryAnswer answer = jobs::AnswerFromMap(*map, request.request(), nearest_cell);
  if (!answer.from_map.verified() && !nearest_cell) {
    *compute = true;
    return grpc::Status::OK;
  }
  if (answer.optimum.status() == "FAILED" && !answer.optimum.has_params()) {
    return Error(
        grpc::StatusCode::FAILED_PRECONDITION,
        "the optimum map " + map->operation +
            " covers these conditions but cannot answer: " + answer.from_map.verification());
  }
  *response->mutable_optimum() = std::move(answer.optimum);
  *response->mutable_from_map() = std::move(answer.from_map);
  response->set_operation(map->operation);
  response->set_stored(false);
  // Only a verified answer is kept: an unverified one depends on on_map_failure (COMPUTE would
  // not take it).
  if (response->from_map().verified()) state.map_index.KeepAnswer(key, *response);
  return grpc::Status::OK;
}

}  // namespace

// ---------------------------------------------------------------------------------------------

grpc::Status ToGrpc(const Status& status) {
  if (status.ok()) return grpc::Status::OK;
  return grpc::Status(static_cast<grpc::StatusCode>(static_cast<int>(status.code())),
                      status.message());
}

std::string OperationName(const std::string& id) { return std::string(kOperationsPrefix) + id; }

v1::JobMetadata MetadataOf(const JobRecord& record) {
  v1::JobMetadata m;
  m.set_name(OperationName(record.id));
  const jobs::JobKindSpec* kind = jobs::FindKind(record.kind);
  m.set_kind(kind != nullptr ? kind->kind : v1::JOB_KIND_UNSPECIFIED);
  m.set_state(StateOf(record.state));
  m.set_progress(record.progress);
  if (record.current_value) m.set_current_value(*record.current_value);
  m.set_points(record.points);
  if (record.created_ms > 0) *m.mutable_create_time() = TimestampOfMs(record.created_ms);
  if (record.started_ms > 0) *m.mutable_start_time() = TimestampOfMs(record.started_ms);
  if (record.finished_ms > 0) *m.mutable_end_time() = TimestampOfMs(record.finished_ms);
  m.set_cache_hit(record.cache_hit);
  if (!record.shared_with.empty()) m.set_shared_with(OperationName(record.shared_with));
  m.set_attempts(record.attempts);
  m.set_request_id(record.request_id);
  m.set_lane(LaneName(record.lane));
  return m;
}

void OptimumIndex::Add(const std::string& key, const std::string& id) {
  if (key.empty()) return;
  std::lock_guard<std::mutex> lock(mutex_);
  entries_.try_emplace(key, Entry{id, nullptr});
}

void OptimumIndex::RemoveJob(const std::string& id) {
  std::lock_guard<std::mutex> lock(mutex_);
  std::erase_if(entries_, [&id](const auto& entry) { return entry.second.id == id; });
}

bool OptimumIndex::Find(const std::string& key, std::string* id,
                        std::shared_ptr<const v1::OptimumResult>* result) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = entries_.find(key);
  if (it == entries_.end()) return false;
  *id = it->second.id;
  *result = it->second.result;
  return true;
}

void OptimumIndex::SetResult(const std::string& key,
                             std::shared_ptr<const v1::OptimumResult> result) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = entries_.find(key);
  if (it != entries_.end()) it->second.result = std::move(result);
}

Status OptimumIndex::Load(JobStore& store) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    entries_.clear();
  }
  ListRequest list;
  list.state = JobState::kSucceeded;
  list.kind = jobs::FindKind(v1::OPTIMUM)->name;
  list.page_size = 1000;
  do {
    StatusOr<ListResult> page = store.List(list);
    if (!page.ok()) return page.status();
    for (const JobRecord& job : page->jobs) Add(job.cache_key, job.id);
    list.page_token = page->next_page_token;
  } while (!list.page_token.empty());
  return Status::Ok();
}

// --- Jobs --------------------------------------------------------------------------------------

template <typename Call>
void JobsService::RegisterUnary(const char* method, void (JobsService::*handle)(Call*)) {
  MarkMethodRawCallback(
      MethodIndex(v1::Jobs::service_full_name(), method),
      RawUnaryHandler<Call>([this, handle](Call* call) { (this->*handle)(call); }));
}

JobsService::JobsService(ServiceState* state) : state_(state) {
  RegisterUnary("SubmitSimulate", &JobsService::SubmitJob<v1::SIMULATE, SubmitSimulateCall>);
  RegisterUnary("SubmitSweep", &JobsService::SubmitJob<v1::SWEEP, SubmitSweepCall>);
  RegisterUnary("SubmitContinue", &JobsService::SubmitJob<v1::CONTINUE, SubmitContinueCall>);
  RegisterUnary("SubmitTrace", &JobsService::SubmitJob<v1::TRACE, SubmitTraceCall>);
  RegisterUnary("SubmitOptimum", &JobsService::SubmitJob<v1::OPTIMUM, SubmitOptimumCall>);
  RegisterUnary("SubmitOptimumMap", &JobsService::SubmitJob<v1::OPTIMUM_MAP, SubmitOptimumMapCall>);
  RegisterUnary("GetResult", &JobsService::GetResult);
  RegisterUnary("QueryOptimum", &JobsService::QueryOptimum);
  MarkMethodRawCallback(
      MethodIndex(v1::Jobs::service_full_name(), "Watch"),
      new grpc::internal::CallbackServerStreamingHandler<grpc::ByteBuffer, grpc::ByteBuffer>(
          [this](grpc::CallbackServerContext* context, const grpc::ByteBuffer* request) {
            return Watch(context, request);
          }));
}

template <v1::JobKind kKind, typename Call>
void JobsService::SubmitJob(Call* call) {
  Offload(state_, call, [this, call](const std::string& client) {
    const auto& r = call->request();
    return Submit(*state_, kKind, r.request(), r.request_id(), client, call->response());
  });
}

void JobsService::GetResult(GetResultCall* call) {
  Offload(state_, call, [this, call](const std::string&) {
    const v1::GetResultRequest& request = call->request();
    v1::GetResultResponse* response = call->response();
    StatusOr<std::string> id = IdOf(request.name());
    if (!id.ok()) return ToGrpc(id.status());
    StatusOr<JobRecord> record = state_->store->Get(*id);
    if (!record.ok()) return ToGrpc(record.status());
    if (record->state != JobState::kSucceeded) {
      return Error(grpc::StatusCode::FAILED_PRECONDITION,
                   "operation " + request.name() + " is " + JobStateName(record->state) +
                       ", not SUCCEEDED: it has no result (GetOperation shows its error)");
    }
    response->set_name(request.name());
    const jobs::JobKindSpec* kind = jobs::FindKind(record->kind);
    if (kind == nullptr) return ToGrpc(Internal("job " + *id + " has an unknown kind"));
    return ToGrpc(ReadResultPage(*state_->store, *kind, *id, request.page_size(),
                                 request.page_token(), state_->options.pages, response));
  });
}

void JobsService::QueryOptimum(QueryOptimumCall* call) {
  StatusOr<std::string> client = Authorize(*state_, call->context());
  if (!client.ok()) return call->Finish(ToGrpc(client.status()));
  const v1::QueryOptimumRequest& request = call->request();
  v1::QueryOptimumResponse* response = call->response();
  const jobs::JobKindSpec& optimum = *jobs::FindKind(v1::OPTIMUM);
  StatusOr<jobs::JobCost> cost = jobs::CheckRequest(optimum, request.request());
  if (!cost.ok()) return call->Finish(ToGrpc(cost.status()));
  if (!v1::QueryOptimumRequest::OnMapFailure_IsValid(request.on_map_failure())) {
    return call->Finish(Error(grpc::StatusCode::INVALID_ARGUMENT,
                              "on_map_failure: " + std::to_string(request.on_map_failure()) +
                                  " is not NEAREST_CELL (0) or COMPUTE (1)"));
  }
  const std::string key = jobs::CacheKeyOf(optimum, request.request());
  std::string id;
  std::shared_ptr<const v1::OptimumResult> cached;
  const bool known = state_->optimum_index.Find(key, &id, &cached);
  if (known && cached != nullptr) {
    // The hot path: an answer already in memory, no store and no engine.
    *response->mutable_optimum() = *cached;
    response->set_operation(OperationName(id));
    response->set_stored(true);
    return call->Finish(grpc::Status::OK);
  }
  // The same query answered from a map before: from memory too.
  const bool maps = !request.no_maps();
  if (!known && maps) {
    if (std::optional<v1::QueryOptimumResponse> kept = state_->map_index.Answer(key)) {
      *response = *std::move(kept);
      return call->Finish(grpc::Status::OK);
    }
  }
  // Computing it is a submit: the same limits apply (a stored answer is served whatever its cost).
  const Status affordable = jobs::CheckCost(*cost, state_->options.LimitsOf(optimum), "optimum");
  const Clock::time_point deadline = WaitDeadline(call->context(), &request.timeout());
  ServiceState* state = state_;
  const bool submitted = state_->executor->TrySubmit([=] {
    bool compute = request.compute();
    if (known) {
      grpc::Status s = AnswerFromStore(*state, key, id, /*stored=*/true, response);
      if (s.ok() || !compute) return call->Finish(s);
      state->optimum_index.RemoveJob(id);  // Deleted meanwhile: compute it again.
    } else {
      // Not in this process's index: another process sharing the store may have computed it.
      StatusOr<std::optional<std::string>> found = state->store->FindSucceeded(key);
      if (!found.ok()) return call->Finish(ToGrpc(found.status()));
      if (found->has_value()) {
        grpc::Status s = AnswerFromStore(*state, key, **found, /*stored=*/true, response);
        if (s.ok()) return call->Finish(s);
      }
      std::string nearest;
      if (maps) {
        grpc::Status s = AnswerFromMaps(*state, request, key, response, &compute, &nearest);
        if (!s.ok() || response->has_optimum()) return call->Finish(s);
      }
      if (!compute) {
        return call->Finish(
            Error(grpc::StatusCode::NOT_FOUND,
                  "no stored optimum for this request and no optimum map covers its conditions" +
                      (nearest.empty() ? std::string() : " (nearest: " + nearest + ")") +
                      "; set compute to run it"));
      }
      if (!affordable.ok()) return call->Finish(ToGrpc(affordable));
    }
    Operation op;
    std::string job_id;
    if (grpc::Status s = Submit(*state, v1::OPTIMUM, request.request(), "", *client, &op, &job_id);
        !s.ok()) {
      return call->Finish(s);
    }
    response->set_operation(op.name());
    auto done = [state, call, response, key, job_id](const StatusOr<JobRecord>& record,
                                                     bool timed_out) {
      if (!record.ok()) return call->Finish(ToGrpc(record.status()));
      if (timed_out) return call->Finish(grpc::Status::OK);  // `operation` names the job.
      switch (record->state) {
        case JobState::kSucceeded:
          return call->Finish(AnswerFromStore(*state, key, job_id, record->cache_hit, response));
        case JobState::kFailed:
          return call->Finish(ToGrpc(Status(record->error_code, record->error_message)));
        default:
          return call->Finish(Error(grpc::StatusCode::ABORTED, "the optimum job was cancelled"));
      }
    };
    state->hub->Add(job_id, std::make_shared<WaitWatcher>(deadline, std::move(done)));
  });
  if (!submitted) {
    call->Finish(Error(grpc::StatusCode::RESOURCE_EXHAUSTED,
                       "the server is busy: its request queue is full; retry later"));
  }
}

grpc::ServerWriteReactor<grpc::ByteBuffer>* JobsService::Watch(grpc::CallbackServerContext* context,
                                                               const grpc::ByteBuffer* raw) {
  auto* reactor = new WatchReactor();
  if (StatusOr<std::string> client = Authorize(*state_, context); !client.ok()) {
    reactor->Finish(BoundedStatus(ToGrpc(client.status())));
    return reactor;
  }
  v1::WatchRequest request;
  if (grpc::Status s = ParseRequest(*raw, &request); !s.ok()) {
    reactor->Finish(BoundedStatus(std::move(s)));
    return reactor;
  }
  StatusOr<std::string> id = IdOf(request.name());
  if (!id.ok()) {
    reactor->Finish(BoundedStatus(ToGrpc(id.status())));
    return reactor;
  }
  // The first record (and NOT_FOUND for an unknown job) comes from the hub at once.
  state_->hub->Add(*id, reactor->sink());
  return reactor;
}

// --- Operations --------------------------------------------------------------------------------

template <typename Call>
void OperationsService::RegisterUnary(const char* method,
                                      void (OperationsService::*handle)(Call*)) {
  MarkMethodRawCallback(
      MethodIndex(google::longrunning::Operations::service_full_name(), method),
      RawUnaryHandler<Call>([this, handle](Call* call) { (this->*handle)(call); }));
}

OperationsService::OperationsService(ServiceState* state) : state_(state) {
  RegisterUnary("ListOperations", &OperationsService::ListOperations);
  RegisterUnary("GetOperation", &OperationsService::GetOperation);
  RegisterUnary("DeleteOperation", &OperationsService::DeleteOperation);
  RegisterUnary("CancelOperation", &OperationsService::CancelOperation);
  RegisterUnary("WaitOperation", &OperationsService::WaitOperation);
}

void OperationsService::ListOperations(ListOperationsCall* call) {
  Offload(state_, call, [this, call](const std::string&) {
    const google::longrunning::ListOperationsRequest& request = call->request();
    if (!request.name().empty() && request.name() != "operations") {
      return Error(grpc::StatusCode::INVALID_ARGUMENT,
                   "name: the parent is \"operations\" (or empty), got '" +
                       request.name().substr(0, 100) + "'");
    }
    ListRequest list;
    if (Status s = ParseFilter(request.filter(), &list); !s.ok()) return ToGrpc(s);
    list.page_size = request.page_size();
    list.page_token = request.page_token();
    StatusOr<ListResult> page = state_->store->List(list);
    if (!page.ok()) return ToGrpc(page.status());
    for (const JobRecord& job : page->jobs) {
      // Results are left out of lists (they can be large): GetOperation or GetResult has them.
      StatusOr<Operation> op = OperationOf(*state_, job, /*include_response=*/false);
      if (!op.ok()) return ToGrpc(op.status());
      *call->response()->add_operations() = std::move(op).value();
    }
    call->response()->set_next_page_token(page->next_page_token);
    return grpc::Status::OK;
  });
}

void OperationsService::GetOperation(GetOperationCall* call) {
  Offload(state_, call, [this, call](const std::string&) {
    StatusOr<std::string> id = IdOf(call->request().name());
    if (!id.ok()) return ToGrpc(id.status());
    StatusOr<JobRecord> record = state_->store->Get(*id);
    if (!record.ok()) return ToGrpc(record.status());
    StatusOr<Operation> op = OperationOf(*state_, *record, /*include_response=*/true);
    if (!op.ok()) return ToGrpc(op.status());
    *call->response() = std::move(op).value();
    return grpc::Status::OK;
  });
}

void OperationsService::DeleteOperation(DeleteOperationCall* call) {
  Offload(state_, call, [this, call](const std::string&) {
    StatusOr<std::string> id = IdOf(call->request().name());
    if (!id.ok()) return ToGrpc(id.status());
    if (Status s = state_->store->Delete(*id); !s.ok()) return ToGrpc(s);
    state_->optimum_index.RemoveJob(*id);
    state_->map_index.RemoveJob(*id);
    state_->hub->Notify();
    return grpc::Status::OK;
  });
}

void OperationsService::CancelOperation(CancelOperationCall* call) {
  Offload(state_, call, [this, call](const std::string&) {
    StatusOr<std::string> id = IdOf(call->request().name());
    if (!id.ok()) return ToGrpc(id.status());
    StatusOr<JobState> after = state_->store->Cancel(*id);
    if (!after.ok()) return ToGrpc(after.status());
    // A running job stops at its engine's next progress callback.
    if (*after == JobState::kRunning) state_->pool->Cancel(*id);
    state_->hub->Notify();
    return grpc::Status::OK;
  });
}

void OperationsService::WaitOperation(WaitOperationCall* call) {
  if (StatusOr<std::string> client = Authorize(*state_, call->context()); !client.ok()) {
    return call->Finish(ToGrpc(client.status()));
  }
  const google::longrunning::WaitOperationRequest& request = call->request();
  StatusOr<std::string> id = IdOf(request.name());
  if (!id.ok()) return call->Finish(ToGrpc(id.status()));
  ServiceState* state = state_;
  auto done = [state, call](const StatusOr<JobRecord>& record, bool) {
    if (!record.ok()) return call->Finish(ToGrpc(record.status()));
    StatusOr<Operation> op = OperationOf(*state, *record, /*include_response=*/true);
    if (!op.ok()) return call->Finish(ToGrpc(op.status()));
    *call->response() = std::move(op).value();
    call->Finish(grpc::Status::OK);
  };
  state_->hub->Add(
      *id, std::make_shared<WaitWatcher>(
               WaitDeadline(call->context(), request.has_timeout() ? &request.timeout() : nullptr),
               std::move(done)));
}

}  // namespace drillbif::server
