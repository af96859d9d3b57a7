#include "jobs/job_cost.h"

#include <cmath>
#include <cstdio>
#include <string>

namespace drillbif::jobs {
namespace {

std::string Format(double value, const char* unit) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), value < 10 ? "%.1f %s" : "%.0f %s", value, unit);
  return buffer;
}

// RESOURCE_EXHAUSTED for one term over its limit.
Status OverLimit(const CostTerm& term, const std::string& estimate, const std::string& limit,
                 const char* limit_name, const char* kind) {
  return ResourceExhausted(term.driver + ": " + estimate + ", above the limit of " + limit + " (" +
                           limit_name + " of " + kind + " jobs)");
}

}  // namespace

Status KindLimits::Validate() const {
  if (!(std::isfinite(max_seconds) && max_seconds >= 0)) {
    return InvalidArgument("max_seconds: must be a finite number >= 0");
  }
  if (max_result_bytes < 0) return InvalidArgument("max_result_bytes: must be >= 0");
  if (max_memory_bytes < 0) return InvalidArgument("max_memory_bytes: must be >= 0");
  return Status::Ok();
}

std::string HumanBytes(double bytes) {
  if (!std::isfinite(bytes)) return "more bytes than can be counted";
  if (bytes >= 1e9) return Format(bytes / 1e9, "GB");
  if (bytes >= 1e6) return Format(bytes / 1e6, "MB");
  if (bytes >= 1e3) return Format(bytes / 1e3, "kB");
  return Format(bytes, "B");
}

std::string HumanSeconds(double seconds) {
  if (!std::isfinite(seconds)) return "longer than can be counted";
  if (seconds >= 86400 * 365) return Format(seconds / (86400 * 365), "years");
  if (seconds >= 86400) return Format(seconds / 86400, "days");
  if (seconds >= 3600) return Format(seconds / 3600, "h");
  if (seconds >= 60) return Format(seconds / 60, "min");
  if (seconds >= 1) return Format(seconds, "s");
  return Format(seconds * 1e3, "ms");
}

Status CheckCost(const JobCost& cost, const KindLimits& limits, const char* kind) {
  // `!(a <= b)` so that a NaN estimate (never expected) is refused too.
  if (limits.max_seconds > 0 && !(cost.seconds.amount <= limits.max_seconds)) {
    return OverLimit(cost.seconds, "about " + HumanSeconds(cost.seconds.amount) + " of computing",
                     HumanSeconds(limits.max_seconds), "max_seconds", kind);
  }
  if (limits.max_result_bytes > 0 &&
      !(cost.result_bytes.amount <= static_cast<double>(limits.max_result_bytes))) {
    return OverLimit(
        cost.result_bytes, "about " + HumanBytes(cost.result_bytes.amount) + " of results",
        HumanBytes(static_cast<double>(limits.max_result_bytes)), "max_result_bytes", kind);
  }
  if (limits.max_memory_bytes > 0 &&
      !(cost.memory_bytes.amount <= static_cast<double>(limits.max_memory_bytes))) {
    return OverLimit(
        cost.memory_bytes, "about " + HumanBytes(cost.memory_bytes.amount) + " of memory",
        HumanBytes(static_cast<double>(limits.max_memory_bytes)), "max_memory_bytes", kind);
  }
  return Status::Ok();
}

}  // namespace drillbif::jobs
