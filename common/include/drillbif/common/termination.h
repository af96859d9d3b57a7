// How a run ends: the one vocabulary every summary of the engine speaks (a simulation, a sweep,
// an orbit solve, a continuation, a curve, a trace, a stability region, an optimum search).
//
// Every run ends in one of four ways (Termination), says so in words (a message), carries a
// Status for the service to pass on, counts its work (each summary its own counters) and prints
// itself in one line (BriefReport):
//   completed: 785 steps (2 rejected), 2345 Newton iterations; increasing: reached max
// Non-convergence is a result, not a failure: a solver that used its iterations without meeting
// its tolerance reports kNoConvergence with an OK status and its last iterate (Ceres'
// Solver::Summary, Eigen's ComputationInfo).
#ifndef DRILLBIF_COMMON_TERMINATION_H_
#define DRILLBIF_COMMON_TERMINATION_H_

#include <cstdint>
#include <string>

#include "drillbif/common/status.h"

namespace drillbif {

// How a run ended.
enum class Termination {
  // Ran to its end: converged, or stopped where asked (a parameter bound, a step budget, a
  // special point in stop_at). The status is OK.
  kCompleted,
  // An iterative solver used its iterations without meeting its tolerance. A result, not a
  // failure: the status is OK and the run's output is its last iterate, which callers may reject.
  kNoConvergence,
  // The progress callback (or a sink) asked to stop: the output is what was computed until then.
  // The status is CANCELLED.
  kCancelled,
  // Could not run or go on (invalid options, a failed flow, a singular system): the status says
  // why; the output is what was computed before.
  kFailed,
};

// "COMPLETED", "NO_CONVERGENCE", "CANCELLED", "FAILED": the names of the service's results.
const char* TerminationName(Termination termination);

// The part every summary holds: how the run ended, why, and its one-line report. A summary
// derives from it, adds its counters (64-bit where they count work) and extends BriefReport
// with them.
struct RunSummary {
  // Failed until the run says otherwise: a summary nobody finished is not taken for a success.
  Termination termination = Termination::kFailed;
  // OK when completed or not converged, CANCELLED when cancelled, the error when failed.
  Status status;
  // How the run ended, in words ("reached max", "Newton did not converge in 20 iterations", the
  // error's message); may be empty when it completed with nothing to add.
  std::string message;

  bool completed() const { return termination == Termination::kCompleted; }
  bool cancelled() const { return termination == Termination::kCancelled; }
  bool failed() const { return termination == Termination::kFailed; }

  // Ends the run completed (status OK) with `why` as its message.
  void Complete(std::string why = {});
  // Ends the run not converged (status OK): `why` says what was not met.
  void NoConvergence(std::string why);
  // Ends the run cancelled: status CANCELLED with `why`, the message `why` too.
  void Cancel(std::string why);
  // Ends the run failed: `why` (not OK) as status, its message as the message.
  void Fail(Status why);

  // One line: "<termination>" and "; <message>" when there is one ("cancelled; cancelled at
  // period 7"). The summaries' own BriefReport puts their counters after the termination.
  std::string BriefReport() const;

 protected:
  // "<termination>: <counters>; <message>" (no ": " without counters, no "; " without a
  // message; the status's message stands in for an empty message). For the summaries'
  // BriefReport.
  std::string BriefReport(const std::string& counters) const;
};

// "1 step" or "3 steps": a counter and its noun for a BriefReport, the plural formed with an s.
std::string CountOf(int64_t count, const std::string& noun);

}  // namespace drillbif

#endif  // DRILLBIF_COMMON_TERMINATION_H_
