// Brute-force bifurcation sweeps: grid, directions, continuation from the last state, errors and
// cancellation.
#include "drillbif/simulate/sweep.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <string_view>
#include <utility>
#include <vector>

#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "support/same_bits.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;
using testing::SameBits;

PropagatorFactory Exact(const DO& model) {
  return [&model] { return std::make_unique<ExactPropagator>(model); };
}

SweepOptions Small(double min, double max, int steps, SweepDirection direction) {
  SweepOptions o;
  o.param = std::string("b");  // not = "b": GCC 12 warns falsely (-Wrestrict, GCC bug 105329)
  o.min = min, o.max = max, o.steps = steps, o.direction = direction;
  o.transient_periods = 200;
  o.sample_periods = 5;
  return o;
}

// Inside the stable period-1 window (PD at b = 0.110, fold at b = 0.167 in MODEL.md) there is one
// attractor, so up and down sweeps land on the same fixed point at every value (to the contraction
// left after 200 periods at multiplier ~0.1: far below 1e-9).
TEST(Sweep, UpAndDownAgreeInsideThePeriodOneWindow) {
  DO model;
  const SweepOptions o = Small(0.12, 0.16, 5, SweepDirection::kBoth);
  const SweepResult r =
      Sweep(model, Exact(model), testing::ReferenceParams(), DefaultInitialState(model), o);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.status.ToString();
  ASSERT_EQ(r.up.size(), 5u);
  ASSERT_EQ(r.down.size(), 5u);
  for (int i = 0; i < 5; ++i) {
    const SweepPoint& u = r.up[i];
    const SweepPoint& d = r.down[4 - i];
    EXPECT_DOUBLE_EQ(u.value, 0.12 + 0.01 * i);
    EXPECT_DOUBLE_EQ(u.value, d.value);
    ASSERT_EQ(u.summary.termination, Termination::kCompleted) << u.summary.message;
    ASSERT_EQ(u.samples.size(), 5u);
    ASSERT_EQ(d.samples.size(), 5u);
    for (int k = 0; k < 5; ++k) {
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(u.samples[k].x[c], d.samples[k].x[c], 1e-9 * (1 + std::abs(d.samples[k].x[c])));
      }
      // Period 1: every sample is the same point.
      EXPECT_NEAR(u.samples[k].x[DO::kP], u.samples[0].x[DO::kP], 1e-9 * 60);
    }
  }
  // At b = 0.15 the fixed point is MODEL.md's (7 decimals).
  EXPECT_NEAR(r.up[3].samples[0].x[DO::kP], testing::kRefFixedP, testing::kRefFixedPrecision);
}

// Sequential sweeping starts each value from the previous value's final state: the default (one
// chunk) on one thread gives the same result as simulating the values one after another by hand,
// the first from x0 with the plain transient (the longer one is for later chunks' starts only).
TEST(Sweep, EachValueStartsFromTheLastState) {
  DO model;
  SweepOptions o = Small(0.09, 0.12, 3, SweepDirection::kUp);
  o.threads = 1;
  const SweepResult r =
      Sweep(model, Exact(model), testing::ReferenceParams(), DefaultInitialState(model), o);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted);
  ExactPropagator prop(model);
  StateVector x = DefaultInitialState(model);
  for (int i = 0; i < 3; ++i) {
    Params p = testing::ReferenceParams();
    p[DO::kB] = r.up[i].value;
    SimulationOptions so;
    so.transient_periods = o.transient_periods;
    so.sample_periods = o.sample_periods;
    const SimulationResult s = Simulate(model, prop, p, x, so);
    ASSERT_EQ(s.poincare.size(), r.up[i].samples.size());
    for (size_t k = 0; k < s.poincare.size(); ++k) {
      EXPECT_EQ(s.poincare[k].x, r.up[i].samples[k].x) << "value " << i << " sample " << k;
    }
    x = s.final_state;
    EXPECT_EQ(r.up[i].start,
              i == 0 ? SweepStart::kFromInitialState : SweepStart::kFromPreviousValue);
    EXPECT_EQ(r.up[i].transient_periods, o.transient_periods);
  }
}

// More threads do not change a sweep: each direction still runs value after value from the last
// state, so 2 and 4 threads (in one direction and in both, with and without a progress callback,
// which moves the work onto a pool) give the values of 1 thread bit for bit (the exact propagator
// is deterministic), every value but a direction's first started FROM_PREVIOUS_VALUE. The grid
// crosses the period-doubling at b = 0.110, where a restarted value would land elsewhere.
TEST(Sweep, MoreThreadsKeepEveryValueStartingFromThePreviousOne) {
  DO model;
  const Params prm = testing::ReferenceParams();
  const StateVector x0 = DefaultInitialState(model);
  for (SweepDirection direction :
       {SweepDirection::kUp, SweepDirection::kDown, SweepDirection::kBoth}) {
    SweepOptions o = Small(0.09, 0.13, 12, direction);
    o.transient_periods = 50;
    o.threads = 1;
    const SweepResult one = Sweep(model, Exact(model), prm, x0, o);
    ASSERT_EQ(one.summary.termination, Termination::kCompleted) << one.summary.status.ToString();
    for (const std::vector<SweepPoint>* list : {&one.up, &one.down}) {
      for (size_t i = 0; i < list->size(); ++i) {
        EXPECT_EQ((*list)[i].start,
                  i == 0 ? SweepStart::kFromInitialState : SweepStart::kFromPreviousValue)
            << i;
        EXPECT_EQ((*list)[i].summary.termination, Termination::kCompleted)
            << (*list)[i].summary.message;
      }
    }
    for (int threads : {2, 4}) {
      for (bool with_progress : {false, true}) {
        o.threads = threads;
        const SweepResult many =
            with_progress ? Sweep(model, Exact(model), prm, x0, o, [](double) { return true; })
                          : Sweep(model, Exact(model), prm, x0, o);
        ASSERT_EQ(many.summary.termination, Termination::kCompleted);
        EXPECT_EQ(many.summary.periods, one.summary.periods);
        EXPECT_EQ(many.summary.events, one.summary.events);
        ASSERT_EQ(many.up.size(), one.up.size());
        ASSERT_EQ(many.down.size(), one.down.size());
        for (size_t i = 0; i < one.up.size(); ++i) {
          EXPECT_TRUE(SameBits(many.up[i], one.up[i])) << threads << " threads, up " << i;
        }
        for (size_t i = 0; i < one.down.size(); ++i) {
          EXPECT_TRUE(SameBits(many.down[i], one.down[i])) << threads << " threads, down " << i;
        }
      }
    }
  }
}

// b over [0, 0.2] in 11 values split explicitly into 3 chunks on 2 threads, 20 transient and 2
// sampled periods a value.
SweepResult ThreeChunksOfEleven(const DO& model, SweepDirection direction) {
  SweepOptions o = Small(0.0, 0.2, 11, direction);
  o.threads = 2;
  o.chunks = 3;
  o.transient_periods = 20;
  o.sample_periods = 2;
  return Sweep(model, Exact(model), testing::ReferenceParams(), DefaultInitialState(model), o);
}

// An explicitly chunked sweep: each chunk's first value starts from x0, the direction's first
// with the plain transient and every later chunk's with the factor's; the others from the
// previous value. Chunk c of 3 over 11 values starts at floor(c x 11 / 3) = 0, 3, 7.
TEST(Sweep, ExplicitChunksStartEachChunkFromTheInitialState) {
  DO model;
  const SweepResult r = ThreeChunksOfEleven(model, SweepDirection::kBoth);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted);
  for (const std::vector<SweepPoint>* list : {&r.up, &r.down}) {
    ASSERT_EQ(list->size(), 11u);
    for (int i = 0; i < 11; ++i) {
      const SweepPoint& pt = (*list)[i];
      ASSERT_EQ(pt.summary.termination, Termination::kCompleted) << pt.summary.message;
      const bool chunk_start = i == 0 || i == 3 || i == 7;
      EXPECT_EQ(pt.start,
                chunk_start ? SweepStart::kFromInitialState : SweepStart::kFromPreviousValue)
          << i;
      EXPECT_EQ(pt.transient_periods, chunk_start && i > 0 ? 4 * 20 : 20) << i;
    }
  }
  // Each direction: 11 x (20 + 2) periods and 2 x 3 x 20 more at the later chunks' starts.
  EXPECT_EQ(r.summary.periods, 2 * (11 * 22 + 2 * 3 * 20));
}

TEST(Sweep, PiecesAreDirectionMajorChunksInGridOrder) {
  SweepOptions o = Small(0.0, 0.2, 11, SweepDirection::kBoth);
  o.chunks = 3;
  const std::vector<SweepPiece> pieces = SweepPieces(o);
  ASSERT_EQ(pieces.size(), 6u);
  const int first[] = {0, 3, 7};  // floor(c x 11 / 3)
  for (size_t k = 0; k < 6; ++k) {
    EXPECT_EQ(pieces[k].direction, k < 3 ? SweepDirection::kUp : SweepDirection::kDown) << k;
    EXPECT_EQ(pieces[k].first, first[k % 3]) << k;
    EXPECT_EQ(pieces[k].last, k % 3 == 2 ? 10 : first[k % 3 + 1] - 1) << k;
  }
  o.direction = SweepDirection::kDown;
  o.chunks = 1;
  ASSERT_EQ(SweepPieces(o).size(), 1u);
  EXPECT_EQ(SweepPieces(o)[0].direction, SweepDirection::kDown);
  EXPECT_EQ(SweepPieces(o)[0].last, 10);
}

// `piece` is checked against SweepPieces' count, directions x chunks, and so is a sweep of
// hundreds of millions of chunks (5e8 values in 1e8 chunks each way: the check names 2e8 pieces
// without making them).
TEST(Sweep, PieceIsCheckedAgainstDirectionsTimesChunks) {
  SweepOptions o = Small(0.0, 0.2, 11, SweepDirection::kBoth);
  o.chunks = 3;
  o.piece = 5;
  EXPECT_TRUE(o.Validate().ok());
  o.piece = 6;
  const Status six = o.Validate();
  EXPECT_EQ(six.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(six.message().find("0 .. 5 (directions x chunks pieces)"), std::string::npos)
      << six.message();
  o.steps = 500000000;
  o.chunks = 100000000;
  o.piece = 200000000;
  const Status many = o.Validate();
  EXPECT_EQ(many.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(many.message().find("0 .. 199999999"), std::string::npos) << many.message();
}

// Each piece run alone gives, bit for bit, the values the whole sweep gives at the same grid
// positions (samples, how each ended, how each started), and its summary counts only them: a
// piece starts from x0 and needs nothing from the others. Over [0.08, 0.2] the grid crosses the
// period-doubling at b = 0.110, so the values differ from each other in more than roundoff.
void ExpectPiecesEqualTheWholeSweep(int chunks) {
  DO model;
  SweepOptions o = Small(0.08, 0.2, 7, SweepDirection::kBoth);
  o.transient_periods = 30;
  o.sample_periods = 3;
  o.chunks = chunks;
  o.threads = 2;
  const Params prm = testing::ReferenceParams();
  const StateVector x0 = DefaultInitialState(model);
  const SweepResult whole = Sweep(model, Exact(model), prm, x0, o);
  ASSERT_EQ(whole.summary.termination, Termination::kCompleted);
  const std::vector<SweepPiece> pieces = SweepPieces(o);
  ASSERT_EQ(pieces.size(), static_cast<size_t>(2 * chunks));
  int64_t values = 0, periods = 0, events = 0;
  for (size_t k = 0; k < pieces.size(); ++k) {
    const SweepPiece& piece = pieces[k];
    SweepOptions one = o;
    one.piece = static_cast<int>(k);
    const SweepResult part = Sweep(model, Exact(model), prm, x0, one);
    ASSERT_EQ(part.summary.termination, Termination::kCompleted) << k;
    const bool up = piece.direction == SweepDirection::kUp;
    const std::vector<SweepPoint>& got = up ? part.up : part.down;
    const std::vector<SweepPoint>& want = up ? whole.up : whole.down;
    EXPECT_TRUE((up ? part.down : part.up).empty()) << k;
    ASSERT_EQ(got.size(), static_cast<size_t>(piece.last - piece.first + 1)) << k;
    for (int i = piece.first; i <= piece.last; ++i) {
      EXPECT_TRUE(testing::SameBits(got[static_cast<size_t>(i - piece.first)],
                                    want[static_cast<size_t>(i)]))
          << "piece " << k << ", position " << i;
    }
    EXPECT_EQ(part.summary.values, piece.last - piece.first + 1) << k;
    values += part.summary.values;
    periods += part.summary.periods;
    events += part.summary.events;
  }
  EXPECT_EQ(values, whole.summary.values);
  EXPECT_EQ(periods, whole.summary.periods);
  EXPECT_EQ(events, whole.summary.events);
}

TEST(Sweep, EachPieceAloneEqualsTheWholeSweepBitwiseWithOneChunk) {
  ExpectPiecesEqualTheWholeSweep(1);
}

TEST(Sweep, EachPieceAloneEqualsTheWholeSweepBitwiseWithTwoChunks) {
  ExpectPiecesEqualTheWholeSweep(2);
}

// Streamed, a piece's values keep their positions in the whole sweep's lists.
TEST(Sweep, AStreamedPieceKeepsItsPositions) {
  DO model;
  SweepOptions o = Small(0.08, 0.2, 7, SweepDirection::kBoth);
  o.transient_periods = 30;
  o.sample_periods = 3;
  o.chunks = 2;
  o.piece = 3;  // the down direction's second chunk: positions 3 .. 6
  std::vector<int> positions;
  std::vector<SweepDirection> directions;
  const SweepResult r =
      Sweep(model, Exact(model), testing::ReferenceParams(), DefaultInitialState(model), o, {}, {},
            [&](SweepDirection d, int index, SweepPoint&&) {
              directions.push_back(d);
              positions.push_back(index);
              return true;
            });
  ASSERT_EQ(r.summary.termination, Termination::kCompleted);
  EXPECT_EQ(positions, (std::vector<int>{3, 4, 5, 6}));
  EXPECT_EQ(directions, std::vector<SweepDirection>(4, SweepDirection::kDown));
  EXPECT_TRUE(r.up.empty() && r.down.empty());
}

TEST(Sweep, ChunksCoverTheGridInOrder) {
  DO model;
  const SweepResult r = ThreeChunksOfEleven(model, SweepDirection::kUp);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted);
  ASSERT_EQ(r.up.size(), 11u);
  EXPECT_TRUE(r.down.empty());
  for (int i = 0; i < 11; ++i) {
    EXPECT_NEAR(r.up[i].value, 0.02 * i, 1e-15);
    EXPECT_EQ(r.up[i].summary.termination, Termination::kCompleted) << r.up[i].summary.message;
    EXPECT_EQ(r.up[i].samples.size(), 2u);
  }
}

// The exact propagator, except that every Advance at the listed values of b fails.
class FailingAt final : public Propagator {
 public:
  FailingAt(const DO& model, std::vector<double> values)
      : exact_(model), values_(std::move(values)) {}
  std::string_view name() const override { return "failing"; }
  FlowResult FlowMap(int mode, const StateVector& x0, double t, const Params& params,
                     const FlowRequest& request) override {
    return exact_.FlowMap(mode, x0, t, params, request);
  }
  AdvanceResult Advance(const AdvanceRequest& request, const Params& params) override {
    for (double v : values_) {
      if (std::abs(params[DO::kB] - v) < 1e-12) {  // grid values are 0.01 apart
        AdvanceResult r;
        r.status = Internal("injected failure");
        r.x = request.x0;
        return r;
      }
    }
    return exact_.Advance(request, params);
  }

 private:
  ExactPropagator exact_;
  std::vector<double> values_;
};

// A value that fails hands no state on: the values after it start from the last value that
// completed (FROM_EARLIER_VALUE), or from x0 while none has (FROM_INITIAL_STATE). Values 0, 2 and
// 3 of 0.10, 0.11, ..., 0.14 fail; value 4 equals, bit for bit, a run by hand from value 1's end.
TEST(Sweep, AfterAFailedValueTheNextStartsFromTheLastCompletedOne) {
  DO model;
  SweepOptions o = Small(0.10, 0.14, 5, SweepDirection::kUp);
  o.threads = 1;
  const PropagatorFactory failing = [&model] {
    return std::make_unique<FailingAt>(model, std::vector<double>{0.10, 0.12, 0.13});
  };
  const Params prm = testing::ReferenceParams();
  const StateVector x0 = DefaultInitialState(model);
  const SweepResult r = Sweep(model, failing, prm, x0, o);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted);
  ASSERT_EQ(r.up.size(), 5u);
  const Termination kOk = Termination::kCompleted, kFail = Termination::kFailed;
  const Termination ends[] = {kFail, kOk, kFail, kFail, kOk};
  const SweepStart starts[] = {SweepStart::kFromInitialState, SweepStart::kFromInitialState,
                               SweepStart::kFromPreviousValue, SweepStart::kFromEarlierValue,
                               SweepStart::kFromEarlierValue};
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(r.up[i].summary.termination, ends[i]) << i << ": " << r.up[i].summary.message;
    EXPECT_EQ(r.up[i].start, starts[i]) << i;
  }
  ExactPropagator prop(model);
  SimulationOptions so;
  so.transient_periods = o.transient_periods;
  so.sample_periods = o.sample_periods;
  Params p = prm;
  p[DO::kB] = r.up[1].value;
  const SimulationResult first = Simulate(model, prop, p, x0, so);
  p[DO::kB] = r.up[4].value;
  const SimulationResult last = Simulate(model, prop, p, first.final_state, so);
  ASSERT_EQ(last.poincare.size(), r.up[4].samples.size());
  for (size_t k = 0; k < last.poincare.size(); ++k) {
    EXPECT_EQ(last.poincare[k].x, r.up[4].samples[k].x) << k;
  }
}

TEST(Sweep, InvalidRequestsNameTheProblem) {
  DO model;
  const Params prm = testing::ReferenceParams();
  const StateVector x0 = DefaultInitialState(model);
  struct Case {
    SweepOptions options;
    const char* needle;
  };
  SweepOptions unknown = Small(0, 1, 3, SweepDirection::kUp);
  unknown.param = "zeta";
  SweepOptions reversed = Small(0.2, 0.1, 3, SweepDirection::kUp);
  SweepOptions one_step = Small(0.1, 0.2, 1, SweepDirection::kUp);
  SweepOptions bad_xi = Small(-1.0, 0.5, 3, SweepDirection::kUp);
  bad_xi.param = "xi";
  SweepOptions no_chunk = Small(0.1, 0.2, 3, SweepDirection::kUp);
  no_chunk.chunks = 0;
  SweepOptions too_many_chunks = Small(0.1, 0.2, 3, SweepDirection::kUp);
  too_many_chunks.chunks = 4;
  SweepOptions no_such_piece = Small(0.1, 0.2, 3, SweepDirection::kBoth);
  no_such_piece.piece = 2;  // two directions of one chunk: pieces 0 and 1
  SweepOptions negative_piece = Small(0.1, 0.2, 3, SweepDirection::kUp);
  negative_piece.piece = -2;
  for (const Case& c :
       {Case{unknown, "zeta"}, Case{reversed, "max must be > min"}, Case{one_step, "steps"},
        Case{bad_xi, "xi"}, Case{no_chunk, "chunks"}, Case{too_many_chunks, "chunks"},
        Case{no_such_piece, "piece"}, Case{negative_piece, "piece"}}) {
    const SweepResult r = Sweep(model, Exact(model), prm, x0, c.options);
    EXPECT_FALSE(r.summary.status.ok());
    EXPECT_EQ(r.summary.termination, Termination::kFailed);
    EXPECT_EQ(r.summary.values, 0);
    EXPECT_NE(r.summary.status.message().find(c.needle), std::string::npos)
        << r.summary.status.message();
  }
}

TEST(Sweep, ProgressCanCancel) {
  DO model;
  SweepOptions o = Small(0.0, 0.2, 400, SweepDirection::kBoth);
  o.transient_periods = 500;
  const SweepResult r = Sweep(model, Exact(model), testing::ReferenceParams(),
                              DefaultInitialState(model), o, [](double) { return false; });
  EXPECT_EQ(r.summary.termination, Termination::kCancelled);
  EXPECT_EQ(r.summary.status.code(), StatusCode::kCancelled);
  EXPECT_EQ(r.summary.BriefReport().rfind("cancelled: ", 0), 0u) << r.summary.BriefReport();
}

}  // namespace
}  // namespace drillbif
