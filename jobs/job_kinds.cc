#include "jobs/job_kinds.h"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <google/protobuf/reflection.h>
#include <openssl/evp.h>

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <string>

#include "drillbif/version.h"
#include "jobs/job_common.h"
#include "jobs/job_runner.h"
#include "jobs/optimum_runner.h"
#include "jobs/trace_runner.h"

namespace drillbif::jobs {
namespace {

using google::protobuf::FieldDescriptor;
using google::protobuf::Message;
using google::protobuf::Reflection;

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

// INVALID_ARGUMENT "field: message" unless the model parameters are valid.
Status CheckParams(const v1::ModelParams& params, const std::string& field) {
  const Params engine = internal::ToEngineParams(params);
  Status s = internal::Model().ValidateParams(engine);
  if (s.ok()) return s;
  return InvalidArgument(field + ": " + s.message());
}

template <typename Request>
StatusOr<Request> Parse(std::string_view bytes) {
  Request request;
  if (!request.ParseFromArray(bytes.data(), static_cast<int>(bytes.size()))) {
    return InvalidArgument("the stored request is not a valid " + request.GetTypeName());
  }
  return request;
}

// The runner's result as a JobOutput.
template <typename Result>
StatusOr<JobOutput> Output(StatusOr<Result> result, int64_t points_of_result) {
  if (!result.ok()) return result.status();
  JobOutput out;
  out.cancelled = result->status() == "CANCELLED";
  out.points = points_of_result;
  out.result = DeterministicBytes(*result);
  return out;
}

int64_t PointsOf(const v1::SimulateResult& r) { return r.poincare_size(); }
int64_t PointsOf(const v1::SweepResult& r) { return r.up_size() + r.down_size(); }
int64_t PointsOf(const v1::ContinueResult& r) { return r.points_size(); }
int64_t PointsOf(const v1::TraceResult& r) { return r.curves_size(); }
int64_t PointsOf(const v1::OptimumResult& r) { return r.status() == "COMPLETED" ? 1 : 0; }

template <typename Request, typename Result, typename Runner>
StatusOr<JobOutput> Run(std::string_view bytes, const ProgressCallback& progress, Runner runner) {
  StatusOr<Request> request = Parse<Request>(bytes);
  if (!request.ok()) return request.status();
  StatusOr<Result> result = runner(*request, progress);
  const int64_t points = result.ok() ? PointsOf(*result) : 0;
  return Output(std::move(result), points);
}

// Page tokens are "o" + the decimal offset of the first point of the page: opaque to clients,
// validated on use.
StatusOr<int64_t> ParsePageToken(std::string_view token) {
  if (token.empty()) return int64_t{0};
  int64_t offset = -1;
  if (token[0] == 'o') {
    const char* begin = token.data() + 1;
    const char* end = token.data() + token.size();
    auto [ptr, ec] = std::from_chars(begin, end, offset);
    if (ec != std::errc() || ptr != end || offset < 0) offset = -1;
  }
  if (offset < 0)
    return InvalidArgument("page_token: malformed token '" + std::string(token) + "'");
  return offset;
}

std::string NextToken(int64_t next, int64_t total) {
  if (next >= total) return std::string();
  std::string token("o");
  token += std::to_string(next);
  return token;
}

// Keeps the elements [begin, end) of a repeated field.
template <typename Repeated>
void KeepRange(Repeated* field, int64_t begin, int64_t end) {
  const int64_t n = field->size();
  begin = std::clamp<int64_t>(begin, 0, n);
  end = std::clamp<int64_t>(end, begin, n);
  if (end < n) field->DeleteSubrange(static_cast<int>(end), static_cast<int>(n - end));
  if (begin > 0) field->DeleteSubrange(0, static_cast<int>(begin));
}

}  // namespace

const char* KindName(v1::JobKind kind) {
  switch (kind) {
    case v1::SIMULATE:
      return "simulate";
    case v1::SWEEP:
      return "sweep";
    case v1::CONTINUE:
      return "continue";
    case v1::TRACE:
      return "trace";
    case v1::OPTIMUM:
      return "optimum";
    default:
      return "";
  }
}

v1::JobKind KindOf(std::string_view name) {
  for (v1::JobKind kind : {v1::SIMULATE, v1::SWEEP, v1::CONTINUE, v1::TRACE, v1::OPTIMUM}) {
    if (name == KindName(kind)) return kind;
  }
  return v1::JOB_KIND_UNSPECIFIED;
}

std::string ResultTypeName(v1::JobKind kind) {
  switch (kind) {
    case v1::SIMULATE:
      return v1::SimulateResult::descriptor()->full_name();
    case v1::SWEEP:
      return v1::SweepResult::descriptor()->full_name();
    case v1::CONTINUE:
      return v1::ContinueResult::descriptor()->full_name();
    case v1::TRACE:
      return v1::TraceResult::descriptor()->full_name();
    case v1::OPTIMUM:
      return v1::OptimumResult::descriptor()->full_name();
    default:
      return std::string();
  }
}

std::string DeterministicBytes(const google::protobuf::Message& message) {
  std::string bytes;
  {
    google::protobuf::io::StringOutputStream stream(&bytes);
    google::protobuf::io::CodedOutputStream coded(&stream);
    coded.SetSerializationDeterministic(true);
    message.SerializeToCodedStream(&coded);
  }  // The coded stream flushes into `bytes` when it goes out of scope.
  return bytes;
}

std::string Sha256Hex(std::string_view data) {
  unsigned char digest[EVP_MAX_MD_SIZE];
  unsigned int length = 0;
  EVP_Digest(data.data(), data.size(), digest, &length, EVP_sha256(), nullptr);
  std::string hex(2 * length, '0');
  static constexpr char kDigits[] = "0123456789abcdef";
  for (unsigned int i = 0; i < length; ++i) {
    hex[2 * i] = kDigits[digest[i] >> 4];
    hex[2 * i + 1] = kDigits[digest[i] & 15];
  }
  return hex;
}

std::string CacheKey(v1::JobKind kind, std::string_view request_bytes) {
  // Length prefixes make the concatenation unambiguous.
  std::string input;
  for (std::string_view part :
       {std::string_view(KindName(kind)), std::string_view(EngineVersion()), request_bytes}) {
    input += std::to_string(part.size());
    input += ':';
    input += part;
  }
  return Sha256Hex(input);
}

Status ValidateAtSubmit(v1::JobKind kind, const google::protobuf::Message& request) {
  if (std::string bad = NonFiniteField(request, "request."); !bad.empty()) {
    return InvalidArgument(bad + ": must be a finite number (NaN and infinities are refused)");
  }
  switch (kind) {
    case v1::SIMULATE:
      return CheckParams(static_cast<const v1::SimulateRequest&>(request).params(),
                         "request.params");
    case v1::SWEEP: {
      // The swept parameter's base value is replaced by the grid: check the others only.
      const auto& sweep = static_cast<const v1::SweepRequest&>(request);
      v1::ModelParams params = sweep.params();
      if (const FieldDescriptor* f = params.GetDescriptor()->FindFieldByName(sweep.param())) {
        params.GetReflection()->ClearField(&params, f);
      }
      return CheckParams(params, "request.params");
    }
    case v1::CONTINUE:
      return CheckParams(static_cast<const v1::ContinueRequest&>(request).params(),
                         "request.params");
    case v1::TRACE:
      return CheckParams(static_cast<const v1::TraceRequest&>(request).params(), "request.params");
    case v1::OPTIMUM:
      return CheckParams(static_cast<const v1::OptimumRequest&>(request).trace().params(),
                         "request.trace.params");
    default:
      return InvalidArgument("unknown job kind");
  }
}

StatusOr<JobOutput> RunJob(v1::JobKind kind, std::string_view request_bytes,
                           const ProgressCallback& progress,
                           const std::function<void(double)>& value,
                           jobs::OptimumCache* optimum_cache) {
  switch (kind) {
    case v1::SIMULATE:
      return Run<v1::SimulateRequest, v1::SimulateResult>(request_bytes, progress,
                                                          jobs::RunSimulate);
    case v1::SWEEP:
      return Run<v1::SweepRequest, v1::SweepResult>(
          request_bytes, progress, [&value](const v1::SweepRequest& r, const ProgressCallback& p) {
            return jobs::RunSweep(r, p, value);
          });
    case v1::CONTINUE:
      return Run<v1::ContinueRequest, v1::ContinueResult>(
          request_bytes, progress,
          [&value](const v1::ContinueRequest& r, const ProgressCallback& p) {
            return jobs::RunContinue(r, p, value);
          });
    case v1::TRACE:
      return Run<v1::TraceRequest, v1::TraceResult>(
          request_bytes, progress,
          [optimum_cache](const v1::TraceRequest& r, const ProgressCallback& p) {
            return jobs::RunTrace(r, p, optimum_cache);
          });
    case v1::OPTIMUM:
      return Run<v1::OptimumRequest, v1::OptimumResult>(
          request_bytes, progress,
          [optimum_cache](const v1::OptimumRequest& r, const ProgressCallback& p) {
            return jobs::RunOptimum(r, p, optimum_cache);
          });
    default:
      return InvalidArgument("unknown job kind");
  }
}

int64_t ExpectedPoints(v1::JobKind kind, std::string_view request_bytes) {
  if (kind != v1::SWEEP) return 0;
  StatusOr<v1::SweepRequest> sweep = Parse<v1::SweepRequest>(request_bytes);
  if (!sweep.ok()) return 0;
  const int64_t steps = sweep->has_steps() ? sweep->steps() : 1000;
  return sweep->direction() == v1::SweepRequest::BOTH ? 2 * steps : steps;
}

Status PageResult(v1::JobKind kind, std::string_view result_bytes, int page_size,
                  std::string_view page_token, v1::GetResultResponse* response) {
  if (page_size < 0 || page_size > kMaxResultPageSize) {
    return InvalidArgument("page_size: must be in [0, " + std::to_string(kMaxResultPageSize) +
                           "], got " + std::to_string(page_size));
  }
  StatusOr<int64_t> offset = ParsePageToken(page_token);
  if (!offset.ok()) return offset.status();
  const auto parse = [&](google::protobuf::Message* m) {
    return m->ParseFromArray(result_bytes.data(), static_cast<int>(result_bytes.size()))
               ? Status::Ok()
               : Internal("the stored result is not a valid " + m->GetTypeName());
  };
  const bool paged = page_size > 0;
  const int64_t begin = *offset;
  const int64_t end = begin + page_size;
  switch (kind) {
    case v1::SIMULATE: {
      v1::SimulateResult* r = response->mutable_simulate();
      if (Status s = parse(r); !s.ok()) return s;
      response->set_total_points(PointsOf(*r));
      return Status::Ok();
    }
    case v1::OPTIMUM: {
      v1::OptimumResult* r = response->mutable_optimum();
      if (Status s = parse(r); !s.ok()) return s;
      response->set_total_points(PointsOf(*r));
      return Status::Ok();
    }
    case v1::SWEEP: {
      v1::SweepResult* r = response->mutable_sweep();
      if (Status s = parse(r); !s.ok()) return s;
      const int64_t total = PointsOf(*r);
      response->set_total_points(total);
      if (!paged) return Status::Ok();
      // The page is a window on up ++ down.
      const int64_t n_up = r->up_size();
      KeepRange(r->mutable_up(), begin, end);
      KeepRange(r->mutable_down(), begin - n_up, end - n_up);
      response->set_next_page_token(NextToken(end, total));
      return Status::Ok();
    }
    case v1::CONTINUE: {
      v1::ContinueResult* r = response->mutable_continue_();
      if (Status s = parse(r); !s.ok()) return s;
      const int64_t total = PointsOf(*r);
      response->set_total_points(total);
      if (!paged) return Status::Ok();
      KeepRange(r->mutable_points(), begin, end);
      // The period-doubled branch is a result of its own: only in the first page.
      if (begin > 0) r->clear_period_doubled_branch();
      response->set_next_page_token(NextToken(end, total));
      return Status::Ok();
    }
    case v1::TRACE: {
      v1::TraceResult* r = response->mutable_trace();
      if (Status s = parse(r); !s.ok()) return s;
      const int64_t total = PointsOf(*r);
      response->set_total_points(total);
      if (!paged) return Status::Ok();
      KeepRange(r->mutable_curves(), begin, end);
      response->set_next_page_token(NextToken(end, total));
      return Status::Ok();
    }
    default:
      return Internal("unknown job kind");
  }
}

}  // namespace drillbif::jobs
