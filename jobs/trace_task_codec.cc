#include "jobs/trace_task_codec.h"

#include <google/protobuf/repeated_field.h>

#include <algorithm>
#include <climits>
#include <cstdint>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

#include "drillbif/v1/trace.pb.h"
#include "drillbif/v1/trace_task.pb.h"
#include "jobs/request_bytes.h"

namespace drillbif::jobs {
namespace {

using google::protobuf::RepeatedField;
using google::protobuf::RepeatedPtrField;

// The last enumerator of each engine enum the messages carry: decoding accepts 0 .. last. An
// enumerator added after one of these is refused by decoding (an error, never a wrong value)
// until it is named here; the codec's test compares these ranges with the engine's name
// functions, which name every enumerator.
constexpr SpecialPointKind kLastSpecialPointKind = SpecialPointKind::kPowerMax;
constexpr CurveKind kLastCurveKind = CurveKind::kNeimarkSacker;
constexpr Codim2Kind kLastCodim2Kind = Codim2Kind::kCusp;
constexpr Termination kLastTermination = Termination::kFailed;
constexpr StatusCode kLastStatusCode = StatusCode::kUnauthenticated;

// Errors name the field by its path from the top message: each level prefixes its field's name.
Status Within(const std::string& field, Status status) {
  if (status.ok()) return status;
  return InvalidArgument(field + "." + status.message());
}

Status Bad(const std::string& field, const std::string& what) {
  return InvalidArgument(field + ": " + what);
}

template <typename Enum>
int32_t EncodeEnum(Enum value) {
  return static_cast<int32_t>(value);
}

template <typename Enum>
Status DecodeEnum(const std::string& field, int32_t value, Enum last, Enum* out) {
  if (value < 0 || value > static_cast<int32_t>(last)) {
    return Bad(field, "value " + std::to_string(value) + " outside 0.." +
                          std::to_string(static_cast<int32_t>(last)));
  }
  *out = static_cast<Enum>(value);
  return Status::Ok();
}

void EncodeDoubles(const double* data, Eigen::Index size, RepeatedField<double>* out) {
  out->Reserve(static_cast<int>(size));
  out->Add(data, data + size);
}

// An Eigen vector of dynamic size up to `max_size` (the fixed capacity of StateVector and
// Params: a longer one would overrun it).
template <typename Vector>
Status DecodeVector(const std::string& field, const RepeatedField<double>& in, int max_size,
                    Vector* out) {
  if (in.size() > max_size) {
    return Bad(field, std::to_string(in.size()) + " values, more than the " +
                          std::to_string(max_size) + " it holds");
  }
  out->resize(in.size());
  std::copy(in.begin(), in.end(), out->data());
  return Status::Ok();
}

// Every struct's pair, declared ahead so that the templates below find them all.
void Encode(const Status& in, v1::TaskStatus* out);
Status Decode(const v1::TaskStatus& in, Status* out);
void Encode(const Signature& in, v1::TaskSignature* out);
Status Decode(const v1::TaskSignature& in, Signature* out);
void Encode(const PeriodicOrbit& in, v1::TaskOrbit* out);
Status Decode(const v1::TaskOrbit& in, PeriodicOrbit* out);
void Encode(const Stability& in, v1::TaskStability* out);
Status Decode(const v1::TaskStability& in, Stability* out);
void Encode(const Admissibility& in, v1::TaskAdmissibility* out);
Status Decode(const v1::TaskAdmissibility& in, Admissibility* out);
void Encode(const ContinuationSummary& in, v1::TaskSummary* out);
Status Decode(const v1::TaskSummary& in, ContinuationSummary* out);
void Encode(const ContinuationPoint& in, v1::TaskContinuationPoint* out);
Status Decode(const v1::TaskContinuationPoint& in, ContinuationPoint* out);
void Encode(const SideStability& in, v1::TaskSideStability* out);
Status Decode(const v1::TaskSideStability& in, SideStability* out);
void Encode(const NearGrazing& in, v1::TaskNearGrazing* out);
Status Decode(const v1::TaskNearGrazing& in, NearGrazing* out);
void Encode(const SpecialPoint& in, v1::TaskSpecialPoint* out);
Status Decode(const v1::TaskSpecialPoint& in, SpecialPoint* out);
void Encode(const CurvePoint& in, v1::TaskCurvePoint* out);
Status Decode(const v1::TaskCurvePoint& in, CurvePoint* out);
void Encode(const Codim2Point& in, v1::TaskCodim2Point* out);
Status Decode(const v1::TaskCodim2Point& in, Codim2Point* out);
void Encode(const CurveResult& in, v1::TaskCurveResult* out);
Status Decode(const v1::TaskCurveResult& in, CurveResult* out);
void Encode(const SwitchCandidate& in, v1::TaskSwitchCandidate* out);
Status Decode(const v1::TaskSwitchCandidate& in, SwitchCandidate* out);
void Encode(const std::pair<SpecialPoint, CurveResult>& in, v1::TaskCandidateTry* out);
Status Decode(const v1::TaskCandidateTry& in, std::pair<SpecialPoint, CurveResult>* out);
void Encode(const CandidateRun& in, v1::TaskCandidateRunResult* out);
Status Decode(const v1::TaskCandidateRunResult& in, CandidateRun* out);
void Encode(const std::vector<SwitchCandidate>& in, v1::TaskCandidateList* out);
Status Decode(const v1::TaskCandidateList& in, std::vector<SwitchCandidate>* out);
void Encode(const CurveTask& in, v1::TaskCurve* out);
Status Decode(const v1::TaskCurve& in, CurveTask* out);
void Encode(const CandidatesTask& in, v1::TaskCandidates* out);
Status Decode(const v1::TaskCandidates& in, CandidatesTask* out);
void Encode(const CandidateTask& in, v1::TaskCandidateRun* out);
Status Decode(const v1::TaskCandidateRun& in, CandidateTask* out);

void Encode(const Eigen::MatrixXd& in, v1::TaskMatrix* out) {
  out->set_rows(in.rows());
  out->set_cols(in.cols());
  EncodeDoubles(in.data(), in.size(), out->mutable_data());
}

Status DecodeMatrix(const std::string& field, const v1::TaskMatrix& in, Eigen::MatrixXd* out) {
  const int64_t rows = in.rows(), cols = in.cols(), size = in.data_size();
  // Dimensions past INT_MAX are refused before rows * cols is formed (no overflow).
  if (rows < 0 || cols < 0 || rows > INT_MAX || cols > INT_MAX || rows * cols != size) {
    return Bad(field, std::to_string(rows) + " x " + std::to_string(cols) + " matrix with " +
                          std::to_string(size) + " entries");
  }
  out->resize(rows, cols);
  std::copy(in.data().begin(), in.data().end(), out->data());
  return Status::Ok();
}

void Encode(const Status& in, v1::TaskStatus* out) {
  out->set_code(EncodeEnum(in.code()));
  out->set_message(in.message());
}

Status Decode(const v1::TaskStatus& in, Status* out) {
  StatusCode code = StatusCode::kOk;
  DRILLBIF_RETURN_IF_ERROR(DecodeEnum("code", in.code(), kLastStatusCode, &code));
  *out = Status(code, in.message());
  return Status::Ok();
}

// A message-typed field: the encoder always sets it, so an unset one is malformed.
template <typename Message, typename T>
Status DecodeRequired(const std::string& field, bool has, const Message& in, T* out) {
  if (!has) return Bad(field, "not set");
  return Within(field, Decode(in, out));
}

template <typename T, typename Message>
void EncodeList(const std::vector<T>& in, RepeatedPtrField<Message>* out) {
  out->Reserve(static_cast<int>(in.size()));
  for (const T& value : in) Encode(value, out->Add());
}

template <typename Message, typename T>
Status DecodeList(const std::string& field, const RepeatedPtrField<Message>& in,
                  std::vector<T>* out) {
  out->clear();
  out->reserve(in.size());
  for (int i = 0; i < in.size(); ++i) {
    T value;
    DRILLBIF_RETURN_IF_ERROR(Within(field + "[" + std::to_string(i) + "]", Decode(in[i], &value)));
    out->push_back(std::move(value));
  }
  return Status::Ok();
}

void Encode(const Signature& in, v1::TaskSignature* out) {
  out->set_periods(in.periods);
  for (const SegmentSpec& s : in.segments) {
    v1::TaskSegment* segment = out->add_segments();
    segment->set_mode(s.mode);
    segment->set_guard(s.guard);
    segment->set_tangent(s.tangent);
  }
}

Status Decode(const v1::TaskSignature& in, Signature* out) {
  out->periods = in.periods();
  out->segments.clear();
  for (const v1::TaskSegment& s : in.segments()) {
    out->segments.push_back(SegmentSpec{s.mode(), s.guard(), s.tangent()});
  }
  return Status::Ok();
}

void Encode(const PeriodicOrbit& in, v1::TaskOrbit* out) {
  Encode(in.signature, out->mutable_signature());
  EncodeDoubles(in.params.data(), in.params.size(), out->mutable_params());
  for (const StateVector& x : in.starts) {
    EncodeDoubles(x.data(), x.size(), out->add_starts()->mutable_values());
  }
  EncodeDoubles(in.durations.data(), in.durations.size(), out->mutable_durations());
}

Status Decode(const v1::TaskOrbit& in, PeriodicOrbit* out) {
  DRILLBIF_RETURN_IF_ERROR(
      DecodeRequired("signature", in.has_signature(), in.signature(), &out->signature));
  DRILLBIF_RETURN_IF_ERROR(DecodeVector("params", in.params(), kMaxParams, &out->params));
  out->starts.assign(in.starts_size(), StateVector());
  for (int i = 0; i < in.starts_size(); ++i) {
    DRILLBIF_RETURN_IF_ERROR(DecodeVector("starts[" + std::to_string(i) + "]",
                                          in.starts(i).values(), kMaxStateDim, &out->starts[i]));
  }
  out->durations.assign(in.durations().begin(), in.durations().end());
  return Status::Ok();
}

void Encode(const Stability& in, v1::TaskStability* out) {
  for (const std::complex<double>& mu : in.multipliers) {
    v1::TaskComplex* c = out->add_multipliers();
    c->set_re(mu.real());
    c->set_im(mu.imag());
  }
  out->set_structural_zeros(in.structural_zeros);
  out->set_structural_ones(in.structural_ones);
  out->set_stable(in.stable);
  Encode(in.monodromy, out->mutable_monodromy());
}

Status Decode(const v1::TaskStability& in, Stability* out) {
  out->multipliers.clear();
  for (const v1::TaskComplex& c : in.multipliers()) out->multipliers.emplace_back(c.re(), c.im());
  out->structural_zeros = in.structural_zeros();
  out->structural_ones = in.structural_ones();
  out->stable = in.stable();
  if (!in.has_monodromy()) return Bad("monodromy", "not set");
  return DecodeMatrix("monodromy", in.monodromy(), &out->monodromy);
}

void Encode(const Admissibility& in, v1::TaskAdmissibility* out) {
  out->set_admissible(in.admissible);
  out->set_segment(in.segment);
  out->set_guard(in.guard);
  out->set_at_start(in.at_start);
  out->set_time(in.time);
  out->set_message(in.message);
}

Status Decode(const v1::TaskAdmissibility& in, Admissibility* out) {
  out->admissible = in.admissible();
  out->segment = in.segment();
  out->guard = in.guard();
  out->at_start = in.at_start();
  out->time = in.time();
  out->message = in.message();
  return Status::Ok();
}

void Encode(const ContinuationSummary& in, v1::TaskSummary* out) {
  out->set_termination(EncodeEnum(in.termination));
  Encode(in.status, out->mutable_status());
  out->set_message(in.message);
  out->set_steps(in.steps);
  out->set_rejected_steps(in.rejected_steps);
  out->set_newton_iterations(in.newton_iterations);
}

Status Decode(const v1::TaskSummary& in, ContinuationSummary* out) {
  DRILLBIF_RETURN_IF_ERROR(
      DecodeEnum("termination", in.termination(), kLastTermination, &out->termination));
  DRILLBIF_RETURN_IF_ERROR(DecodeRequired("status", in.has_status(), in.status(), &out->status));
  out->message = in.message();
  out->steps = in.steps();
  out->rejected_steps = in.rejected_steps();
  out->newton_iterations = in.newton_iterations();
  return Status::Ok();
}

void Encode(const ContinuationPoint& in, v1::TaskContinuationPoint* out) {
  out->set_value(in.value);
  Encode(in.orbit, out->mutable_orbit());
  EncodeDoubles(in.measures.data(), in.measures.size(), out->mutable_measures());
  Encode(in.stability, out->mutable_stability());
  out->set_period(in.period);
}

Status Decode(const v1::TaskContinuationPoint& in, ContinuationPoint* out) {
  out->value = in.value();
  DRILLBIF_RETURN_IF_ERROR(DecodeRequired("orbit", in.has_orbit(), in.orbit(), &out->orbit));
  out->measures.assign(in.measures().begin(), in.measures().end());
  DRILLBIF_RETURN_IF_ERROR(
      DecodeRequired("stability", in.has_stability(), in.stability(), &out->stability));
  out->period = in.period();
  return Status::Ok();
}

void Encode(const SideStability& in, v1::TaskSideStability* out) {
  out->set_known(in.known);
  out->set_stable(in.stable);
  out->set_max_modulus(in.max_modulus);
}

Status Decode(const v1::TaskSideStability& in, SideStability* out) {
  *out = SideStability{in.known(), in.stable(), in.max_modulus()};
  return Status::Ok();
}

void Encode(const NearGrazing& in, v1::TaskNearGrazing* out) {
  out->set_near(in.near);
  out->set_kind(EncodeEnum(in.kind));
  out->set_value(in.value);
  out->set_distance(in.distance);
}

Status Decode(const v1::TaskNearGrazing& in, NearGrazing* out) {
  out->near = in.near();
  DRILLBIF_RETURN_IF_ERROR(DecodeEnum("kind", in.kind(), kLastSpecialPointKind, &out->kind));
  out->value = in.value();
  out->distance = in.distance();
  return Status::Ok();
}

void Encode(const SpecialPoint& in, v1::TaskSpecialPoint* out) {
  out->set_kind(EncodeEnum(in.kind));
  Encode(in.point, out->mutable_point());
  out->set_detail(in.detail);
  Encode(in.before, out->mutable_before());
  Encode(in.after, out->mutable_after());
  Encode(in.near_grazing, out->mutable_near_grazing());
}

Status Decode(const v1::TaskSpecialPoint& in, SpecialPoint* out) {
  DRILLBIF_RETURN_IF_ERROR(DecodeEnum("kind", in.kind(), kLastSpecialPointKind, &out->kind));
  DRILLBIF_RETURN_IF_ERROR(DecodeRequired("point", in.has_point(), in.point(), &out->point));
  out->detail = in.detail();
  DRILLBIF_RETURN_IF_ERROR(DecodeRequired("before", in.has_before(), in.before(), &out->before));
  DRILLBIF_RETURN_IF_ERROR(DecodeRequired("after", in.has_after(), in.after(), &out->after));
  return DecodeRequired("near_grazing", in.has_near_grazing(), in.near_grazing(),
                        &out->near_grazing);
}

void Encode(const CurvePoint& in, v1::TaskCurvePoint* out) {
  out->set_value1(in.value1);
  out->set_value2(in.value2);
  Encode(in.orbit, out->mutable_orbit());
  EncodeDoubles(in.measures.data(), in.measures.size(), out->mutable_measures());
  Encode(in.stability, out->mutable_stability());
}

Status Decode(const v1::TaskCurvePoint& in, CurvePoint* out) {
  out->value1 = in.value1();
  out->value2 = in.value2();
  DRILLBIF_RETURN_IF_ERROR(DecodeRequired("orbit", in.has_orbit(), in.orbit(), &out->orbit));
  out->measures.assign(in.measures().begin(), in.measures().end());
  return DecodeRequired("stability", in.has_stability(), in.stability(), &out->stability);
}

void Encode(const Codim2Point& in, v1::TaskCodim2Point* out) {
  out->set_kind(EncodeEnum(in.kind));
  Encode(in.point, out->mutable_point());
  out->set_detail(in.detail);
  out->set_bracket(in.bracket);
  Encode(in.violation, out->mutable_violation());
  out->set_same_as_curve(in.same_as_curve);
  out->set_same_as_index(in.same_as_index);
}

Status Decode(const v1::TaskCodim2Point& in, Codim2Point* out) {
  DRILLBIF_RETURN_IF_ERROR(DecodeEnum("kind", in.kind(), kLastCodim2Kind, &out->kind));
  DRILLBIF_RETURN_IF_ERROR(DecodeRequired("point", in.has_point(), in.point(), &out->point));
  out->detail = in.detail();
  out->bracket = in.bracket();
  DRILLBIF_RETURN_IF_ERROR(
      DecodeRequired("violation", in.has_violation(), in.violation(), &out->violation));
  out->same_as_curve = in.same_as_curve();
  out->same_as_index = in.same_as_index();
  return Status::Ok();
}

void Encode(const CurveResult& in, v1::TaskCurveResult* out) {
  out->set_kind(EncodeEnum(in.kind));
  EncodeList(in.points, out->mutable_points());
  EncodeList(in.crossings, out->mutable_crossings());
  EncodeList(in.codim2, out->mutable_codim2());
  EncodeList(in.unverified_ends, out->mutable_unverified_ends());
  Encode(in.summary, out->mutable_summary());
}

Status Decode(const v1::TaskCurveResult& in, CurveResult* out) {
  DRILLBIF_RETURN_IF_ERROR(DecodeEnum("kind", in.kind(), kLastCurveKind, &out->kind));
  DRILLBIF_RETURN_IF_ERROR(DecodeList("points", in.points(), &out->points));
  DRILLBIF_RETURN_IF_ERROR(DecodeList("crossings", in.crossings(), &out->crossings));
  DRILLBIF_RETURN_IF_ERROR(DecodeList("codim2", in.codim2(), &out->codim2));
  DRILLBIF_RETURN_IF_ERROR(
      DecodeList("unverified_ends", in.unverified_ends(), &out->unverified_ends));
  return DecodeRequired("summary", in.has_summary(), in.summary(), &out->summary);
}

// The StatusOr<PeriodicOrbit>: an orbit with status OK, or no orbit and the error.
void Encode(const SwitchCandidate& in, v1::TaskSwitchCandidate* out) {
  if (in.orbit.ok()) Encode(*in.orbit, out->mutable_orbit());
  Encode(in.orbit.status(), out->mutable_orbit_status());
  out->set_seed_kind(EncodeEnum(in.seed_kind));
  out->set_kind(EncodeEnum(in.kind));
  out->set_step_off(in.step_off);
}

Status DecodeCandidateOrbit(const v1::TaskSwitchCandidate& in, StatusOr<PeriodicOrbit>* out) {
  Status status;
  DRILLBIF_RETURN_IF_ERROR(
      DecodeRequired("orbit_status", in.has_orbit_status(), in.orbit_status(), &status));
  if (!status.ok()) {
    if (in.has_orbit()) return Bad("orbit", "set with the error " + status.ToString());
    *out = std::move(status);
    return Status::Ok();
  }
  // An OK StatusOr has no message; one here could not be decoded back into it.
  if (!status.message().empty()) return Bad("orbit_status", "OK with a message");
  PeriodicOrbit orbit;
  DRILLBIF_RETURN_IF_ERROR(DecodeRequired("orbit", in.has_orbit(), in.orbit(), &orbit));
  *out = std::move(orbit);
  return Status::Ok();
}

Status Decode(const v1::TaskSwitchCandidate& in, SwitchCandidate* out) {
  DRILLBIF_RETURN_IF_ERROR(DecodeCandidateOrbit(in, &out->orbit));
  DRILLBIF_RETURN_IF_ERROR(
      DecodeEnum("seed_kind", in.seed_kind(), kLastSpecialPointKind, &out->seed_kind));
  DRILLBIF_RETURN_IF_ERROR(DecodeEnum("kind", in.kind(), kLastCurveKind, &out->kind));
  out->step_off = in.step_off();
  return Status::Ok();
}

void Encode(const std::pair<SpecialPoint, CurveResult>& in, v1::TaskCandidateTry* out) {
  Encode(in.first, out->mutable_start());
  Encode(in.second, out->mutable_curve());
}

Status Decode(const v1::TaskCandidateTry& in, std::pair<SpecialPoint, CurveResult>* out) {
  DRILLBIF_RETURN_IF_ERROR(DecodeRequired("start", in.has_start(), in.start(), &out->first));
  return DecodeRequired("curve", in.has_curve(), in.curve(), &out->second);
}

void Encode(const CandidateRun& in, v1::TaskCandidateRunResult* out) {
  out->set_deferred(in.deferred);
  out->set_stopped(in.stopped);
  EncodeList(in.tries, out->mutable_tries());
}

Status Decode(const v1::TaskCandidateRunResult& in, CandidateRun* out) {
  out->deferred = in.deferred();
  out->stopped = in.stopped();
  return DecodeList("tries", in.tries(), &out->tries);
}

void Encode(const std::vector<SwitchCandidate>& in, v1::TaskCandidateList* out) {
  EncodeList(in, out->mutable_candidates());
}

Status Decode(const v1::TaskCandidateList& in, std::vector<SwitchCandidate>* out) {
  return DecodeList("candidates", in.candidates(), out);
}

void Encode(const CurveTask& in, v1::TaskCurve* out) {
  Encode(in.start, out->mutable_start());
  out->set_axis(in.axis);
}

Status Decode(const v1::TaskCurve& in, CurveTask* out) {
  DRILLBIF_RETURN_IF_ERROR(DecodeRequired("start", in.has_start(), in.start(), &out->start));
  out->axis = in.axis();
  return Status::Ok();
}

void Encode(const CandidatesTask& in, v1::TaskCandidates* out) {
  out->set_from_kind(EncodeEnum(in.from_kind));
  Encode(in.point, out->mutable_point());
}

Status Decode(const v1::TaskCandidates& in, CandidatesTask* out) {
  DRILLBIF_RETURN_IF_ERROR(
      DecodeEnum("from_kind", in.from_kind(), kLastCurveKind, &out->from_kind));
  return DecodeRequired("point", in.has_point(), in.point(), &out->point);
}

void Encode(const CandidateTask& in, v1::TaskCandidateRun* out) {
  Encode(in.point, out->mutable_point());
  Encode(in.candidate, out->mutable_candidate());
  out->set_last_resort(in.last_resort);
}

Status Decode(const v1::TaskCandidateRun& in, CandidateTask* out) {
  DRILLBIF_RETURN_IF_ERROR(DecodeRequired("point", in.has_point(), in.point(), &out->point));
  DRILLBIF_RETURN_IF_ERROR(
      DecodeRequired("candidate", in.has_candidate(), in.candidate(), &out->candidate));
  out->last_resort = in.last_resort();
  return Status::Ok();
}

// Decodes `in` into a new alternative T of the variant `out`.
template <typename T, typename Message, typename Variant>
Status DecodeAlternative(const std::string& field, const Message& in, Variant* out) {
  T value;
  DRILLBIF_RETURN_IF_ERROR(Within(field, Decode(in, &value)));
  *out = std::move(value);
  return Status::Ok();
}

// Parses `bytes` (the field `field`) as a `message`; protobuf's parser takes at most INT_MAX
// bytes.
Status Parse(std::string_view bytes, const std::string& field, google::protobuf::Message* message) {
  if (bytes.size() > static_cast<size_t>(INT_MAX) ||
      !message->ParseFromArray(bytes.data(), static_cast<int>(bytes.size()))) {
    return Bad(field, "not a serialized " + message->GetTypeName());
  }
  return Status::Ok();
}

Status DecodeTask(const v1::TraceTaskRequest& in, TraceTask* out) {
  switch (in.task_case()) {
    case v1::TraceTaskRequest::kCurve:
      return DecodeAlternative<CurveTask>("curve", in.curve(), out);
    case v1::TraceTaskRequest::kCandidates:
      return DecodeAlternative<CandidatesTask>("candidates", in.candidates(), out);
    case v1::TraceTaskRequest::kCandidateRun:
      return DecodeAlternative<CandidateTask>("candidate_run", in.candidate_run(), out);
    case v1::TraceTaskRequest::TASK_NOT_SET:
      break;
  }
  return Bad("task", "not set (one of curve, candidates, candidate_run)");
}

Status DecodeResult(const v1::TraceTaskResponse& in, TraceTaskResult* out) {
  switch (in.result_case()) {
    case v1::TraceTaskResponse::kCurve:
      return DecodeAlternative<CurveResult>("curve", in.curve(), out);
    case v1::TraceTaskResponse::kCandidates:
      return DecodeAlternative<std::vector<SwitchCandidate>>("candidates", in.candidates(), out);
    case v1::TraceTaskResponse::kCandidateRun:
      return DecodeAlternative<CandidateRun>("candidate_run", in.candidate_run(), out);
    case v1::TraceTaskResponse::RESULT_NOT_SET:
      break;
  }
  return Bad("result", "not set (one of curve, candidates, candidate_run)");
}

}  // namespace

void EncodeTask(const TraceTask& task, v1::TraceTaskRequest* request) {
  std::visit(
      [request](const auto& t) {
        using T = std::decay_t<decltype(t)>;
        if constexpr (std::is_same_v<T, CurveTask>) Encode(t, request->mutable_curve());
        if constexpr (std::is_same_v<T, CandidatesTask>) Encode(t, request->mutable_candidates());
        if constexpr (std::is_same_v<T, CandidateTask>) {
          Encode(t, request->mutable_candidate_run());
        }
      },
      task);
}

std::string EncodeTraceTaskRequest(std::string_view parent_trace_request, const TraceTask& task) {
  v1::TraceTaskRequest request;
  request.set_trace_request(std::string(parent_trace_request));
  EncodeTask(task, &request);
  return DeterministicBytes(request);
}

std::string EncodeTraceTaskBatch(std::string_view parent_trace_request,
                                 const std::vector<const TraceTask*>& tasks) {
  v1::TraceTaskBatch batch;
  batch.set_trace_request(std::string(parent_trace_request));
  for (const TraceTask* task : tasks) EncodeTask(*task, batch.add_tasks());
  return DeterministicBytes(batch);
}

StatusOr<DecodedTraceTaskBatch> DecodeTraceTaskBatch(const v1::TraceTaskBatch& batch) {
  v1::TraceRequest parent;
  DRILLBIF_RETURN_IF_ERROR(
      Within("TraceTaskBatch", Parse(batch.trace_request(), "trace_request", &parent)));
  if (batch.tasks().empty() || batch.tasks_size() > kMaxTraceTaskBatch) {
    return Bad("TraceTaskBatch.tasks", std::to_string(batch.tasks_size()) + " tasks, not 1 .. " +
                                           std::to_string(kMaxTraceTaskBatch));
  }
  DecodedTraceTaskBatch decoded;
  decoded.trace_request = batch.trace_request();
  decoded.tasks.resize(batch.tasks_size());
  for (int i = 0; i < batch.tasks_size(); ++i) {
    DRILLBIF_RETURN_IF_ERROR(Within("TraceTaskBatch.tasks[" + std::to_string(i) + "]",
                                    DecodeTask(batch.tasks(i), &decoded.tasks[i])));
  }
  return decoded;
}

StatusOr<DecodedTraceTask> DecodeTraceTaskRequest(std::string_view bytes) {
  v1::TraceTaskRequest request;
  DRILLBIF_RETURN_IF_ERROR(Parse(bytes, "TraceTaskRequest", &request));
  return DecodeTraceTaskRequest(request);
}

StatusOr<DecodedTraceTask> DecodeTraceTaskRequest(const v1::TraceTaskRequest& request) {
  v1::TraceRequest parent;
  DRILLBIF_RETURN_IF_ERROR(
      Within("TraceTaskRequest", Parse(request.trace_request(), "trace_request", &parent)));
  DecodedTraceTask decoded;
  DRILLBIF_RETURN_IF_ERROR(Within("TraceTaskRequest", DecodeTask(request, &decoded.task)));
  decoded.trace_request = request.trace_request();
  return decoded;
}

std::string EncodeTraceTaskResult(const TraceTaskResult& result) {
  return DeterministicBytes(TraceTaskResponseOf(result));
}

v1::TraceTaskResponse TraceTaskResponseOf(const TraceTaskResult& result) {
  v1::TraceTaskResponse response;
  std::visit(
      [&response](const auto& r) {
        using T = std::decay_t<decltype(r)>;
        if constexpr (std::is_same_v<T, CurveResult>) Encode(r, response.mutable_curve());
        if constexpr (std::is_same_v<T, std::vector<SwitchCandidate>>) {
          Encode(r, response.mutable_candidates());
        }
        if constexpr (std::is_same_v<T, CandidateRun>) Encode(r, response.mutable_candidate_run());
      },
      result);
  response.set_status("COMPLETED");
  return response;
}

StatusOr<TraceTaskResult> DecodeTraceTaskResult(std::string_view bytes) {
  v1::TraceTaskResponse response;
  DRILLBIF_RETURN_IF_ERROR(Parse(bytes, "TraceTaskResponse", &response));
  TraceTaskResult result;
  DRILLBIF_RETURN_IF_ERROR(Within("TraceTaskResponse", DecodeResult(response, &result)));
  return result;
}

v1::TraceTaskBatchResponse TraceTaskBatchResponseOf(const std::vector<TraceTaskResult>& results) {
  v1::TraceTaskBatchResponse response;
  for (const TraceTaskResult& r : results) *response.add_results() = TraceTaskResponseOf(r);
  response.set_status("COMPLETED");
  return response;
}

StatusOr<std::vector<TraceTaskResult>> DecodeTraceTaskBatchResponse(std::string_view bytes) {
  v1::TraceTaskBatchResponse response;
  DRILLBIF_RETURN_IF_ERROR(Parse(bytes, "TraceTaskBatchResponse", &response));
  std::vector<TraceTaskResult> results(response.results_size());
  for (int i = 0; i < response.results_size(); ++i) {
    DRILLBIF_RETURN_IF_ERROR(Within("TraceTaskBatchResponse.results[" + std::to_string(i) + "]",
                                    DecodeResult(response.results(i), &results[i])));
  }
  return results;
}

void EncodeOrbit(const PeriodicOrbit& orbit, v1::TaskOrbit* out) { Encode(orbit, out); }

Status DecodeOrbit(const v1::TaskOrbit& in, PeriodicOrbit* out) {
  return Within("orbit", Decode(in, out));
}

}  // namespace drillbif::jobs
