// What drillctl prints of each kind's result (client/output.h): the JSON names and forms
// (protobuf's JSON mapping with lowerCamelCase names, every field printed) and the CSV tables.
// Simulate, sweep and continue results come from small runs of the job runners; trace and optimum
// results are built by hand, since their printing does not depend on how they were computed.
#include "client/output.h"

#include <gmock/gmock.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <sstream>
#include <string>
#include <vector>

#include "jobs/continue_job.h"
#include "jobs/simulate_job.h"
#include "jobs/sweep_job.h"

namespace drillbif::client {
namespace {

using jobs::EffectiveOutputs;
using jobs::RunContinue;
using jobs::RunSimulate;
using jobs::RunSweep;
using ::testing::EndsWith;
using ::testing::HasSubstr;
using ::testing::StartsWith;

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  std::istringstream in(text);
  for (std::string line; std::getline(in, line);) lines.push_back(line);
  return lines;
}

// Five values of b around the reference point, short windows: ~50 ms.
v1::SweepRequest SmallSweep() {
  v1::SweepRequest request;
  request.set_param("b");
  request.set_min(0.145);
  request.set_max(0.155);
  request.set_steps(5);
  request.set_transient_periods(50);
  request.set_sample_periods(5);
  request.set_threads(1);
  return request;
}

// The reference orbit's signature: NC -impact-> CwoP -progression-> CwP -stick-> CwoP
// -separation-> NC -section.
constexpr const char* kReferenceSignature = "NC>Pi CwoP>l1 CwP>l1 CwoP>l2 NC|";

// The continuation of the reference orbit in b over [0.16, 0.17] through its fold (~60 ms), shared
// by the tests that read it.
const v1::ContinueResult& FoldResult() {
  static const v1::ContinueResult result = [] {
    v1::ContinueRequest request;
    request.mutable_params()->set_b(0.165);
    request.set_param("b");
    request.set_min(0.16);
    request.set_max(0.17);
    StatusOr<v1::ContinueResult> r = RunContinue(request);
    EXPECT_TRUE(r.ok()) << r.status().ToString();
    return r.ok() ? *r : v1::ContinueResult();
  }();
  return result;
}

TEST(Output, SimulateJsonHasCamelCaseMeasuresAndPoincareObjects) {
  v1::SimulateRequest request;
  request.set_sample_periods(2);
  const StatusOr<v1::SimulateResult> result = RunSimulate(request);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  const StatusOr<std::string> json = ToJson(*result, /*pretty=*/false);
  ASSERT_TRUE(json.ok()) << json.status().ToString();
  for (const char* key : {"\"rop\":", "\"power\":", "\"poincare\":[{",
                          "\"p\":", "\"y\":", "\"q\":", "\"mode\":\"NO_CONTACT\"",
                          "\"status\":\"COMPLETED\"", "\"eventsTotal\":", "\"wallSeconds\":"}) {
    EXPECT_THAT(*json, HasSubstr(key));
  }
}

TEST(Output, JsonPrintsZeroMeasuresAndDefaultFields) {
  v1::SimulateResult result;
  result.set_status("COMPLETED");
  result.set_rop(0.0);
  result.set_power(0.0);
  result.set_segments(0);
  const StatusOr<std::string> json = ToJson(result, /*pretty=*/false);
  ASSERT_TRUE(json.ok());
  EXPECT_THAT(*json, HasSubstr("\"rop\":0"));
  EXPECT_THAT(*json, HasSubstr("\"power\":0"));
  EXPECT_THAT(*json, HasSubstr("\"message\":\"\""));
  EXPECT_THAT(*json, HasSubstr("\"poincare\":[]"));
}

TEST(Output, SimulateCsvHasMeasureCommentsThenOneRowPerSample) {
  v1::SimulateRequest request;
  request.set_sample_periods(3);
  const StatusOr<v1::SimulateResult> result = RunSimulate(request);
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  const StatusOr<SimulateTable> table = CsvTableFor(EffectiveOutputs(request));
  ASSERT_TRUE(table.ok());
  EXPECT_EQ(*table, SimulateTable::kPoincare);
  const std::vector<std::string> lines = Lines(SimulateResultToCsv(*result, *table));
  ASSERT_EQ(lines.size(), 2u + 1u + 3u);
  EXPECT_THAT(lines[0], StartsWith("# rop=0.49887658"));
  EXPECT_THAT(lines[1], StartsWith("# power=0.0084749"));
  EXPECT_EQ(lines[2], "period,mode,p,y,q");
  EXPECT_THAT(lines[3], StartsWith("501,NO_CONTACT,-60.184375"));
}

TEST(Output, CsvRefusesTwoTables) {
  v1::SimulateRequest::Outputs outputs;
  outputs.set_poincare(true);
  outputs.set_events(true);
  EXPECT_FALSE(CsvTableFor(outputs).ok());
  outputs.set_poincare(false);
  const StatusOr<SimulateTable> events = CsvTableFor(outputs);
  ASSERT_TRUE(events.ok());
  EXPECT_EQ(*events, SimulateTable::kEvents);
}

TEST(Output, SweepCsvHasOneRowPerSample) {
  const StatusOr<v1::SweepResult> result = RunSweep(SmallSweep());
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  const std::vector<std::string> lines = Lines(SweepResultToCsv(*result));
  ASSERT_EQ(lines.size(), 1u + 5u * 5u);
  EXPECT_EQ(lines[0], "direction,value,period,p,y,q,start");
  EXPECT_THAT(lines[1], StartsWith("up,0.145,"));
  EXPECT_THAT(lines.back(), StartsWith("up,0.15"));  // 0.155 up to rounding
  // The first value's 5 rows started from the initial state, the others from the previous value.
  for (size_t k = 1; k < lines.size(); ++k) {
    EXPECT_THAT(lines[k], EndsWith(k <= 5 ? ",FROM_INITIAL_STATE" : ",FROM_PREVIOUS_VALUE")) << k;
  }
}

TEST(Output, SweepJsonSaysHowEachValueStarted) {
  const StatusOr<v1::SweepResult> result = RunSweep(SmallSweep());
  ASSERT_TRUE(result.ok()) << result.status().ToString();
  const StatusOr<std::string> json = ToJson(*result, false);
  ASSERT_TRUE(json.ok()) << json.status().ToString();
  EXPECT_THAT(*json, HasSubstr("\"start\":\"FROM_INITIAL_STATE\",\"transientPeriods\":\"50\""));
  EXPECT_THAT(*json, HasSubstr("\"start\":\"FROM_PREVIOUS_VALUE\""));
}

TEST(Output, ContinueJsonHasTheDocumentedNamesAndReadsBack) {
  const v1::ContinueResult& r = FoldResult();
  ASSERT_GT(r.points_size(), 0);
  const StatusOr<std::string> json = ToJson(r, false);
  ASSERT_TRUE(json.ok()) << json.status().ToString();
  for (const char* key :
       {"\"points\":[", "\"specialPoints\":[", "\"kind\":\"FOLD\"", "\"kind\":\"ROP_MAX\"",
        "\"rop\":", "\"power\":", "\"period\":", "\"multipliers\":[",
        "\"stable\":", "\"signature\":[\"NO_CONTACT\"", "\"signatureText\":\"NC>Pi CwoP>l1",
        "\"params\":{\"a\":0.3", "\"structuralZeros\":2", "\"newtonIterations\":"}) {
    EXPECT_THAT(*json, HasSubstr(key));
  }
  // '>' printed as itself rather than \u003e, and still the same message when read back.
  v1::ContinueResult back;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(*json, &back).ok());
  EXPECT_EQ(back.SerializeAsString(), r.SerializeAsString());
}

TEST(Output, ContinueCsvHasOneRowPerPointThenTheSpecialPoints) {
  const v1::ContinueResult& r = FoldResult();
  ASSERT_GT(r.points_size(), 0);
  const std::string csv = ContinueResultToCsv(r);
  std::vector<std::string> lines;
  for (size_t at = 0, end; at < csv.size(); at = end + 1) {
    end = csv.find('\n', at);
    lines.push_back(csv.substr(at, end - at));
  }
  ASSERT_EQ(lines.size(), 1u + r.points_size() + r.special_points_size());
  EXPECT_EQ(lines[0], "value,rop,power,period,stable,signature_text,mu_abs_max");
  EXPECT_THAT(lines[1], HasSubstr(std::string(",") + kReferenceSignature + ","));
  EXPECT_THAT(csv, HasSubstr("\n# FOLD value=0.16715"));
  EXPECT_THAT(csv, HasSubstr("\n# ROP_MAX value=0.16381"));
}

// A grazing's line ends with each side's stability after the existing fields; a side the engine
// did not compute is left out, and a change of stability across the grazing is named.
TEST(Output, ContinueCsvGrazingLineEndsWithEachSidesStability) {
  v1::ContinueResult r;
  r.set_status("COMPLETED");
  v1::SpecialPoint* both = r.add_special_points();
  both->set_kind(v1::SpecialPoint::GRAZING_L1);
  both->set_value(0.2048239);
  both->set_detail("A -> B");
  both->mutable_stability_before()->set_stable(true);
  both->mutable_stability_before()->set_max_abs(0.5);
  both->mutable_stability_after()->set_max_abs(2.0);
  both->set_stability_changes(true);
  v1::SpecialPoint* ends = r.add_special_points();
  ends->set_kind(v1::SpecialPoint::GRAZING_PI);
  ends->mutable_stability_before()->set_max_abs(1.5);
  const std::string csv = ContinueResultToCsv(r);
  EXPECT_THAT(csv, HasSubstr(" stable=false signature= detail=A -> B stable_before=true "
                             "mu_abs_max_before=0.5 stable_after=false mu_abs_max_after=2 "
                             "stability_changes=true bracket=0\n"));
  EXPECT_THAT(csv, HasSubstr("# GRAZING_PI value=0 rop=0 power=0 stable=false signature= "
                             "stable_before=false mu_abs_max_before=1.5 bracket=0\n"));
}

// A bifurcation next to a grazing ends its line with the grazing's kind, value and distance,
// after the existing fields; one that is not near a grazing has none of them.
TEST(Output, ContinueCsvLineOfABifurcationNextToAGrazingEndsWithTheGrazing) {
  v1::ContinueResult r;
  r.set_status("COMPLETED");
  v1::SpecialPoint* near = r.add_special_points();
  near->set_kind(v1::SpecialPoint::PERIOD_DOUBLING);
  near->set_value(0.25);
  near->mutable_near_grazing()->set_kind(v1::SpecialPoint::GRAZING_PI);
  near->mutable_near_grazing()->set_value(0.125);
  near->mutable_near_grazing()->set_distance(0.125);
  v1::SpecialPoint* isolated = r.add_special_points();
  isolated->set_kind(v1::SpecialPoint::FOLD);
  isolated->set_value(0.5);
  const std::string csv = ContinueResultToCsv(r);
  EXPECT_THAT(csv, HasSubstr("# PERIOD_DOUBLING value=0.25 rop=0 power=0 stable=false signature= "
                             "near_grazing=GRAZING_PI near_grazing_value=0.125 "
                             "near_grazing_distance=0.125 bracket=0\n"));
  EXPECT_THAT(csv, HasSubstr("# FOLD value=0.5 rop=0 power=0 stable=false signature= bracket=0\n"));
}

TEST(Output, TraceCsvHasOneCommentLinePerUnverifiedEndAndCodim2Point) {
  v1::TraceResult r;
  r.set_status("COMPLETED");
  v1::Curve* curve = r.add_curves();
  curve->set_kind("FOLD");
  curve->set_period(1);
  curve->add_points()->mutable_params()->set_a(0.3);
  curve->add_unverified_ends()->mutable_params()->set_a(0.31);
  curve->add_unverified_ends()->mutable_params()->set_a(0.29);
  v1::Codim2Point* point = r.add_codim2_points();
  point->set_kind("FLIP_GRAZING");
  point->mutable_params()->set_a(0.31142);
  const std::string csv = TraceResultToCsv(r);
  int unverified = 0;
  for (const std::string& line : Lines(csv)) {
    unverified += line.rfind("# UNVERIFIED_END curve=0", 0) == 0 ? 1 : 0;
  }
  EXPECT_EQ(unverified, 2) << csv;
  EXPECT_THAT(csv, HasSubstr("# FLIP_GRAZING curve=0 a=0.31142"));
}

TEST(Output, TraceJsonHasTheDocumentedNames) {
  v1::TraceResult r;
  r.add_curves()->set_kind("PERIOD_DOUBLING");
  r.add_codim2_points()->set_kind("FLIP_GRAZING");
  const StatusOr<std::string> json = ToJson(r, false);
  ASSERT_TRUE(json.ok()) << json.status().ToString();
  EXPECT_THAT(*json, HasSubstr("\"curves\":"));
  EXPECT_THAT(*json, HasSubstr("\"codim2Points\":"));
  EXPECT_THAT(*json, HasSubstr("\"kind\":\"FLIP_GRAZING\""));
  EXPECT_THAT(*json, HasSubstr("\"unverifiedEnds\":[]"));
}

// The row is written only when the result has params (a found optimum).
TEST(Output, OptimumCsvIsTheHeaderAndOneRowEndingWithTheAttractorCount) {
  v1::OptimumResult r;
  r.set_status("COMPLETED");
  r.mutable_params()->set_omega(0.1);
  r.set_rop(1.25);
  r.add_margin(0.15);
  r.add_margin(0.2);
  r.add_attractors()->set_reached_from(5);
  r.add_attractors()->set_reached_from(3);
  const std::vector<std::string> lines = Lines(OptimumResultToCsv(r));
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_THAT(lines[0], HasSubstr("a,b,omega,xi,g,phi0,rop,margin1,margin2"));
  EXPECT_THAT(lines[1], HasSubstr(",1.25,0.15,0.2,"));
  EXPECT_THAT(lines[1], testing::EndsWith(",2"));
}

}  // namespace
}  // namespace drillbif::client
