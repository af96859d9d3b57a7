// drillctl plot: the gnuplot script built for each result kind from small real runs (series,
// labels, titles, legend entries), JSON detection of the result kind, errors, and end to end
// (drillctl --local continue, then drillctl plot to a PNG; skipped without gnuplot).
#include "client/plot.h"

#include <fcntl.h>
#include <gmock/gmock.h>
#include <gtest/gtest.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "client/output.h"
#include "jobs/continue_job.h"
#include "jobs/optimum_job.h"
#include "jobs/simulate_job.h"
#include "jobs/sweep_job.h"
#include "jobs/trace_job.h"
#include "support/small_requests.h"
#include "support/temp_dir.h"

extern char** environ;

namespace drillbif::client {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

// The b-continuation at the reference over [0, 0.2]: every special point kind of the study
// (fold, period doubling, grazings, ROP maxima), ~0.1 s.
const v1::ContinueResult& ReferenceContinuation() {
  static const v1::ContinueResult result = [] {
    v1::ContinueRequest request;
    request.set_param(std::string("b"));
    request.set_min(0.0);
    request.set_max(0.2);
    StatusOr<v1::ContinueResult> r = jobs::RunContinue(request);
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    return r.ok() ? *r : v1::ContinueResult();
  }();
  return result;
}

std::string Script(const AnyResult& result, const PlotOptions& options = {}) {
  StatusOr<std::string> script = BuildPlotScript(result, options);
  EXPECT_TRUE(script.ok()) << script.status().ToString();
  return script.ok() ? *script : std::string();
}

TEST(BuildPlotScript, ContinueDrawsStableSolidUnstableDashedAndEachSpecialPointKind) {
  const v1::ContinueResult& r = ReferenceContinuation();
  ASSERT_GT(r.special_points_size(), 0);
  const std::string s = Script(r);
  EXPECT_THAT(s, HasSubstr("set terminal pngcairo"));
  EXPECT_THAT(s, HasSubstr("set output 'figure.png'"));
  EXPECT_THAT(s, HasSubstr("set xlabel 'b: static force (weight on bit) (dimensionless)'"));
  EXPECT_THAT(s, HasSubstr("set ylabel 'ROP: rate of progression (dimensionless)'"));
  EXPECT_THAT(s, HasSubstr("set title 'ROP along the periodic orbit''s branch in b'"));
  EXPECT_THAT(s, HasSubstr("a = 0.3, omega = 0.1, xi = 0.05, g = 0.02, phi0 = 0"));
  EXPECT_THAT(s, HasSubstr("$branch0_stable using 1:2 with lines lw 2.5 dashtype 1"));
  EXPECT_THAT(s, HasSubstr("$branch0_unstable using 1:2 with lines lw 1.5 dashtype 2"));
  EXPECT_THAT(s, HasSubstr("title 'unstable (dashed)'"));
  for (const v1::SpecialPoint& sp : r.special_points()) {
    const std::string name = v1::SpecialPoint::Kind_Name(sp.kind());
    EXPECT_THAT(s, HasSubstr("title '" + name + " (")) << name;
  }
  for (const char* kind : {"FOLD", "PERIOD_DOUBLING", "ROP_MAX", "GRAZING_L1"}) {
    EXPECT_THAT(s, HasSubstr(std::string("title '") + kind + " (")) << kind;
  }
  EXPECT_THAT(s, HasSubstr("set label 'PD' at 0.110011731"));  // the period doubling, labelled
  // Every branch point is in the data, once per run it belongs to (+1 at each stability change).
  EXPECT_THAT(s, HasSubstr("plot $branch0_stable"));
  EXPECT_THAT(s, HasSubstr("unset output"));
}

TEST(BuildPlotScript, ContinueMeasurePowerAndSvg) {
  PlotOptions options;
  options.measure = "power";
  options.output = "out/fig.SVG";
  const std::string s = Script(ReferenceContinuation(), options);
  EXPECT_THAT(s, HasSubstr("set terminal svg"));
  EXPECT_THAT(s, HasSubstr("set output 'out/fig.SVG'"));
  EXPECT_THAT(s, HasSubstr("set ylabel 'P: mean dissipated power (dimensionless)'"));
  options.measure = "speed";
  EXPECT_THAT(BuildPlotScript(ReferenceContinuation(), options).status().message(),
              HasSubstr("--measure must be rop or power"));
}

TEST(BuildPlotScript, RefusesOtherExtensions) {
  PlotOptions options;
  options.output = "figure.pdf";
  const StatusOr<std::string> s = BuildPlotScript(ReferenceContinuation(), options);
  ASSERT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(s.status().message(), HasSubstr(".png or .svg"));
}

TEST(BuildPlotScript, SweepDrawsUpAndDownAsDotsInTwoColours) {
  v1::SweepRequest request = testing::SmallSweep(0.1, 20);
  request.set_direction(v1::SweepRequest::BOTH);
  request.set_sample_periods(10);
  request.set_transient_periods(100);
  StatusOr<v1::SweepResult> r = jobs::RunSweep(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  PlotOptions options;
  options.param = "b";
  const std::string s = Script(*r, options);
  EXPECT_THAT(s, HasSubstr("$up using 1:2 with points pt 7"));
  EXPECT_THAT(s, HasSubstr("lc rgb '#1f4e9c' title 'sweep up (b increasing)'"));
  EXPECT_THAT(s, HasSubstr("$down using 1:2 with points pt 6"));
  EXPECT_THAT(s, HasSubstr("lc rgb '#d62728' title 'sweep down (b decreasing)'"));
  EXPECT_THAT(s, HasSubstr("set xlabel 'b: static force (weight on bit) (dimensionless)'"));
  EXPECT_THAT(s, HasSubstr("set ylabel 'y at the section s = 0: bit velocity (dimensionless)'"));
  EXPECT_THAT(s, HasSubstr("Brute-force bifurcation diagram in b (up and down sweeps, 20 values)"));
  // One row per Poincare sample: 20 values x 10 periods per direction.
  const std::string up = s.substr(s.find("$up << EOD\n"), s.find("EOD\n$down") - s.find("$up"));
  EXPECT_EQ(std::count(up.begin(), up.end(), '\n'), 1 + 20 * 10);
}

TEST(BuildPlotScript, TraceShadesTheRegionAndMarksCodim2PointsAndTheOptimum) {
  v1::TraceRequest request = testing::SmallBoxTrace();
  request.mutable_region()->add_grid(21);
  request.mutable_region()->add_grid(21);
  StatusOr<v1::TraceResult> trace = jobs::RunTrace(request);
  ASSERT_TRUE(trace.ok()) << trace.status().ToString();
  ASSERT_GT(trace->region().polygons_size(), 0);
  v1::OptimumRequest opt_request;
  *opt_request.mutable_trace() = testing::SmallBoxTrace();
  opt_request.add_margin(0.01);
  opt_request.add_margin(0.02);
  opt_request.add_grid(21);
  opt_request.add_grid(21);
  StatusOr<v1::OptimumResult> optimum = jobs::RunOptimum(opt_request);
  ASSERT_TRUE(optimum.ok()) << optimum.status().ToString();

  PlotOptions options;
  options.optimum = *optimum;
  const std::string s = Script(*trace, options);
  EXPECT_THAT(s, HasSubstr("set xlabel 'omega: forcing frequency (dimensionless)'"));
  EXPECT_THAT(s, HasSubstr("set ylabel 'a: forcing amplitude (dimensionless)'"));
  EXPECT_THAT(s, HasSubstr("Two-parameter bifurcation diagram in (omega, a) with the stability"));
  EXPECT_THAT(s, HasSubstr("with filledcurves closed fs transparent solid"));
  EXPECT_THAT(s, HasSubstr("title 'stable period-1: " + trace->region().signatures(0) + "'"));
  for (const char* kind : {"FOLD curve", "PERIOD_DOUBLING curve", "GRAZING curve"}) {
    EXPECT_THAT(s, HasSubstr(std::string("title '") + kind + "'")) << kind;
  }
  for (const v1::Codim2Point& p : trace->codim2_points()) {
    EXPECT_THAT(s, HasSubstr("title '" + p.kind() + "'")) << p.kind();
  }
  EXPECT_THAT(s, HasSubstr("$optimum using 1:2 with points"));
  EXPECT_THAT(s, HasSubstr("title 'optimum: ROP 1.437"));
  EXPECT_THAT(s, HasSubstr("set xrange [0.047:0.153]"));  // the box and 3% around it

  // Without an optimum, none is drawn; an optimum alone is refused with what to do instead.
  EXPECT_THAT(Script(*trace), Not(HasSubstr("$optimum")));
  const StatusOr<std::string> alone = BuildPlotScript(*optimum, {});
  ASSERT_FALSE(alone.ok());
  EXPECT_THAT(alone.status().message(), HasSubstr("--optimum"));
}

TEST(BuildPlotScript, SimulatePhasePortraitColouredByMode) {
  v1::SimulateRequest request;
  request.set_transient_periods(100);
  request.set_sample_periods(2);
  request.mutable_outputs()->set_poincare(true);
  request.mutable_outputs()->set_trajectory_dt(0.5);
  StatusOr<v1::SimulateResult> r = jobs::RunSimulate(request);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  const std::string s = Script(*r);
  EXPECT_THAT(s, HasSubstr("Phase portrait: trajectory"));
  EXPECT_THAT(s, HasSubstr("set xlabel 'p: bit position relative to the slider bottom"));
  EXPECT_THAT(s, HasSubstr("set ylabel 'y: bit velocity (dimensionless)'"));
  for (const char* mode : {"NC: no contact", "CwoP: contact without progression",
                           "CwP: contact with progression", "Poincare section s = 0"}) {
    EXPECT_THAT(s, HasSubstr(std::string("title '") + mode + "'")) << mode;
  }
}

// A map over b of three cells, finished out of order, the middle one without an optimum.
v1::OptimumMapResult ThreeCellMap() {
  v1::OptimumMapResult map;
  map.add_over("b");
  map.mutable_optimum()->mutable_trace()->add_trace_params("omega");
  map.mutable_optimum()->mutable_trace()->add_trace_params("a");
  for (int k : {2, 0, 1}) {
    v1::OptimumMapCell* c = map.add_cells();
    c->add_index(k);
    c->add_condition(0.125 + 0.0625 * k);  // exact in binary: the rows are compared as text
    c->mutable_optimum()->set_status(k == 1 ? "FAILED" : "COMPLETED");
    if (k == 1) continue;
    c->mutable_optimum()->set_rop(1.25 + k);
    c->mutable_optimum()->mutable_params()->set_omega(0.05);
    c->mutable_optimum()->mutable_params()->set_a(0.375 + 0.125 * k);
  }
  return map;
}

TEST(BuildPlotScript, MapDrawsTheOptimumAgainstItsConditionWithGaps) {
  const std::string s = Script(ThreeCellMap(), PlotOptions());
  EXPECT_THAT(s, HasSubstr("Robust ROP optimum over b (3 cells)"));
  // The cells in b order, the failed one a blank line (a gap) and a cross.
  EXPECT_THAT(s, HasSubstr("$found << EOD\n0.125 1.25 0.05 0.375\n\n0.25 3.25 0.05 0.625\nEOD"));
  EXPECT_THAT(s, HasSubstr("$missing << EOD\n0.1875 0\nEOD"));
  EXPECT_THAT(s, HasSubstr("$found using 1:3 axes x1y2 with linespoints pt 4 lc rgb '#d62728' "
                           "title 'omega'"));
  EXPECT_THAT(s, HasSubstr("title 'no optimum'"));
}

TEST(ParseResultJson, DetectsEachKindFromItsFields) {
  const StatusOr<std::string> json = ToJson(ReferenceContinuation(), true);
  ASSERT_TRUE(json.ok());
  StatusOr<AnyResult> parsed = ParseResultJson(*json);
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  EXPECT_EQ(ResultKindName(*parsed), "continue");

  v1::SweepResult sweep;
  sweep.add_up()->add_samples()->set_y(1.0);
  parsed = ParseResultJson(*ToJson(sweep, false));
  ASSERT_TRUE(parsed.ok());
  EXPECT_EQ(ResultKindName(*parsed), "sweep");

  v1::OptimumResult optimum;
  optimum.mutable_params()->set_a(0.4);
  parsed = ParseResultJson(*ToJson(optimum, false));
  ASSERT_TRUE(parsed.ok());
  EXPECT_EQ(ResultKindName(*parsed), "optimum");

  parsed = ParseResultJson(*ToJson(ThreeCellMap(), false));
  ASSERT_TRUE(parsed.ok()) << parsed.status().ToString();
  EXPECT_EQ(ResultKindName(*parsed), "optimum-map");

  v1::SimulateResult simulate;
  simulate.add_trajectory()->set_p(1.0);
  parsed = ParseResultJson(*ToJson(simulate, false));
  ASSERT_TRUE(parsed.ok());
  EXPECT_EQ(ResultKindName(*parsed), "simulate");

  EXPECT_THAT(ParseResultJson("{\"foo\": 1}").status().message(),
              HasSubstr("unknown result kind: its fields (foo)"));
  EXPECT_THAT(ParseResultJson("not json").status().message(), HasSubstr("not a JSON object"));
}

#ifdef DRILLCTL_BINARY
// Runs the binary with args; exit code, or -1.
int RunDrillctl(const std::vector<std::string>& args, const std::string& err_path) {
  std::vector<std::string> strings = {DRILLCTL_BINARY};
  strings.insert(strings.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& s : strings) argv.push_back(s.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, 2, err_path.c_str(), O_WRONLY | O_CREAT | O_TRUNC,
                                   0644);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, argv[0], &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  int status = 0;
  if (rc != 0 || waitpid(pid, &status, 0) != pid || !WIFEXITED(status)) return -1;
  return WEXITSTATUS(status);
}

bool GnuplotOnPath() {
  std::stringstream path(getenv("PATH") != nullptr ? getenv("PATH") : "");
  for (std::string dir; std::getline(path, dir, ':');) {
    if (access((dir + "/gnuplot").c_str(), X_OK) == 0) return true;
  }
  return false;
}

std::string Slurp(const std::string& path) {
  std::ifstream file(path, std::ios::binary);
  std::stringstream text;
  text << file.rdbuf();
  return text.str();
}

TEST(DrillctlPlot, ContinueToPngEndToEnd) {
  if (!GnuplotOnPath()) GTEST_SKIP() << "gnuplot is not installed (scripts/setup.sh installs it)";
  testing::TempDir dir("plot");
  ASSERT_FALSE(dir.path().empty());
  const std::string json = dir.path() + "/c.json", png = dir.path() + "/c.png",
                    err = dir.path() + "/err", gp = dir.path() + "/c.gp";
  ASSERT_EQ(RunDrillctl({"--local", "continue", "--param", "b", "--min", "0.14", "--max", "0.16",
                         "-o", json},
                        err),
            0)
      << Slurp(err);
  ASSERT_EQ(RunDrillctl({"plot", json, "-o", png, "--script", gp}, err), 0) << Slurp(err);
  const std::string bytes = Slurp(png);
  ASSERT_GT(bytes.size(), 1000u);
  EXPECT_EQ(bytes.substr(0, 8), std::string("\x89PNG\r\n\x1a\n", 8));
  EXPECT_THAT(Slurp(gp), HasSubstr("set output '" + png + "'"));

  // Errors exit 2 with a message.
  EXPECT_EQ(RunDrillctl({"plot", json, "-o", dir.path() + "/c.pdf"}, err), 2);
  EXPECT_THAT(Slurp(err), HasSubstr(".png or .svg"));
  EXPECT_EQ(RunDrillctl({"plot", dir.path() + "/missing.json", "-o", png}, err), 2);
  EXPECT_THAT(Slurp(err), HasSubstr("cannot read"));
}
#endif

}  // namespace
}  // namespace drillbif::client
