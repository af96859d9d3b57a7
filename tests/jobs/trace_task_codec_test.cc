// The codec of a trace's tasks and results (jobs/trace_task_codec.h): the round trip is exact on
// real engine data (curves of the reference model with their codimension-2 points) and on values
// with every field set to a value that is neither the engine's default nor the proto default,
// and malformed bytes are INVALID_ARGUMENT naming the field, never a crash.
#include "jobs/trace_task_codec.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <bit>
#include <cmath>
#include <complex>
#include <cstdint>
#include <cstdio>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

#include "drillbif/continuation/curve.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/v1/trace.pb.h"
#include "drillbif/v1/trace_task.pb.h"
#include "jobs/request_bytes.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"
#include "support/same_bits.h"

namespace drillbif::jobs {
namespace {

// ---------------------------------------------------------------------------------------------
// Deep equality: every field of two values, doubles by their bits (NaN equal to itself when its
// bits are, -0.0 different from 0.0), matrices by dimensions and bits, strings byte for byte,
// statuses by code and message. Differences are the paths of the fields that differ.

using ::testing::HasSubstr;
using Differences = std::vector<std::string>;

void Compare(const std::string& path, double a, double b, Differences* d) {
  if (!testing::SameBits(a, b)) d->push_back(path);
}
template <typename T>
requires(std::is_integral_v<T> || std::is_enum_v<T>) void Compare(const std::string& path, T a, T b,
                                                                  Differences* d) {
  if (a != b) d->push_back(path);
}
void Compare(const std::string& path, const std::string& a, const std::string& b, Differences* d) {
  if (a != b) d->push_back(path);
}
void Compare(const std::string& path, const Status& a, const Status& b, Differences* d) {
  Compare(path + ".code", a.code(), b.code(), d);
  Compare(path + ".message", a.message(), b.message(), d);
}
void Compare(const std::string& path, const std::complex<double>& a, const std::complex<double>& b,
             Differences* d) {
  Compare(path + ".re", a.real(), b.real(), d);
  Compare(path + ".im", a.imag(), b.imag(), d);
}
void Compare(const std::string& path, const SegmentSpec& a, const SegmentSpec& b, Differences* d);
void Compare(const std::string& path, const Signature& a, const Signature& b, Differences* d);
void Compare(const std::string& path, const PeriodicOrbit& a, const PeriodicOrbit& b,
             Differences* d);
void Compare(const std::string& path, const Stability& a, const Stability& b, Differences* d);
void Compare(const std::string& path, const Admissibility& a, const Admissibility& b,
             Differences* d);
void Compare(const std::string& path, const ContinuationSummary& a, const ContinuationSummary& b,
             Differences* d);
void Compare(const std::string& path, const ContinuationPoint& a, const ContinuationPoint& b,
             Differences* d);
void Compare(const std::string& path, const SideStability& a, const SideStability& b,
             Differences* d);
void Compare(const std::string& path, const NearGrazing& a, const NearGrazing& b, Differences* d);
void Compare(const std::string& path, const SpecialPoint& a, const SpecialPoint& b, Differences* d);
void Compare(const std::string& path, const CurvePoint& a, const CurvePoint& b, Differences* d);
void Compare(const std::string& path, const Codim2Point& a, const Codim2Point& b, Differences* d);
void Compare(const std::string& path, const CurveResult& a, const CurveResult& b, Differences* d);
void Compare(const std::string& path, const SwitchCandidate& a, const SwitchCandidate& b,
             Differences* d);
void Compare(const std::string& path, const CandidateRun& a, const CandidateRun& b, Differences* d);
void Compare(const std::string& path, const CurveTask& a, const CurveTask& b, Differences* d);
void Compare(const std::string& path, const CandidatesTask& a, const CandidatesTask& b,
             Differences* d);
void Compare(const std::string& path, const CandidateTask& a, const CandidateTask& b,
             Differences* d);

// StateVector, Params and Eigen::MatrixXd.
template <int Rows, int Cols, int Options, int MaxRows, int MaxCols>
void Compare(const std::string& path,
             const Eigen::Matrix<double, Rows, Cols, Options, MaxRows, MaxCols>& a,
             const Eigen::Matrix<double, Rows, Cols, Options, MaxRows, MaxCols>& b,
             Differences* d) {
  if (a.rows() != b.rows() || a.cols() != b.cols()) {
    d->push_back(path + " (dimensions)");
    return;
  }
  for (Eigen::Index j = 0; j < a.cols(); ++j) {
    for (Eigen::Index i = 0; i < a.rows(); ++i) {
      Compare(path + "(" + std::to_string(i) + "," + std::to_string(j) + ")", a(i, j), b(i, j), d);
    }
  }
}
template <typename A, typename B>
void Compare(const std::string& path, const std::pair<A, B>& a, const std::pair<A, B>& b,
             Differences* d) {
  Compare(path + ".first", a.first, b.first, d);
  Compare(path + ".second", a.second, b.second, d);
}
template <typename T>
void Compare(const std::string& path, const std::vector<T>& a, const std::vector<T>& b,
             Differences* d) {
  if (a.size() != b.size()) {
    d->push_back(path + " (size)");
    return;
  }
  for (size_t i = 0; i < a.size(); ++i) {
    Compare(path + "[" + std::to_string(i) + "]", a[i], b[i], d);
  }
}
template <typename... T>
void Compare(const std::string& path, const std::variant<T...>& a, const std::variant<T...>& b,
             Differences* d) {
  if (a.index() != b.index()) {
    d->push_back(path + " (alternative)");
    return;
  }
  std::visit([&](const auto& x) { Compare(path, x, std::get<std::decay_t<decltype(x)>>(b), d); },
             a);
}

void Compare(const std::string& path, const SegmentSpec& a, const SegmentSpec& b, Differences* d) {
  Compare(path + ".mode", a.mode, b.mode, d);
  Compare(path + ".guard", a.guard, b.guard, d);
  Compare(path + ".tangent", a.tangent, b.tangent, d);
}
void Compare(const std::string& path, const Signature& a, const Signature& b, Differences* d) {
  Compare(path + ".periods", a.periods, b.periods, d);
  Compare(path + ".segments", a.segments, b.segments, d);
}
void Compare(const std::string& path, const PeriodicOrbit& a, const PeriodicOrbit& b,
             Differences* d) {
  Compare(path + ".signature", a.signature, b.signature, d);
  Compare(path + ".params", a.params, b.params, d);
  Compare(path + ".starts", a.starts, b.starts, d);
  Compare(path + ".durations", a.durations, b.durations, d);
}
void Compare(const std::string& path, const Stability& a, const Stability& b, Differences* d) {
  Compare(path + ".multipliers", a.multipliers, b.multipliers, d);
  Compare(path + ".structural_zeros", a.structural_zeros, b.structural_zeros, d);
  Compare(path + ".structural_ones", a.structural_ones, b.structural_ones, d);
  Compare(path + ".stable", a.stable, b.stable, d);
  Compare(path + ".monodromy", a.monodromy, b.monodromy, d);
}
void Compare(const std::string& path, const Admissibility& a, const Admissibility& b,
             Differences* d) {
  Compare(path + ".admissible", a.admissible, b.admissible, d);
  Compare(path + ".segment", a.segment, b.segment, d);
  Compare(path + ".guard", a.guard, b.guard, d);
  Compare(path + ".at_start", a.at_start, b.at_start, d);
  Compare(path + ".time", a.time, b.time, d);
  Compare(path + ".message", a.message, b.message, d);
}
void Compare(const std::string& path, const ContinuationSummary& a, const ContinuationSummary& b,
             Differences* d) {
  Compare(path + ".termination", a.termination, b.termination, d);
  Compare(path + ".status", a.status, b.status, d);
  Compare(path + ".message", a.message, b.message, d);
  Compare(path + ".steps", a.steps, b.steps, d);
  Compare(path + ".rejected_steps", a.rejected_steps, b.rejected_steps, d);
  Compare(path + ".newton_iterations", a.newton_iterations, b.newton_iterations, d);
}
void Compare(const std::string& path, const ContinuationPoint& a, const ContinuationPoint& b,
             Differences* d) {
  Compare(path + ".value", a.value, b.value, d);
  Compare(path + ".orbit", a.orbit, b.orbit, d);
  Compare(path + ".measures", a.measures, b.measures, d);
  Compare(path + ".stability", a.stability, b.stability, d);
  Compare(path + ".period", a.period, b.period, d);
}
void Compare(const std::string& path, const SideStability& a, const SideStability& b,
             Differences* d) {
  Compare(path + ".known", a.known, b.known, d);
  Compare(path + ".stable", a.stable, b.stable, d);
  Compare(path + ".max_modulus", a.max_modulus, b.max_modulus, d);
}
void Compare(const std::string& path, const NearGrazing& a, const NearGrazing& b, Differences* d) {
  Compare(path + ".near", a.near, b.near, d);
  Compare(path + ".kind", a.kind, b.kind, d);
  Compare(path + ".value", a.value, b.value, d);
  Compare(path + ".distance", a.distance, b.distance, d);
}
void Compare(const std::string& path, const SpecialPoint& a, const SpecialPoint& b,
             Differences* d) {
  Compare(path + ".kind", a.kind, b.kind, d);
  Compare(path + ".point", a.point, b.point, d);
  Compare(path + ".detail", a.detail, b.detail, d);
  Compare(path + ".before", a.before, b.before, d);
  Compare(path + ".after", a.after, b.after, d);
  Compare(path + ".near_grazing", a.near_grazing, b.near_grazing, d);
}
void Compare(const std::string& path, const CurvePoint& a, const CurvePoint& b, Differences* d) {
  Compare(path + ".value1", a.value1, b.value1, d);
  Compare(path + ".value2", a.value2, b.value2, d);
  Compare(path + ".orbit", a.orbit, b.orbit, d);
  Compare(path + ".measures", a.measures, b.measures, d);
  Compare(path + ".stability", a.stability, b.stability, d);
}
void Compare(const std::string& path, const Codim2Point& a, const Codim2Point& b, Differences* d) {
  Compare(path + ".kind", a.kind, b.kind, d);
  Compare(path + ".point", a.point, b.point, d);
  Compare(path + ".detail", a.detail, b.detail, d);
  Compare(path + ".bracket", a.bracket, b.bracket, d);
  Compare(path + ".violation", a.violation, b.violation, d);
  Compare(path + ".same_as_curve", a.same_as_curve, b.same_as_curve, d);
  Compare(path + ".same_as_index", a.same_as_index, b.same_as_index, d);
}
void Compare(const std::string& path, const CurveResult& a, const CurveResult& b, Differences* d) {
  Compare(path + ".kind", a.kind, b.kind, d);
  Compare(path + ".points", a.points, b.points, d);
  Compare(path + ".crossings", a.crossings, b.crossings, d);
  Compare(path + ".codim2", a.codim2, b.codim2, d);
  Compare(path + ".unverified_ends", a.unverified_ends, b.unverified_ends, d);
  Compare(path + ".summary", a.summary, b.summary, d);
}
void Compare(const std::string& path, const SwitchCandidate& a, const SwitchCandidate& b,
             Differences* d) {
  Compare(path + ".orbit.status", a.orbit.status(), b.orbit.status(), d);
  if (a.orbit.ok() && b.orbit.ok()) Compare(path + ".orbit", *a.orbit, *b.orbit, d);
  Compare(path + ".seed_kind", a.seed_kind, b.seed_kind, d);
  Compare(path + ".kind", a.kind, b.kind, d);
  Compare(path + ".step_off", a.step_off, b.step_off, d);
}
void Compare(const std::string& path, const CandidateRun& a, const CandidateRun& b,
             Differences* d) {
  Compare(path + ".deferred", a.deferred, b.deferred, d);
  Compare(path + ".stopped", a.stopped, b.stopped, d);
  Compare(path + ".tries", a.tries, b.tries, d);
}
void Compare(const std::string& path, const CurveTask& a, const CurveTask& b, Differences* d) {
  Compare(path + ".start", a.start, b.start, d);
  Compare(path + ".axis", a.axis, b.axis, d);
}
void Compare(const std::string& path, const CandidatesTask& a, const CandidatesTask& b,
             Differences* d) {
  Compare(path + ".from_kind", a.from_kind, b.from_kind, d);
  Compare(path + ".point", a.point, b.point, d);
}
void Compare(const std::string& path, const CandidateTask& a, const CandidateTask& b,
             Differences* d) {
  Compare(path + ".point", a.point, b.point, d);
  Compare(path + ".candidate", a.candidate, b.candidate, d);
  Compare(path + ".last_resort", a.last_resort, b.last_resort, d);
}

template <typename T>
Differences DifferencesOf(const T& a, const T& b) {
  Differences d;
  Compare("value", a, b, &d);
  return d;
}

std::string Joined(const Differences& d) {
  std::string s;
  for (const std::string& path : d) s += path + "\n";
  return s;
}

// ---------------------------------------------------------------------------------------------
// Values with every field set: numbers distinct, nonzero and unlike the engine's defaults,
// strings with a NUL and a byte that is not UTF-8, enums neither 0 nor the engine's default, and
// every bool `flag` (a value is filled once with each, so a dropped bool shows either way).

// A NaN with a payload: its bits must survive, not only its NaN-ness.
const double kPayloadNaN = std::bit_cast<double>(uint64_t{0x7ff80000deadbeef});

class Filler {
 public:
  explicit Filler(bool flag) : flag_(flag) {}

  double Real() { return 0.1 + 1.37 * static_cast<double>(++n_); }
  int Int() { return 2 + static_cast<int>(++n_); }
  int64_t Count() { return (int64_t{1} << 40) + ++n_; }  // past 32 bits
  std::string Text() { return std::string("text\0\xff ", 7) + std::to_string(++n_); }

  Signature MakeSignature() {
    Signature s;
    s.periods = Int();
    s.segments = {{Int(), Int(), flag_}, {Int(), -1, !flag_}};
    return s;
  }
  PeriodicOrbit Orbit() {
    PeriodicOrbit o;
    o.signature = MakeSignature();
    o.params.resize(6);
    for (Eigen::Index i = 0; i < o.params.size(); ++i) o.params[i] = Real();
    for (int k = 0; k < 2; ++k) {
      StateVector x(4);
      for (Eigen::Index i = 0; i < x.size(); ++i) x[i] = Real();
      o.starts.push_back(x);
    }
    o.durations = {Real(), Real()};
    return o;
  }
  Stability MakeStability() {
    Stability s;
    s.multipliers = {{Real(), Real()}, {Real(), -Real()}};
    s.structural_zeros = Int();
    s.structural_ones = Int();
    s.stable = flag_;
    s.monodromy.resize(3, 2);  // not square: rows and columns must not be swapped
    for (Eigen::Index i = 0; i < s.monodromy.size(); ++i) s.monodromy.data()[i] = Real();
    return s;
  }
  // Measures with the doubles that are easiest to lose: a NaN payload, -0.0, infinity and a
  // subnormal.
  std::vector<double> Measures() {
    return {Real(), kPayloadNaN, -0.0, -std::numeric_limits<double>::infinity(),
            std::numeric_limits<double>::denorm_min()};
  }
  ContinuationPoint MakeContinuationPoint() {
    return ContinuationPoint{Real(), Orbit(), Measures(), MakeStability(), Real()};
  }
  SideStability MakeSideStability() { return SideStability{flag_, !flag_, Real()}; }
  SpecialPoint MakeSpecialPoint() {
    SpecialPoint s;
    s.kind = SpecialPointKind::kNeimarkSacker;
    s.point = MakeContinuationPoint();
    s.detail = Text();
    s.before = MakeSideStability();
    s.after = MakeSideStability();
    s.near_grazing = NearGrazing{flag_, SpecialPointKind::kGrazingL2, Real(), Real()};
    return s;
  }
  CurvePoint MakeCurvePoint() {
    return CurvePoint{Real(), Real(), Orbit(), Measures(), MakeStability()};
  }
  Codim2Point MakeCodim2Point() {
    Codim2Point q;
    q.kind = Codim2Kind::kResonance13;
    q.point = MakeCurvePoint();
    q.detail = Text();
    q.bracket = Real();
    q.violation = Admissibility{flag_, Int(), Int(), !flag_, Real(), Text()};
    q.same_as_curve = Int();
    q.same_as_index = Int();
    return q;
  }
  ContinuationSummary Summary() {
    ContinuationSummary s;
    s.termination = Termination::kNoConvergence;
    s.status = Status(StatusCode::kAborted, Text());
    s.message = Text();
    s.steps = Count();
    s.rejected_steps = Count();
    s.newton_iterations = Count();
    return s;
  }
  CurveResult MakeCurveResult() {
    CurveResult r;
    r.kind = CurveKind::kGrazing;
    r.points = {MakeCurvePoint(), MakeCurvePoint()};
    r.crossings = {MakeCurvePoint()};
    r.codim2 = {MakeCodim2Point()};
    r.unverified_ends = {MakeCodim2Point()};
    r.summary = Summary();
    return r;
  }
  SwitchCandidate Candidate() {
    SwitchCandidate c;
    c.orbit = Orbit();
    c.seed_kind = SpecialPointKind::kGrazingPi;
    c.kind = CurveKind::kNeimarkSacker;
    c.step_off = Int();
    return c;
  }
  CandidateRun Run() {
    CandidateRun r;
    r.deferred = flag_;
    r.stopped = !flag_;
    r.tries = {{MakeSpecialPoint(), MakeCurveResult()}, {MakeSpecialPoint(), MakeCurveResult()}};
    return r;
  }
  CurveTask Curve() { return CurveTask{MakeSpecialPoint(), Int()}; }
  CandidatesTask Candidates() {
    return CandidatesTask{CurveKind::kPeriodDoubling, MakeCodim2Point()};
  }
  CandidateTask CandidateRunTask() { return CandidateTask{MakeCodim2Point(), Candidate(), flag_}; }

 private:
  bool flag_;
  int64_t n_ = 0;
};

// ---------------------------------------------------------------------------------------------
// Round trips.

// A parent request as the service stores it: the worker must get these bytes back unchanged.
std::string ParentRequest() {
  v1::TraceRequest request;
  request.add_trace_params("omega");
  request.add_trace_params("a");
  request.add_min(0.05);
  request.add_min(0.01);
  request.add_max(2.0);
  request.add_max(8.0);
  request.set_max_period(2);
  return request.SerializeAsString();
}

// The task decoded from its encoding equals it in every field, the parent's bytes come back
// unchanged, and encoding the decoded task gives the same bytes.
void ExpectTaskRoundTrip(const TraceTask& task) {
  const std::string parent = ParentRequest();
  const std::string bytes = EncodeTraceTaskRequest(parent, task);
  const StatusOr<DecodedTraceTask> decoded = DecodeTraceTaskRequest(bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_EQ(decoded->trace_request, parent);
  const Differences d = DifferencesOf(task, decoded->task);
  EXPECT_TRUE(d.empty()) << "fields that differ:\n" << Joined(d);
  EXPECT_EQ(EncodeTraceTaskRequest(decoded->trace_request, decoded->task), bytes);
}

void ExpectResultRoundTrip(const TraceTaskResult& result) {
  const std::string bytes = EncodeTraceTaskResult(result);
  const StatusOr<TraceTaskResult> decoded = DecodeTraceTaskResult(bytes);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  const Differences d = DifferencesOf(result, *decoded);
  EXPECT_TRUE(d.empty()) << "fields that differ:\n" << Joined(d);
  EXPECT_EQ(EncodeTraceTaskResult(*decoded), bytes);
}

TEST(TraceTaskCodecTest, FilledTasksRoundTripExactly) {
  for (bool flag : {false, true}) {
    SCOPED_TRACE(flag ? "bools true" : "bools false");
    Filler fill(flag);
    ExpectTaskRoundTrip(fill.Curve());
    ExpectTaskRoundTrip(fill.Candidates());
    ExpectTaskRoundTrip(fill.CandidateRunTask());
  }
}

TEST(TraceTaskCodecTest, FilledResultsRoundTripExactly) {
  for (bool flag : {false, true}) {
    SCOPED_TRACE(flag ? "bools true" : "bools false");
    Filler fill(flag);
    ExpectResultRoundTrip(fill.MakeCurveResult());
    SwitchCandidate failed = fill.Candidate();
    failed.orbit = Status(StatusCode::kFailedPrecondition, fill.Text());
    ExpectResultRoundTrip(std::vector<SwitchCandidate>{fill.Candidate(), failed});
    ExpectResultRoundTrip(std::vector<SwitchCandidate>{});
    ExpectResultRoundTrip(fill.Run());
  }
}

// A batch of every kind of task, and of every kind of result, comes back task for task and
// result for result, in order; encoding the decoded batch gives the same bytes.
TEST(TraceTaskCodecTest, BatchesRoundTripExactlyInOrder) {
  Filler fill(true);
  const std::vector<TraceTask> tasks = {fill.Curve(), fill.Candidates(), fill.CandidateRunTask()};
  const std::string parent = ParentRequest();
  const std::string bytes = EncodeTraceTaskBatch(parent, {&tasks[0], &tasks[1], &tasks[2]});
  v1::TraceTaskBatch batch;
  ASSERT_TRUE(batch.ParseFromString(bytes));
  const StatusOr<DecodedTraceTaskBatch> decoded = DecodeTraceTaskBatch(batch);
  ASSERT_TRUE(decoded.ok()) << decoded.status().ToString();
  EXPECT_EQ(decoded->trace_request, parent);
  ASSERT_EQ(decoded->tasks.size(), tasks.size());
  for (size_t i = 0; i < tasks.size(); ++i) {
    const Differences d = DifferencesOf(tasks[i], decoded->tasks[i]);
    EXPECT_TRUE(d.empty()) << "task " << i << ", fields that differ:\n" << Joined(d);
  }
  EXPECT_EQ(
      EncodeTraceTaskBatch(parent, {&decoded->tasks[0], &decoded->tasks[1], &decoded->tasks[2]}),
      bytes);
  const std::vector<TraceTaskResult> results = {
      fill.MakeCurveResult(), std::vector<SwitchCandidate>{fill.Candidate()}, fill.Run()};
  const std::string result_bytes = DeterministicBytes(TraceTaskBatchResponseOf(results));
  const StatusOr<std::vector<TraceTaskResult>> back = DecodeTraceTaskBatchResponse(result_bytes);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  ASSERT_EQ(back->size(), results.size());
  for (size_t i = 0; i < results.size(); ++i) {
    const Differences d = DifferencesOf(results[i], (*back)[i]);
    EXPECT_TRUE(d.empty()) << "result " << i << ", fields that differ:\n" << Joined(d);
  }
  EXPECT_EQ(DeterministicBytes(TraceTaskBatchResponseOf(*back)), result_bytes);
}

TEST(TraceTaskCodecTest, MalformedBatchesNameTheTaskOrResult) {
  Filler fill(false);
  const TraceTask task = fill.Curve();
  v1::TraceTaskBatch batch;
  ASSERT_TRUE(batch.ParseFromString(EncodeTraceTaskBatch(ParentRequest(), {&task, &task})));
  batch.mutable_tasks(1)->clear_curve();
  const StatusOr<DecodedTraceTaskBatch> unset = DecodeTraceTaskBatch(batch);
  EXPECT_EQ(unset.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(unset.status().message(), HasSubstr("TraceTaskBatch.tasks[1].task: not set"));
  batch.set_trace_request("\xff\xff");
  EXPECT_THAT(DecodeTraceTaskBatch(batch).status().message(),
              HasSubstr("TraceTaskBatch.trace_request"));
  v1::TraceTaskBatchResponse response =
      TraceTaskBatchResponseOf({fill.MakeCurveResult(), fill.Run()});
  response.mutable_results(1)->clear_candidate_run();
  const StatusOr<std::vector<TraceTaskResult>> bad =
      DecodeTraceTaskBatchResponse(DeterministicBytes(response));
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_THAT(bad.status().message(), HasSubstr("TraceTaskBatchResponse.results[1].result"));
  EXPECT_EQ(DecodeTraceTaskBatchResponse("\xff\xff").status().code(), StatusCode::kInvalidArgument);
}

// Singular double fields (proto3 leaves out a field at its default; -0.0 must not be taken for
// it) with -0.0, a NaN payload, infinities and a subnormal.
TEST(TraceTaskCodecTest, SignedZerosAndNaNsInSingleFieldsRoundTripExactly) {
  const double inf = std::numeric_limits<double>::infinity();
  CurveTask task = Filler(true).Curve();
  task.start.point.value = -0.0;
  task.start.point.period = kPayloadNaN;
  task.start.before.max_modulus = -inf;
  task.start.after.max_modulus = std::numeric_limits<double>::denorm_min();
  task.start.near_grazing.value = -0.0;
  task.start.near_grazing.distance = inf;
  ExpectTaskRoundTrip(task);
  CandidatesTask candidates = Filler(false).Candidates();
  candidates.point.point.value1 = -0.0;
  candidates.point.point.value2 = kPayloadNaN;
  candidates.point.bracket = -0.0;
  candidates.point.point.stability.multipliers = {{-0.0, kPayloadNaN}};
  candidates.point.point.stability.monodromy = Eigen::MatrixXd::Constant(2, 2, -0.0);
  ExpectTaskRoundTrip(candidates);
}

TEST(TraceTaskCodecTest, DefaultValuesRoundTripExactly) {
  ExpectTaskRoundTrip(CurveTask{});
  ExpectTaskRoundTrip(CandidatesTask{});
  ExpectTaskRoundTrip(CandidateTask{});
  ExpectResultRoundTrip(CurveResult{});
  ExpectResultRoundTrip(CandidateRun{});
}

// Every value of each engine enum, and every status code, comes back.
TEST(TraceTaskCodecTest, EveryEnumValueRoundTrips) {
  for (int k = 0; k <= static_cast<int>(SpecialPointKind::kPowerMax); ++k) {
    CurveTask task;
    task.start.kind = static_cast<SpecialPointKind>(k);
    task.start.near_grazing.kind = static_cast<SpecialPointKind>(k);
    ExpectTaskRoundTrip(task);
  }
  for (int k = 0; k <= static_cast<int>(Codim2Kind::kCusp); ++k) {
    CandidatesTask task;
    task.from_kind = static_cast<CurveKind>(k % 4);
    task.point.kind = static_cast<Codim2Kind>(k);
    ExpectTaskRoundTrip(task);
  }
  for (int k = 0; k <= static_cast<int>(StatusCode::kUnauthenticated); ++k) {
    CurveResult result;
    result.kind = static_cast<CurveKind>(k % 4);
    result.summary.termination = static_cast<Termination>(k % 4);
    result.summary.status = Status(static_cast<StatusCode>(k), "code " + std::to_string(k));
    ExpectResultRoundTrip(result);
  }
}

// The values the codec accepts for each enum are the engine enum's: every value below the first
// one refused has an engine name, and the first refused has none (the name functions' fallback).
// An enumerator added to the engine gets a name, so this fails until the codec's range grows.
int FirstRefused(const std::function<bool(int32_t)>& decodes) {
  int32_t k = 0;
  while (k < 1000 && decodes(k)) ++k;
  return k;
}

TEST(TraceTaskCodecTest, EnumRangesAreTheEngineEnumsRanges) {
  v1::TraceTaskResponse response;
  ASSERT_TRUE(response.ParseFromString(EncodeTraceTaskResult(Filler(true).MakeCurveResult())));
  v1::TraceTaskRequest request;
  ASSERT_TRUE(
      request.ParseFromString(EncodeTraceTaskRequest(ParentRequest(), Filler(true).Curve())));
  auto result_decodes = [&response](const std::function<void(v1::TaskCurveResult*, int32_t)>& set) {
    return [&response, set](int32_t k) {
      v1::TraceTaskResponse changed = response;
      set(changed.mutable_curve(), k);
      return DecodeTraceTaskResult(changed.SerializeAsString()).ok();
    };
  };
  const int curve_kinds =
      FirstRefused(result_decodes([](v1::TaskCurveResult* r, int32_t k) { r->set_kind(k); }));
  const int codim2_kinds = FirstRefused(
      result_decodes([](v1::TaskCurveResult* r, int32_t k) { r->mutable_codim2(0)->set_kind(k); }));
  const int terminations = FirstRefused(result_decodes(
      [](v1::TaskCurveResult* r, int32_t k) { r->mutable_summary()->set_termination(k); }));
  const int codes = FirstRefused(result_decodes([](v1::TaskCurveResult* r, int32_t k) {
    r->mutable_summary()->mutable_status()->set_code(k);
  }));
  const int point_kinds = FirstRefused([&request](int32_t k) {
    v1::TraceTaskRequest changed = request;
    changed.mutable_curve()->mutable_start()->set_kind(k);
    return DecodeTraceTaskRequest(changed.SerializeAsString()).ok();
  });
  auto expect_range = [](int refused, const std::function<std::string(int)>& name,
                         const std::string& unnamed, const char* what) {
    for (int k = 0; k < refused; ++k) EXPECT_NE(name(k), unnamed) << what << " " << k;
    EXPECT_EQ(name(refused), unnamed) << what << " " << refused << " is refused";
  };
  expect_range(
      curve_kinds, [](int k) { return CurveKindName(static_cast<CurveKind>(k)); }, "?",
      "CurveKind");
  expect_range(
      codim2_kinds, [](int k) { return Codim2KindName(static_cast<Codim2Kind>(k)); }, "?",
      "Codim2Kind");
  expect_range(
      point_kinds, [](int k) { return SpecialPointKindName(static_cast<SpecialPointKind>(k)); },
      "?", "SpecialPointKind");
  expect_range(
      terminations, [](int k) { return TerminationName(static_cast<Termination>(k)); }, "?",
      "Termination");
  // StatusCodeName's fallback is "UNKNOWN", also the name of code 2.
  expect_range(
      codes,
      [](int k) {
        return k == 2 ? std::string("UNKNOWN (2)") : StatusCodeName(static_cast<StatusCode>(k));
      },
      "UNKNOWN", "StatusCode");
  // A negative value is refused too.
  EXPECT_FALSE(result_decodes([](v1::TaskCurveResult* r, int32_t k) { r->set_kind(k); })(-1));
}

// ---------------------------------------------------------------------------------------------
// The helper sees every field: changing any one field of a filled value is a difference at that
// field's path. With the round trips above this means no field is dropped or altered.

template <typename T>
using Change = std::pair<std::string, std::function<void(T&)>>;

template <typename T>
void ExpectEveryChangeNoticed(const T& value, const std::vector<Change<T>>& changes) {
  EXPECT_TRUE(DifferencesOf(value, value).empty()) << Joined(DifferencesOf(value, value));
  for (const auto& [path, change] : changes) {
    T changed = value;
    change(changed);
    const Differences d = DifferencesOf(value, changed);
    ASSERT_EQ(d.size(), 1u) << path << ":\n" << Joined(d);
    EXPECT_EQ(d[0], path);
  }
}

double Other(double x) { return std::nextafter(x, std::numeric_limits<double>::infinity()); }

TEST(TraceTaskCodecTest, EqualityNoticesAChangeOfAnyCurveTaskField) {
  const CurveTask task = Filler(true).Curve();
  ExpectEveryChangeNoticed<CurveTask>(
      task,
      {
          {"value.start.kind", [](CurveTask& t) { t.start.kind = SpecialPointKind::kFold; }},
          {"value.start.point.value", [](CurveTask& t) { t.start.point.value += 1; }},
          {"value.start.point.orbit.signature.periods",
           [](CurveTask& t) { ++t.start.point.orbit.signature.periods; }},
          {"value.start.point.orbit.signature.segments[0].mode",
           [](CurveTask& t) { ++t.start.point.orbit.signature.segments[0].mode; }},
          {"value.start.point.orbit.signature.segments[1].guard",
           [](CurveTask& t) { ++t.start.point.orbit.signature.segments[1].guard; }},
          {"value.start.point.orbit.signature.segments[0].tangent",
           [](CurveTask& t) { t.start.point.orbit.signature.segments[0].tangent ^= true; }},
          {"value.start.point.orbit.signature.segments (size)",
           [](CurveTask& t) { t.start.point.orbit.signature.segments.pop_back(); }},
          {"value.start.point.orbit.params(5,0)",
           [](CurveTask& t) {
             t.start.point.orbit.params[5] = Other(t.start.point.orbit.params[5]);
           }},
          {"value.start.point.orbit.params (dimensions)",
           [](CurveTask& t) { t.start.point.orbit.params.conservativeResize(5); }},
          {"value.start.point.orbit.starts[1](3,0)",
           [](CurveTask& t) {
             t.start.point.orbit.starts[1][3] = -t.start.point.orbit.starts[1][3];
           }},
          {"value.start.point.orbit.starts[0] (dimensions)",
           [](CurveTask& t) { t.start.point.orbit.starts[0].conservativeResize(3); }},
          {"value.start.point.orbit.starts (size)",
           [](CurveTask& t) { t.start.point.orbit.starts.pop_back(); }},
          {"value.start.point.orbit.durations[1]",
           [](CurveTask& t) { t.start.point.orbit.durations[1] += 1; }},
          {"value.start.point.orbit.durations (size)",
           [](CurveTask& t) { t.start.point.orbit.durations.push_back(1); }},
          {"value.start.point.measures[1]",
           [](CurveTask& t) {
             t.start.point.measures[1] = std::numeric_limits<double>::quiet_NaN();
           }},
          {"value.start.point.measures[2]", [](CurveTask& t) { t.start.point.measures[2] = 0.0; }},
          {"value.start.point.measures (size)",
           [](CurveTask& t) { t.start.point.measures.pop_back(); }},
          {"value.start.point.stability.multipliers[1].re",
           [](CurveTask& t) { t.start.point.stability.multipliers[1].real(0.5); }},
          {"value.start.point.stability.multipliers[0].im",
           [](CurveTask& t) { t.start.point.stability.multipliers[0].imag(0.5); }},
          {"value.start.point.stability.multipliers (size)",
           [](CurveTask& t) { t.start.point.stability.multipliers.pop_back(); }},
          {"value.start.point.stability.structural_zeros",
           [](CurveTask& t) { ++t.start.point.stability.structural_zeros; }},
          {"value.start.point.stability.structural_ones",
           [](CurveTask& t) { ++t.start.point.stability.structural_ones; }},
          {"value.start.point.stability.stable",
           [](CurveTask& t) { t.start.point.stability.stable ^= true; }},
          {"value.start.point.stability.monodromy(2,1)",
           [](CurveTask& t) { t.start.point.stability.monodromy(2, 1) += 1; }},
          // The same six entries as 2 x 3: only the dimensions differ.
          {"value.start.point.stability.monodromy (dimensions)",
           [](CurveTask& t) {
             Eigen::MatrixXd& m = t.start.point.stability.monodromy;
             m = Eigen::Map<Eigen::MatrixXd>(m.data(), 2, 3).eval();
           }},
          {"value.start.point.period", [](CurveTask& t) { t.start.point.period += 1; }},
          {"value.start.detail", [](CurveTask& t) { t.start.detail += "x"; }},
          {"value.start.before.known", [](CurveTask& t) { t.start.before.known ^= true; }},
          {"value.start.before.stable", [](CurveTask& t) { t.start.before.stable ^= true; }},
          {"value.start.before.max_modulus", [](CurveTask& t) { t.start.before.max_modulus += 1; }},
          {"value.start.after.known", [](CurveTask& t) { t.start.after.known ^= true; }},
          {"value.start.after.stable", [](CurveTask& t) { t.start.after.stable ^= true; }},
          {"value.start.after.max_modulus", [](CurveTask& t) { t.start.after.max_modulus += 1; }},
          {"value.start.near_grazing.near",
           [](CurveTask& t) { t.start.near_grazing.near ^= true; }},
          {"value.start.near_grazing.kind",
           [](CurveTask& t) { t.start.near_grazing.kind = SpecialPointKind::kGrazingPi; }},
          {"value.start.near_grazing.value", [](CurveTask& t) { t.start.near_grazing.value += 1; }},
          {"value.start.near_grazing.distance",
           [](CurveTask& t) { t.start.near_grazing.distance += 1; }},
          {"value.axis", [](CurveTask& t) { ++t.axis; }},
      });
}

TEST(TraceTaskCodecTest, EqualityNoticesAChangeOfAnyCandidateTaskField) {
  const CandidateTask task = Filler(false).CandidateRunTask();
  ExpectEveryChangeNoticed<CandidateTask>(
      task,
      {
          {"value.point.kind", [](CandidateTask& t) { t.point.kind = Codim2Kind::kCusp; }},
          {"value.point.point.value1", [](CandidateTask& t) { t.point.point.value1 += 1; }},
          {"value.point.point.value2", [](CandidateTask& t) { t.point.point.value2 += 1; }},
          {"value.point.point.orbit.durations[0]",
           [](CandidateTask& t) { t.point.point.orbit.durations[0] += 1; }},
          {"value.point.point.measures[4]",
           [](CandidateTask& t) { t.point.point.measures[4] = 0.0; }},
          {"value.point.point.stability.stable",
           [](CandidateTask& t) { t.point.point.stability.stable ^= true; }},
          {"value.point.detail", [](CandidateTask& t) { t.point.detail.pop_back(); }},
          {"value.point.bracket", [](CandidateTask& t) { t.point.bracket = -t.point.bracket; }},
          {"value.point.violation.admissible",
           [](CandidateTask& t) { t.point.violation.admissible ^= true; }},
          {"value.point.violation.segment", [](CandidateTask& t) { ++t.point.violation.segment; }},
          {"value.point.violation.guard", [](CandidateTask& t) { ++t.point.violation.guard; }},
          {"value.point.violation.at_start",
           [](CandidateTask& t) { t.point.violation.at_start ^= true; }},
          {"value.point.violation.time", [](CandidateTask& t) { t.point.violation.time += 1.0; }},
          {"value.point.violation.message",
           [](CandidateTask& t) { t.point.violation.message[4] = 'x'; }},
          {"value.point.same_as_curve", [](CandidateTask& t) { ++t.point.same_as_curve; }},
          {"value.point.same_as_index", [](CandidateTask& t) { ++t.point.same_as_index; }},
          {"value.candidate.orbit.status.code",
           [](CandidateTask& t) { t.candidate.orbit = Status(StatusCode::kInternal, ""); }},
          {"value.candidate.orbit.durations[0]",
           [](CandidateTask& t) { t.candidate.orbit->durations[0] += 1; }},
          {"value.candidate.seed_kind",
           [](CandidateTask& t) { t.candidate.seed_kind = SpecialPointKind::kFold; }},
          {"value.candidate.kind", [](CandidateTask& t) { t.candidate.kind = CurveKind::kFold; }},
          {"value.candidate.step_off", [](CandidateTask& t) { ++t.candidate.step_off; }},
          {"value.last_resort", [](CandidateTask& t) { t.last_resort ^= true; }},
      });
  // Two failed candidates differ by their messages.
  CandidateTask failed = task;
  failed.candidate.orbit = Status(StatusCode::kInternal, "one");
  ExpectEveryChangeNoticed<CandidateTask>(
      failed, {{"value.candidate.orbit.status.message", [](CandidateTask& t) {
                  t.candidate.orbit = Status(StatusCode::kInternal, "two");
                }}});
}

TEST(TraceTaskCodecTest, EqualityNoticesAChangeOfAnyCandidateRunField) {
  const CandidateRun run = Filler(true).Run();
  ExpectEveryChangeNoticed<CandidateRun>(
      run,
      {
          {"value.deferred", [](CandidateRun& r) { r.deferred ^= true; }},
          {"value.stopped", [](CandidateRun& r) { r.stopped ^= true; }},
          {"value.tries (size)", [](CandidateRun& r) { r.tries.pop_back(); }},
          {"value.tries[1].first.detail", [](CandidateRun& r) { r.tries[1].first.detail += "x"; }},
          {"value.tries[0].second.kind",
           [](CandidateRun& r) { r.tries[0].second.kind = CurveKind::kFold; }},
          {"value.tries[0].second.points[1].value1",
           [](CandidateRun& r) { r.tries[0].second.points[1].value1 += 1; }},
          {"value.tries[0].second.points (size)",
           [](CandidateRun& r) { r.tries[0].second.points.pop_back(); }},
          {"value.tries[1].second.crossings[0].value2",
           [](CandidateRun& r) { r.tries[1].second.crossings[0].value2 += 1; }},
          {"value.tries[1].second.codim2[0].detail",
           [](CandidateRun& r) { r.tries[1].second.codim2[0].detail += "x"; }},
          {"value.tries[1].second.unverified_ends[0].bracket",
           [](CandidateRun& r) { r.tries[1].second.unverified_ends[0].bracket += 1; }},
          {"value.tries[0].second.summary.termination",
           [](CandidateRun& r) { r.tries[0].second.summary.termination = Termination::kFailed; }},
          {"value.tries[0].second.summary.status.code",
           [](CandidateRun& r) {
             r.tries[0].second.summary.status =
                 Status(StatusCode::kInternal, r.tries[0].second.summary.status.message());
           }},
          {"value.tries[0].second.summary.status.message",
           [](CandidateRun& r) {
             r.tries[0].second.summary.status =
                 Status(r.tries[0].second.summary.status.code(), "other");
           }},
          {"value.tries[0].second.summary.message",
           [](CandidateRun& r) { r.tries[0].second.summary.message += "x"; }},
          {"value.tries[0].second.summary.steps",
           [](CandidateRun& r) { ++r.tries[0].second.summary.steps; }},
          {"value.tries[0].second.summary.rejected_steps",
           [](CandidateRun& r) { ++r.tries[0].second.summary.rejected_steps; }},
          {"value.tries[0].second.summary.newton_iterations",
           [](CandidateRun& r) { ++r.tries[0].second.summary.newton_iterations; }},
      });
}

TEST(TraceTaskCodecTest, EqualityNoticesAChangeOfCandidatesTaskFieldsAndAlternatives) {
  const CandidatesTask task = Filler(true).Candidates();
  ExpectEveryChangeNoticed<CandidatesTask>(
      task, {{"value.from_kind", [](CandidatesTask& t) { t.from_kind = CurveKind::kFold; }},
             {"value.point.kind", [](CandidatesTask& t) { t.point.kind = Codim2Kind::kCusp; }}});
  const TraceTask as_task = task;
  EXPECT_EQ(DifferencesOf(as_task, TraceTask{CurveTask{}}), Differences{"value (alternative)"});
}

// ---------------------------------------------------------------------------------------------
// Real engine data: the omega-branch of the reference orbit at a = 0.3 and the curves in
// (omega, a) from its l1 grazing near omega = 0.5 (flip- and fold-grazings along it, ending at a
// double grazing) and from its fold below omega = 0.1 (ending at a fold-grazing, with the
// violation beyond it), as in tests/continuation/codim2_test.cc.

struct EngineData {
  ContinuationResult branch;
  const SpecialPoint* grazing = nullptr;
  const SpecialPoint* fold = nullptr;
  CurveResult grazing_curve;
  CurveResult fold_curve;
};

const SpecialPoint* FindPoint(const ContinuationResult& branch, SpecialPointKind kind, double lo,
                              double hi) {
  for (const SpecialPoint& s : branch.special_points) {
    if (s.kind == kind && s.point.value >= lo && s.point.value <= hi) return &s;
  }
  return nullptr;
}

const EngineData& Engine() {
  static const EngineData* data = [] {
    auto* d = new EngineData;
    DriftingOscillator model;
    ExactPropagator prop(model);
    const StatusOr<PeriodicOrbit> start =
        testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
    if (!start.ok()) return d;
    ContinuationOptions branch;
    branch.param = "omega";
    branch.min = 0.05;
    branch.max = 2.0;
    d->branch = Continue(model, prop, *start, branch);
    d->grazing = FindPoint(d->branch, SpecialPointKind::kGrazingL1, 0.4, 0.6);
    d->fold = FindPoint(d->branch, SpecialPointKind::kFold, 0.05, 0.1);
    CurveOptions curve;
    curve.param1 = std::string("omega");
    curve.param2 = "a";
    curve.min1 = 0.05, curve.max1 = 2.0;
    curve.min2 = 0.01, curve.max2 = 8.0;
    curve.crossings1 = {0.45};  // a crossing to carry
    if (d->grazing != nullptr) d->grazing_curve = ContinueCurve(model, prop, *d->grazing, curve);
    if (d->fold != nullptr) d->fold_curve = ContinueCurve(model, prop, *d->fold, curve);
    return d;
  }();
  return *data;
}

class TraceTaskCodecEngineTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const EngineData& e = Engine();
    ASSERT_NE(e.grazing, nullptr) << e.branch.summary.BriefReport();
    ASSERT_NE(e.fold, nullptr) << e.branch.summary.BriefReport();
    ASSERT_TRUE(e.grazing_curve.summary.completed()) << e.grazing_curve.summary.message;
    ASSERT_TRUE(e.fold_curve.summary.completed()) << e.fold_curve.summary.message;
    // What makes the data worth round-tripping: codimension-2 points with their orbits and
    // monodromies, a crossing, and an end with the violation beyond it.
    ASSERT_GE(e.grazing_curve.codim2.size(), 2u) << e.grazing_curve.summary.message;
    ASSERT_FALSE(e.grazing_curve.crossings.empty()) << e.grazing_curve.summary.message;
    ASSERT_EQ(e.fold_curve.codim2.size(), 1u) << e.fold_curve.summary.message;
    ASSERT_FALSE(e.fold_curve.codim2[0].violation.admissible) << e.fold_curve.codim2[0].detail;
    ASSERT_GT(e.grazing_curve.points.front().stability.monodromy.size(), 0);
    ASSERT_TRUE(e.grazing->before.known);
  }
};

TEST_F(TraceTaskCodecEngineTest, CurveTaskFromALocatedGrazingRoundTripsExactly) {
  ExpectTaskRoundTrip(CurveTask{*Engine().grazing, 0});
  ExpectTaskRoundTrip(CurveTask{*Engine().fold, 1});
}

TEST_F(TraceTaskCodecEngineTest, TracedCurvesRoundTripExactly) {
  const EngineData& e = Engine();
  ExpectResultRoundTrip(e.grazing_curve);
  ExpectResultRoundTrip(e.fold_curve);
  // A curve that failed, with its points so far, and one cancelled.
  CurveResult failed = e.fold_curve;
  failed.summary.Fail(Internal("corrector failed down to min_step at omega = 0.07"));
  failed.unverified_ends = e.grazing_curve.codim2;
  ExpectResultRoundTrip(failed);
  CurveResult cancelled = e.grazing_curve;
  cancelled.summary.Cancel("cancelled at step 12");
  ExpectResultRoundTrip(cancelled);
}

TEST_F(TraceTaskCodecEngineTest, CandidatesOfACodim2PointRoundTripExactly) {
  const EngineData& e = Engine();
  Codim2Point point = e.grazing_curve.codim2.front();
  point.same_as_curve = 3;
  point.same_as_index = 1;
  ExpectTaskRoundTrip(CandidatesTask{CurveKind::kGrazing, point});
  ExpectTaskRoundTrip(CandidatesTask{CurveKind::kFold, e.fold_curve.codim2.front()});

  SwitchCandidate found;
  found.orbit = e.grazing_curve.codim2.back().point.orbit;
  found.seed_kind = SpecialPointKind::kPeriodDoubling;
  found.kind = CurveKind::kPeriodDoubling;
  found.step_off = 2;
  SwitchCandidate missing;
  missing.orbit = Status(StatusCode::kFailedPrecondition, "no admissible start at this point");
  missing.seed_kind = SpecialPointKind::kFold;
  missing.kind = CurveKind::kFold;
  ExpectResultRoundTrip(std::vector<SwitchCandidate>{found, missing});

  ExpectTaskRoundTrip(CandidateTask{point, found, true});
  ExpectTaskRoundTrip(CandidateTask{e.fold_curve.codim2.front(), missing, false});
}

TEST_F(TraceTaskCodecEngineTest, CandidateRunWithTwoTriesRoundTripsExactly) {
  const EngineData& e = Engine();
  CandidateRun run;
  run.stopped = true;
  run.tries = {{*e.grazing, e.grazing_curve}, {*e.fold, e.fold_curve}};
  ExpectResultRoundTrip(run);
  run.stopped = false;
  run.deferred = true;
  ExpectResultRoundTrip(run);
}

// ---------------------------------------------------------------------------------------------
// Malformed input.

// The error is INVALID_ARGUMENT and its message starts with `field`.
template <typename T>
void ExpectErrorAt(const StatusOr<T>& decoded, const std::string& field) {
  ASSERT_FALSE(decoded.ok()) << "expected an error at " << field;
  EXPECT_EQ(decoded.status().code(), StatusCode::kInvalidArgument) << decoded.status().ToString();
  EXPECT_EQ(decoded.status().message().substr(0, field.size()), field)
      << decoded.status().ToString();
}

// A small valid result's message, to break one field of.
v1::TraceTaskResponse ResultMessage() {
  v1::TraceTaskResponse response;
  EXPECT_TRUE(response.ParseFromString(EncodeTraceTaskResult(Filler(true).MakeCurveResult())));
  return response;
}

v1::TraceTaskRequest RequestMessage() {
  v1::TraceTaskRequest request;
  EXPECT_TRUE(request.ParseFromString(
      EncodeTraceTaskRequest(ParentRequest(), Filler(true).CandidateRunTask())));
  return request;
}

StatusOr<TraceTaskResult> DecodeResult(const v1::TraceTaskResponse& response) {
  return DecodeTraceTaskResult(response.SerializeAsString());
}

StatusOr<DecodedTraceTask> DecodeRequest(const v1::TraceTaskRequest& request) {
  return DecodeTraceTaskRequest(request.SerializeAsString());
}

TEST(TraceTaskCodecMalformedTest, TruncatedBytesAreErrors) {
  // Everything after the first byte is inside one length-delimited field (the result; the
  // request's task), so no proper prefix parses into a complete value.
  const std::string result = EncodeTraceTaskResult(Filler(true).Run());
  for (size_t n = 0; n < result.size(); n += 1 + n / 8) {
    ExpectErrorAt(DecodeTraceTaskResult(result.substr(0, n)), "TraceTaskResponse");
  }
  const std::string request = EncodeTraceTaskRequest(ParentRequest(), Filler(true).Curve());
  for (size_t n = 0; n < request.size(); n += 1 + n / 8) {
    ExpectErrorAt(DecodeTraceTaskRequest(request.substr(0, n)), "TraceTaskRequest");
  }
}

TEST(TraceTaskCodecMalformedTest, GarbageIsNamedUnparsable) {
  const std::string garbage(16, '\xff');  // a tag varint that never ends
  ExpectErrorAt(DecodeTraceTaskResult(garbage),
                "TraceTaskResponse: not a serialized drillbif.v1.TraceTaskResponse");
  ExpectErrorAt(DecodeTraceTaskRequest(garbage),
                "TraceTaskRequest: not a serialized drillbif.v1.TraceTaskRequest");
  v1::TraceTaskRequest request = RequestMessage();
  request.set_trace_request(garbage);
  ExpectErrorAt(DecodeRequest(request),
                "TraceTaskRequest.trace_request: not a serialized drillbif.v1.TraceRequest");
}

TEST(TraceTaskCodecMalformedTest, AnEmptyOneofIsNamed) {
  ExpectErrorAt(DecodeTraceTaskResult(""), "TraceTaskResponse.result: not set");
  v1::TraceTaskRequest request = RequestMessage();
  request.clear_task();
  ExpectErrorAt(DecodeRequest(request), "TraceTaskRequest.task: not set");
}

TEST(TraceTaskCodecMalformedTest, AMatrixWhoseEntriesAreNotRowsTimesColsIsNamed) {
  const std::string field = "TraceTaskResponse.curve.points[1].stability.monodromy: ";
  v1::TraceTaskResponse response = ResultMessage();
  v1::TaskMatrix* m =
      response.mutable_curve()->mutable_points(1)->mutable_stability()->mutable_monodromy();
  m->mutable_data()->RemoveLast();
  ExpectErrorAt(DecodeResult(response), field + "3 x 2 matrix with 5 entries");
  m->add_data(1.0);
  m->set_rows(-3);
  m->set_cols(-2);  // the product is right, the dimensions are not
  ExpectErrorAt(DecodeResult(response), field + "-3 x -2 matrix with 6 entries");
  // Huge dimensions whose product overflows to the entries' count: 2^32 * 2^32 + 6 wraps to 6.
  m->set_rows(int64_t{1} << 32);
  m->set_cols(int64_t{1} << 32);
  ExpectErrorAt(DecodeResult(response), field);
  m->clear_data();
  m->set_rows(int64_t{1} << 40);
  m->set_cols(0);
  ExpectErrorAt(DecodeResult(response), field + "1099511627776 x 0 matrix with 0 entries");
}

TEST(TraceTaskCodecMalformedTest, VectorsLongerThanTheirEigenTypeAreNamed) {
  v1::TraceTaskResponse response = ResultMessage();
  v1::TaskOrbit* orbit = response.mutable_curve()->mutable_crossings(0)->mutable_orbit();
  for (int i = 0; i < kMaxStateDim; ++i) orbit->mutable_starts(1)->add_values(1.0);
  ExpectErrorAt(DecodeResult(response), "TraceTaskResponse.curve.crossings[0].orbit.starts[1]: 12");
  response = ResultMessage();
  orbit = response.mutable_curve()->mutable_crossings(0)->mutable_orbit();
  for (int i = 0; i < kMaxParams; ++i) orbit->add_params(1.0);
  ExpectErrorAt(DecodeResult(response), "TraceTaskResponse.curve.crossings[0].orbit.params: 18");
}

TEST(TraceTaskCodecMalformedTest, EnumsAndStatusCodesOutOfRangeAreNamed) {
  v1::TraceTaskResponse response = ResultMessage();
  response.mutable_curve()->set_kind(4);
  ExpectErrorAt(DecodeResult(response), "TraceTaskResponse.curve.kind: value 4 outside 0..3");
  response = ResultMessage();
  response.mutable_curve()->mutable_codim2(0)->set_kind(10);
  ExpectErrorAt(DecodeResult(response), "TraceTaskResponse.curve.codim2[0].kind: value 10");
  response = ResultMessage();
  response.mutable_curve()->mutable_summary()->set_termination(-1);
  ExpectErrorAt(DecodeResult(response), "TraceTaskResponse.curve.summary.termination: value -1");
  response = ResultMessage();
  response.mutable_curve()->mutable_summary()->mutable_status()->set_code(17);
  ExpectErrorAt(DecodeResult(response), "TraceTaskResponse.curve.summary.status.code: value 17");

  v1::TraceTaskRequest request = RequestMessage();
  request.mutable_candidate_run()->mutable_candidate()->set_seed_kind(10);
  ExpectErrorAt(DecodeRequest(request), "TraceTaskRequest.candidate_run.candidate.seed_kind");
  v1::TraceTaskRequest curve;
  ASSERT_TRUE(curve.ParseFromString(EncodeTraceTaskRequest(ParentRequest(), Filler(true).Curve())));
  curve.mutable_curve()->mutable_start()->mutable_near_grazing()->set_kind(-5);
  ExpectErrorAt(DecodeRequest(curve), "TraceTaskRequest.curve.start.near_grazing.kind: value -5");
}

TEST(TraceTaskCodecMalformedTest, AnUnsetMessageFieldIsNamed) {
  v1::TraceTaskResponse response = ResultMessage();
  response.mutable_curve()->mutable_points(0)->clear_orbit();
  ExpectErrorAt(DecodeResult(response), "TraceTaskResponse.curve.points[0].orbit: not set");
  response = ResultMessage();
  response.mutable_curve()->mutable_unverified_ends(0)->mutable_point()->clear_stability();
  ExpectErrorAt(DecodeResult(response),
                "TraceTaskResponse.curve.unverified_ends[0].point.stability: not set");
  response = ResultMessage();
  response.mutable_curve()->clear_summary();
  ExpectErrorAt(DecodeResult(response), "TraceTaskResponse.curve.summary: not set");
}

TEST(TraceTaskCodecMalformedTest, ASwitchCandidateOrbitIsAnOrbitOrAnErrorNotBothOrNeither) {
  const std::string field = "TraceTaskRequest.candidate_run.candidate.";
  v1::TraceTaskRequest request = RequestMessage();
  request.mutable_candidate_run()->mutable_candidate()->clear_orbit();
  ExpectErrorAt(DecodeRequest(request), field + "orbit: not set");
  request = RequestMessage();
  request.mutable_candidate_run()->mutable_candidate()->mutable_orbit_status()->set_code(9);
  ExpectErrorAt(DecodeRequest(request), field + "orbit: set with the error FAILED_PRECONDITION");
  request = RequestMessage();
  request.mutable_candidate_run()->mutable_candidate()->mutable_orbit_status()->set_message("?");
  ExpectErrorAt(DecodeRequest(request), field + "orbit_status: OK with a message");
  request = RequestMessage();
  request.mutable_candidate_run()->mutable_candidate()->clear_orbit_status();
  ExpectErrorAt(DecodeRequest(request), field + "orbit_status: not set");
}

// Random mutations of valid encodings (flipped, replaced, inserted and deleted bytes, cuts):
// each decodes to a value or to INVALID_ARGUMENT, never a crash; a value decoded re-encodes to
// bytes that decode again. Fixed seed: the same inputs on every run.
TEST(TraceTaskCodecMalformedTest, RandomMutationsDecodeToAValueOrAnError) {
  std::mt19937_64 random(20261128);
  auto mutate = [&random](std::string bytes) {
    const int edits = 1 + static_cast<int>(random() % 4);
    for (int k = 0; k < edits && !bytes.empty(); ++k) {
      const size_t at = random() % bytes.size();
      switch (random() % 5) {
        case 0:
          bytes[at] = static_cast<char>(bytes[at] ^ (1 << (random() % 8)));
          break;
        case 1:
          bytes[at] = static_cast<char>(random());
          break;
        case 2:
          bytes.insert(at, 1, static_cast<char>(random()));
          break;
        case 3:
          bytes.erase(at, 1);
          break;
        default:
          bytes.resize(at);
          break;
      }
    }
    return bytes;
  };
  Filler fill(true);
  const std::string request = EncodeTraceTaskRequest(ParentRequest(), fill.CandidateRunTask());
  const std::string result = EncodeTraceTaskResult(fill.Run());
  int request_values = 0, result_values = 0;
  constexpr int kMutations = 3000;
  for (int i = 0; i < kMutations; ++i) {
    const StatusOr<DecodedTraceTask> task = DecodeTraceTaskRequest(mutate(request));
    if (task.ok()) {
      ++request_values;
      const std::string again = EncodeTraceTaskRequest(task->trace_request, task->task);
      ASSERT_TRUE(DecodeTraceTaskRequest(again).ok());
    } else {
      ASSERT_EQ(task.status().code(), StatusCode::kInvalidArgument) << task.status().ToString();
    }
    const StatusOr<TraceTaskResult> value = DecodeTraceTaskResult(mutate(result));
    if (value.ok()) {
      ++result_values;
      ASSERT_TRUE(DecodeTraceTaskResult(EncodeTraceTaskResult(*value)).ok());
    } else {
      ASSERT_EQ(value.status().code(), StatusCode::kInvalidArgument) << value.status().ToString();
    }
  }
  // Both outcomes occur: the mutations reach the errors and the values (a changed double is a
  // valid value); counts printed for the record.
  std::printf("mutations decoded to a value: %d of %d requests, %d of %d results\n", request_values,
              kMutations, result_values, kMutations);
  EXPECT_GT(request_values, 0);
  EXPECT_LT(request_values, kMutations);
  EXPECT_GT(result_values, 0);
  EXPECT_LT(result_values, kMutations);
}

}  // namespace
}  // namespace drillbif::jobs
