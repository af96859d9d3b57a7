// The termination vocabulary (common/include/drillbif/common/termination.h): the names, the
// setters' status and message, and the one-line report.
#include "drillbif/common/termination.h"

#include <gtest/gtest.h>

#include <string>

namespace drillbif {
namespace {

// A summary with one counter, as the engine's summaries extend RunSummary.
struct CountingSummary : RunSummary {
  int64_t steps = 0;
  std::string BriefReport() const { return RunSummary::BriefReport(CountOf(steps, "step")); }
};

TEST(Termination, NamesAreTheServiceResultNames) {
  EXPECT_STREQ(TerminationName(Termination::kCompleted), "COMPLETED");
  EXPECT_STREQ(TerminationName(Termination::kNoConvergence), "NO_CONVERGENCE");
  EXPECT_STREQ(TerminationName(Termination::kCancelled), "CANCELLED");
  EXPECT_STREQ(TerminationName(Termination::kFailed), "FAILED");
}

TEST(RunSummary, IsFailedUntilFinished) {
  const RunSummary summary;
  EXPECT_EQ(summary.termination, Termination::kFailed);
  EXPECT_TRUE(summary.failed());
  EXPECT_FALSE(summary.completed());
}

TEST(RunSummary, CompleteAndNoConvergenceKeepAnOkStatus) {
  RunSummary summary;
  summary.Complete("reached max");
  EXPECT_TRUE(summary.completed());
  EXPECT_TRUE(summary.status.ok());
  EXPECT_EQ(summary.message, "reached max");

  // Not converging is a result: the status stays OK, the message says what was not met.
  summary.NoConvergence("Newton did not converge in 20 iterations");
  EXPECT_EQ(summary.termination, Termination::kNoConvergence);
  EXPECT_TRUE(summary.status.ok());
  EXPECT_EQ(summary.message, "Newton did not converge in 20 iterations");
}

TEST(RunSummary, CancelSetsStatusCancelledWithItsMessage) {
  RunSummary summary;
  summary.Cancel("cancelled at period 7");
  EXPECT_TRUE(summary.cancelled());
  EXPECT_EQ(summary.status.code(), StatusCode::kCancelled);
  EXPECT_EQ(summary.status.message(), "cancelled at period 7");
  EXPECT_EQ(summary.message, "cancelled at period 7");
}

TEST(RunSummary, FailKeepsTheErrorAndItsMessage) {
  RunSummary summary;
  summary.Complete("reached max");
  summary.Fail(InvalidArgument("min_step must be > 0"));
  EXPECT_TRUE(summary.failed());
  EXPECT_EQ(summary.status.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(summary.message, "min_step must be > 0");
}

TEST(RunSummaryBriefReport, NamesTheTerminationThenTheMessage) {
  RunSummary summary;
  summary.Complete();
  EXPECT_EQ(summary.BriefReport(), "completed");
  summary.Complete("reached max");
  EXPECT_EQ(summary.BriefReport(), "completed; reached max");
  summary.NoConvergence("residual 1e-3");
  EXPECT_EQ(summary.BriefReport(), "no convergence; residual 1e-3");
  summary.Cancel("cancelled at period 7");
  EXPECT_EQ(summary.BriefReport(), "cancelled; cancelled at period 7");
  summary.Fail(Internal("singular Newton system"));
  EXPECT_EQ(summary.BriefReport(), "failed; singular Newton system");
}

TEST(RunSummaryBriefReport, StatusMessageStandsInForAnEmptyMessage) {
  RunSummary summary;
  summary.status = Cancelled("stopped by the sink");
  summary.termination = Termination::kCancelled;
  EXPECT_EQ(summary.BriefReport(), "cancelled; stopped by the sink");
}

TEST(RunSummaryBriefReport, PutsASummarysCountersAfterTheTermination) {
  CountingSummary summary;
  summary.steps = 785;
  summary.Complete();
  EXPECT_EQ(summary.BriefReport(), "completed: 785 steps");
  summary.steps = 1;
  summary.Cancel("cancelled");
  EXPECT_EQ(summary.BriefReport(), "cancelled: 1 step; cancelled");
}

TEST(CountOf, FormsThePluralWithAnS) {
  EXPECT_EQ(CountOf(0, "step"), "0 steps");
  EXPECT_EQ(CountOf(1, "step"), "1 step");
  EXPECT_EQ(CountOf(2345, "Newton iteration"), "2345 Newton iterations");
  // Counters are 64-bit: work counted past 2^31 prints whole.
  EXPECT_EQ(CountOf(int64_t{1} << 40, "segment"), "1099511627776 segments");
}

}  // namespace
}  // namespace drillbif
