// libFuzzer target: the submit-time checks of one job kind (jobs/registry.h CheckRequest: the
// finiteness check and the kind's validation and cost estimate) and its admission against the
// kind's default limits (jobs/job_cost.h CheckCost). Built once per kind: DRILLBIF_FUZZ_KIND is
// the kind's name ("simulate", "sweep", "continue", "trace", "optimum").
//
// Input: the kind's request message (SimulateRequest, ...), as JSON when it starts with '{'
// (parsed by the REST gateway's own FromJson: UTF-8 checked, unknown fields refused), else as
// binary protobuf (what gRPC clients send and the store keeps).
//
// Invariants beyond "no crash, no sanitizer report" (UBSan traps on signed overflow and on
// out-of-range float-to-integer casts):
// - a refusal is INVALID_ARGUMENT with a message naming a field of the request;
// - an estimate has every amount >= 0 and not NaN, each with a driver to name in a refusal;
// - an amount that overflowed (+infinity) is refused by the kind's limits, and an admitted
//   request has finite amounts within them; a refusal by the limits is RESOURCE_EXHAUSTED;
// - the request re-encodes: its deterministic bytes (what the store keeps and RunJob parses)
//   and its JSON parse back to the same message, and the bytes' copy gets the same verdict.
#include <google/protobuf/descriptor.h>
#include <google/protobuf/util/json_util.h>

#include <cctype>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <set>
#include <string>
#include <string_view>

#include "fuzz/fuzz_checks.h"
#include "jobs/job_cost.h"
#include "jobs/registry.h"
#include "jobs/request_bytes.h"
#include "server/rest_request.h"

#ifndef DRILLBIF_FUZZ_KIND
#error "DRILLBIF_FUZZ_KIND must name the job kind to fuzz"
#endif

namespace drillbif::fuzz {
namespace {

using google::protobuf::Descriptor;
using google::protobuf::FieldDescriptor;
using google::protobuf::Message;

// Every field name (proto and JSON spelling) of `type` and the messages below it.
void CollectFieldNames(const Descriptor* type, std::set<const Descriptor*>* seen,
                       std::set<std::string>* names) {
  if (!seen->insert(type).second) return;
  for (int i = 0; i < type->field_count(); ++i) {
    const FieldDescriptor* field = type->field(i);
    names->insert(field->name());
    names->insert(field->json_name());
    if (field->message_type() != nullptr) CollectFieldNames(field->message_type(), seen, names);
  }
}

bool IsWordChar(char c) { return std::isalnum(static_cast<unsigned char>(c)) || c == '_'; }

// Whether `message` names one of `names` as a whole word. A one-letter name (the model's
// parameters a, b, g and state components p, q, s, y) counts only where it is used as a name
// ("a must be", "q = ", "a:"), not as the English article.
bool NamesAField(const std::string& message, const std::set<std::string>& names) {
  for (const std::string& name : names) {
    for (size_t at = message.find(name); at != std::string::npos; at = message.find(name, at + 1)) {
      const size_t end = at + name.size();
      if ((at > 0 && IsWordChar(message[at - 1])) ||
          (end < message.size() && IsWordChar(message[end]))) {
        continue;
      }
      if (name.size() > 1) return true;
      const std::string_view after = std::string_view(message).substr(end);
      if (after.starts_with(" must") || after.starts_with(" =") || after.starts_with(":") ||
          after.starts_with(" in [")) {
        return true;
      }
    }
  }
  return false;
}

const jobs::JobKindSpec& Kind() {
  static const jobs::JobKindSpec* kind = jobs::FindKind(std::string_view(DRILLBIF_FUZZ_KIND));
  DRILLBIF_FUZZ_CHECK(kind != nullptr, "no kind " DRILLBIF_FUZZ_KIND);
  return *kind;
}

const std::set<std::string>& FieldNames() {
  static const std::set<std::string> names = [] {
    std::set<std::string> out;
    std::set<const Descriptor*> seen;
    CollectFieldNames(Kind().request_type, &seen, &out);
    return out;
  }();
  return names;
}

bool ParseJson(std::string_view json, Message* message) {
  return server::FromJson(json, message, "request").ok();
}

void CheckTerm(const jobs::CostTerm& term, const char* what) {
  DRILLBIF_FUZZ_CHECK(!std::isnan(term.amount) && term.amount >= 0,
                      std::string(what) + " = " + std::to_string(term.amount));
  DRILLBIF_FUZZ_CHECK(!term.driver.empty(), std::string(what) + " has no driver");
}

// The estimate of an accepted request, and its admission against the kind's default limits.
void CheckCost(const jobs::JobCost& cost) {
  CheckTerm(cost.seconds, "seconds");
  CheckTerm(cost.result_bytes, "result_bytes");
  CheckTerm(cost.memory_bytes, "memory_bytes");
  const jobs::KindLimits& limits = Kind().default_limits;
  const Status admitted = jobs::CheckCost(cost, limits, Kind().name.c_str());
  const bool finite = std::isfinite(cost.seconds.amount) &&
                      std::isfinite(cost.result_bytes.amount) &&
                      std::isfinite(cost.memory_bytes.amount);
  if (admitted.ok()) {
    DRILLBIF_FUZZ_CHECK(finite, "an overflowed estimate was admitted");
    // A limit of 0 is no limit.
    DRILLBIF_FUZZ_CHECK(
        (limits.max_seconds == 0 || cost.seconds.amount <= limits.max_seconds) &&
            (limits.max_result_bytes == 0 || cost.result_bytes.amount <= limits.max_result_bytes) &&
            (limits.max_memory_bytes == 0 || cost.memory_bytes.amount <= limits.max_memory_bytes),
        "admitted above a limit");
  } else {
    DRILLBIF_FUZZ_CHECK(admitted.code() == StatusCode::kResourceExhausted, admitted.ToString());
    DRILLBIF_FUZZ_CHECK(admitted.message().find(Kind().name) != std::string::npos,
                        admitted.ToString());
  }
}

bool SameCost(const jobs::JobCost& a, const jobs::JobCost& b) {
  return a.seconds.amount == b.seconds.amount && a.seconds.driver == b.seconds.driver &&
         a.result_bytes.amount == b.result_bytes.amount &&
         a.result_bytes.driver == b.result_bytes.driver &&
         a.memory_bytes.amount == b.memory_bytes.amount &&
         a.memory_bytes.driver == b.memory_bytes.driver;
}

// Re-encodings of `request` parse back to it, and the stored bytes get the same verdict.
void CheckReencoding(const Message& request, const StatusOr<jobs::JobCost>& verdict) {
  const std::string bytes = jobs::DeterministicBytes(request);
  std::unique_ptr<Message> stored = Kind().NewRequest();
  DRILLBIF_FUZZ_CHECK(stored->ParseFromString(bytes), request.ShortDebugString());
  DRILLBIF_FUZZ_CHECK(SameMessage(request, *stored), request.ShortDebugString());
  DRILLBIF_FUZZ_CHECK(jobs::DeterministicBytes(*stored) == bytes, request.ShortDebugString());
  const StatusOr<jobs::JobCost> again = jobs::CheckRequest(Kind(), *stored);
  DRILLBIF_FUZZ_CHECK(again.ok() == verdict.ok(), again.status().ToString());
  if (verdict.ok()) {
    DRILLBIF_FUZZ_CHECK(SameCost(*verdict, *again), request.ShortDebugString());
  } else {
    DRILLBIF_FUZZ_CHECK(again.status().message() == verdict.status().message(),
                        again.status().ToString());
  }

  std::string json;
  DRILLBIF_FUZZ_CHECK(google::protobuf::util::MessageToJsonString(request, &json).ok(),
                      request.ShortDebugString());
  std::unique_ptr<Message> from_json = Kind().NewRequest();
  DRILLBIF_FUZZ_CHECK(ParseJson(json, from_json.get()), json);
  DRILLBIF_FUZZ_CHECK(SameMessage(*KnownFieldsOf(request), *from_json), json);
}

}  // namespace
}  // namespace drillbif::fuzz

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  using namespace drillbif;  // NOLINT: the entry point is outside the namespace
  const std::string_view input(reinterpret_cast<const char*>(data), size);
  std::unique_ptr<google::protobuf::Message> request = fuzz::Kind().NewRequest();
  const bool parsed = input.starts_with('{')
                          ? fuzz::ParseJson(input, request.get())
                          : request->ParseFromArray(data, static_cast<int>(size));
  if (!parsed) return 0;

  const StatusOr<jobs::JobCost> cost = jobs::CheckRequest(fuzz::Kind(), *request);
  if (cost.ok()) {
    fuzz::CheckCost(*cost);
  } else {
    DRILLBIF_FUZZ_CHECK(cost.status().code() == StatusCode::kInvalidArgument,
                        cost.status().ToString());
    DRILLBIF_FUZZ_CHECK(fuzz::NamesAField(cost.status().message(), fuzz::FieldNames()),
                        "names no field: " + cost.status().ToString());
  }
  fuzz::CheckReencoding(*request, cost);
  return 0;
}
