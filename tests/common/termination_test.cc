// The termination vocabulary (common/include/drillbif/common/termination.h): the names, the
// setters' status and message, the one-line report, and each engine summary's report with its
// counters. How each engine entry point ends on completion, cancellation and failure is asserted
// where that entry point is tested (tests/simulate, orbit, continuation, region: the cancel
// tests and the bad-input tests); an orbit solve that runs out of iterations, which only the
// vocabulary distinguishes, is here.
#include "drillbif/common/termination.h"

#include <gtest/gtest.h>

#include <string>

#include "drillbif/continuation/trace.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/orbit/periodic_orbit.h"
#include "drillbif/region/robust_optimum.h"
#include "drillbif/simulate/sweep.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

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

TEST(EngineSummaryBriefReport, SimulationCountsSegmentsEventsAndEvaluations) {
  SimulationSummary s;
  s.segments = 1200, s.events = 800, s.evaluations = 96000;
  s.Complete();
  EXPECT_EQ(s.BriefReport(), "completed: 1200 segments, 800 events, 96000 evaluations");
  s.Fail(InvalidArgument("sample_periods must be >= 1"));
  EXPECT_EQ(s.BriefReport(),
            "failed: 1200 segments, 800 events, 96000 evaluations; sample_periods must be >= 1");
}

TEST(EngineSummaryBriefReport, SweepCountsValuesPeriodsAndEvents) {
  SweepSummary s;
  s.values = 2000, s.periods = 1200000, s.events = 1;
  s.Cancel("sweep cancelled");
  EXPECT_EQ(s.BriefReport(), "cancelled: 2000 values, 1200000 periods, 1 event; sweep cancelled");
}

TEST(EngineSummaryBriefReport, OrbitSolveCountsIterationsAndTheResidual) {
  OrbitSolveSummary s;
  s.iterations = 4, s.residual = 1.234e-13;
  s.Complete();
  EXPECT_EQ(s.BriefReport(), "completed: 4 Newton iterations, residual 1.2e-13");
  s.iterations = 20, s.residual = 3e-4;
  s.NoConvergence("Newton did not converge in 20 iterations");
  EXPECT_EQ(s.BriefReport(),
            "no convergence: 20 Newton iterations, residual 0.0003; Newton did not converge in 20 "
            "iterations");
}

TEST(EngineSummaryBriefReport, ContinuationCountsStepsRejectedAndNewtonIterations) {
  ContinuationSummary s;
  s.steps = 785, s.rejected_steps = 2, s.newton_iterations = 2345;
  s.Complete();
  EXPECT_EQ(s.BriefReport(), "completed: 785 steps (2 rejected), 2345 Newton iterations");
  // Counters are 64-bit: a budget of steps beyond 2^31 would still be counted whole.
  s.newton_iterations = int64_t{3} << 31;
  s.Cancel("continuation cancelled");
  EXPECT_EQ(s.BriefReport(),
            "cancelled: 785 steps (2 rejected), 6442450944 Newton iterations; continuation "
            "cancelled");
}

TEST(EngineSummaryBriefReport, TraceCountsCurvesBranchPointsAndNotes) {
  TraceSummary s;
  s.curves = 436, s.branch_points = 5200;
  s.notes = {"a note", "another"};
  s.Complete();
  EXPECT_EQ(s.BriefReport(), "completed: 436 curves, 5200 branch points, 2 notes");
}

TEST(EngineSummaryBriefReport, RegionCountsSolvesNodesAndEdges) {
  RegionSummary s;
  s.solves = 4000, s.inside_nodes = 1200, s.switches = 3, s.boundary_edges = 80;
  s.untraced_edges = 2, s.seam_edges = 0;
  s.Complete("1200 of 10201 grid nodes inside");
  EXPECT_EQ(s.BriefReport(),
            "completed: 4000 Newton solves, 1200 inside nodes (3 switched), 80 boundary edges (2 "
            "untraced, 0 seams); 1200 of 10201 grid nodes inside");
}

TEST(EngineSummaryBriefReport, OptimumCountsCandidates) {
  OptimumSummary s;
  s.candidates = 1;
  s.Fail(NotFound("no grid node is that far from the boundary"));
  EXPECT_EQ(s.BriefReport(), "failed: 1 candidate; no grid node is that far from the boundary");
}

// An orbit solve that uses its iterations without meeting the tolerance is a result: kNoConvergence
// with an OK status, the last iterate returned in *orbit (not the guess), and the residual there.
TEST(OrbitSolveTermination, RunningOutOfIterationsIsNoConvergenceNotFailure) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const StatusOr<PeriodicOrbit> solved =
      testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  ASSERT_TRUE(solved.ok()) << solved.status().ToString();
  PeriodicOrbit orbit = *solved;
  // 1e-3 off the solution: one Newton step moves the orbit by ~1e-3, far above the step
  // tolerance 1e-11 (1 + |x|), so one iteration cannot converge.
  orbit.starts[0][DriftingOscillator::kY] += 1e-3;
  const PeriodicOrbit guess = orbit;
  OrbitSolverOptions one;
  one.max_iterations = 1;
  const OrbitSolveSummary s = SolveOrbit(model, prop, one, &orbit);
  EXPECT_EQ(s.termination, Termination::kNoConvergence) << s.BriefReport();
  EXPECT_TRUE(s.status.ok()) << s.status.ToString();
  EXPECT_EQ(s.iterations, 1);
  EXPECT_GT(s.residual, 0.0);
  EXPECT_NE(s.message.find("did not converge in 1 iterations"), std::string::npos) << s.message;
  EXPECT_NE(orbit.starts[0], guess.starts[0]);  // the last iterate, not the guess
  // Given more iterations the same guess converges (Newton from 1e-3 away: a few iterations).
  PeriodicOrbit again = guess;
  const OrbitSolveSummary converged = SolveOrbit(model, prop, {}, &again);
  EXPECT_EQ(converged.termination, Termination::kCompleted) << converged.BriefReport();
  EXPECT_GT(converged.iterations, 1);
}

// Invalid options fail the solve before any iteration, the message saying which.
TEST(OrbitSolveTermination, InvalidOptionsFailWithTheirMessage) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  PeriodicOrbit orbit = *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  OrbitSolverOptions none;
  none.max_iterations = 0;
  const OrbitSolveSummary s = SolveOrbit(model, prop, none, &orbit);
  EXPECT_EQ(s.termination, Termination::kFailed);
  EXPECT_EQ(s.status.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message.find("max_iterations"), std::string::npos) << s.message;
  EXPECT_EQ(s.iterations, 0);
}

}  // namespace
}  // namespace drillbif
