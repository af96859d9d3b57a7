#include "drillbif/common/termination.h"

#include <string>
#include <utility>

namespace drillbif {
namespace {

// The termination as the report's first word(s): lower case, so that it reads as a sentence.
const char* ReportName(Termination termination) {
  switch (termination) {
    case Termination::kCompleted:
      return "completed";
    case Termination::kNoConvergence:
      return "no convergence";
    case Termination::kCancelled:
      return "cancelled";
    case Termination::kFailed:
      return "failed";
  }
  return "?";
}

}  // namespace

const char* TerminationName(Termination termination) {
  switch (termination) {
    case Termination::kCompleted:
      return "COMPLETED";
    case Termination::kNoConvergence:
      return "NO_CONVERGENCE";
    case Termination::kCancelled:
      return "CANCELLED";
    case Termination::kFailed:
      return "FAILED";
  }
  return "?";
}

void RunSummary::Complete(std::string why) {
  termination = Termination::kCompleted;
  status = Status::Ok();
  message = std::move(why);
}

void RunSummary::NoConvergence(std::string why) {
  termination = Termination::kNoConvergence;
  status = Status::Ok();
  message = std::move(why);
}

void RunSummary::Cancel(std::string why) {
  termination = Termination::kCancelled;
  status = Cancelled(why);
  message = std::move(why);
}

void RunSummary::Fail(Status why) {
  termination = Termination::kFailed;
  message = why.message();
  status = std::move(why);
}

std::string RunSummary::BriefReport() const { return BriefReport(std::string()); }

std::string RunSummary::BriefReport(const std::string& counters) const {
  std::string out = ReportName(termination);
  if (!counters.empty()) out += ": " + counters;
  const std::string& why = message.empty() ? status.message() : message;
  if (!why.empty()) out += "; " + why;
  return out;
}

std::string CountOf(int64_t count, const std::string& noun) {
  return std::to_string(count) + " " + noun + (count == 1 ? "" : "s");
}

}  // namespace drillbif
