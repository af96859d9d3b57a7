// Sweeps: cancellation with several worker threads within the bound (support/cancel_probe.h),
// streamed values (in grid order, equal to the accumulated ones, with a bounded buffer), and
// period counts that do not fit 32 bits.
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/flow/exact_propagator.h"
#include "drillbif/simulate/sweep.h"
#include "problems/drifting_reference.h"
#include "support/cancel_probe.h"
#include "support/same_bits.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;
using std::chrono::milliseconds;
using testing::CancelProbe;
using testing::SameBits;

constexpr milliseconds kDelay(200);  // as in simulation_cancel_test.cc

PropagatorFactory Exact(const DO& model) {
  return [&model] { return std::make_unique<ExactPropagator>(model); };
}

SweepOptions Grid(int steps, SweepDirection direction, int threads, int chunks) {
  SweepOptions o;
  o.param = std::string("b");
  o.min = 0.12, o.max = 0.16, o.steps = steps, o.direction = direction;
  o.transient_periods = 50;
  o.sample_periods = 5;
  o.threads = threads;
  o.chunks = chunks;
  return o;
}

// 2000 values each way of 500 + 100 periods (~15 s on two threads), four workers on two
// directions: the stop flag ends every worker's simulation; Sweep joins them before it returns,
// so the latency covers the last worker's stop.
TEST(SweepCancel, EveryWorkerStopsPromptly) {
  DO model;
  SweepOptions o = Grid(2000, SweepDirection::kBoth, 4, 2);
  o.transient_periods = 500;
  o.sample_periods = 100;
  CancelProbe probe(kDelay);
  const SweepResult r = Sweep(model, Exact(model), testing::ReferenceParams(),
                              DefaultInitialState(model), o, probe.Callback());
  probe.Returned();
  EXPECT_EQ(r.summary.termination, Termination::kCancelled);
  EXPECT_EQ(r.summary.status.code(), StatusCode::kCancelled);
  probe.ExpectPrompt("sweep, 4 threads");
  // Values reached were kept; none after the ones in progress at the stop.
  ASSERT_EQ(r.up.size(), 2000u);
  const auto done = std::count_if(r.up.begin(), r.up.end(), [](const SweepPoint& p) {
    return p.summary.termination == Termination::kCompleted;
  });
  EXPECT_GT(done, 0);
  EXPECT_LT(done, 2000);
  // The summary counts the values simulated, cancelled ones included; a value's own summary
  // says how its simulation ended, and one never reached is failed with no message.
  EXPECT_GE(r.summary.values, done);
  EXPECT_LT(r.summary.values, 4000);
  EXPECT_EQ(r.summary.message, "sweep cancelled");
  for (const SweepPoint& p : r.up) {
    if (p.start == SweepStart::kNotStarted) {
      EXPECT_EQ(p.summary.termination, Termination::kFailed);
      EXPECT_TRUE(p.summary.message.empty()) << p.summary.message;
    } else if (p.summary.completed()) {
      EXPECT_GT(p.summary.segments, 0);
    }
  }
}

// Values of 2^31 - 1 transient periods (and 4 times that at the second chunk's first value,
// which used to overflow 32 bits): each of the four workers (two chunks each way) is inside one
// long simulation when the stop comes.
TEST(SweepCancel, WorkersInsideLongValuesStopPromptly) {
  DO model;
  SweepOptions o = Grid(4, SweepDirection::kBoth, 4, 2);
  o.transient_periods = std::numeric_limits<int32_t>::max();
  ASSERT_TRUE(o.Validate().ok());
  CancelProbe probe(kDelay);
  const SweepResult r = Sweep(model, Exact(model), testing::ReferenceParams(),
                              DefaultInitialState(model), o, probe.Callback());
  probe.Returned();
  EXPECT_EQ(r.summary.termination, Termination::kCancelled);
  for (const std::vector<SweepPoint>* list : {&r.up, &r.down}) {
    ASSERT_EQ(list->size(), 4u);
    EXPECT_EQ((*list)[0].summary.termination, Termination::kCancelled);
    EXPECT_EQ((*list)[2].summary.termination, Termination::kCancelled);  // the second chunk's first
    EXPECT_EQ((*list)[2].transient_periods, int64_t{4} * std::numeric_limits<int32_t>::max());
  }
  probe.ExpectPrompt("sweep, workers in 2^33-period values");
}

TEST(SweepOverflow, TotalPeriodsBeyond64BitsAreRefused) {
  // 1e6 values each way of up to (2^31 - 1) x (2^31 - 1) + 5 periods: ~2^83 in all.
  SweepOptions o = Grid(1000000, SweepDirection::kBoth, 1, 1);
  o.transient_periods = std::numeric_limits<int32_t>::max();
  o.chunk_start_transient_factor = std::numeric_limits<int32_t>::max();
  const Status s = o.Validate();
  EXPECT_EQ(s.code(), StatusCode::kInvalidArgument);
  EXPECT_NE(s.message().find("chunk_start_transient_factor"), std::string::npos) << s.message();
  o.chunk_start_transient_factor = 4;  // 1e6 x 2 x (2^33 + 5) ~ 2^54: honoured
  EXPECT_TRUE(o.Validate().ok()) << o.Validate().ToString();
}

// Streams the sweep `o` and compares with the same sweep accumulated.
void ExpectStreamedEqualsAccumulated(const SweepOptions& o) {
  DO model;
  const Params prm = testing::ReferenceParams();
  const StateVector x0 = DefaultInitialState(model);
  const SweepResult kept = Sweep(model, Exact(model), prm, x0, o);
  ASSERT_EQ(kept.summary.termination, Termination::kCompleted);
  std::vector<SweepPoint> up, down;
  const std::thread::id caller = std::this_thread::get_id();
  bool on_caller = true;
  const SweepResult r = Sweep(
      model, Exact(model), prm, x0, o, {}, {}, [&](SweepDirection d, int index, SweepPoint&& p) {
        on_caller = on_caller && std::this_thread::get_id() == caller;
        std::vector<SweepPoint>& list = d == SweepDirection::kUp ? up : down;
        EXPECT_EQ(index, static_cast<int>(list.size()));
        list.push_back(std::move(p));
        return true;
      });
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.status.ToString();
  EXPECT_TRUE(on_caller);
  EXPECT_TRUE(r.up.empty());
  EXPECT_TRUE(r.down.empty());
  EXPECT_EQ(r.summary.periods, kept.summary.periods);
  ASSERT_EQ(up.size(), kept.up.size());
  ASSERT_EQ(down.size(), kept.down.size());
  for (size_t k = 0; k < up.size(); ++k) EXPECT_TRUE(SameBits(up[k], kept.up[k])) << k;
  for (size_t k = 0; k < down.size(); ++k) EXPECT_TRUE(SameBits(down[k], kept.down[k])) << k;
}

// Three threads, three chunks per direction, and three threads with the default one chunk: the
// values arrive on the calling thread in grid order per direction, equal bit for bit to the
// accumulated ones, and the result lists stay empty.
TEST(SweepStream, ValuesArriveInGridOrderAsAccumulated) {
  for (int chunks : {3, 1}) {
    SCOPED_TRACE(std::to_string(chunks) + " chunks");
    ExpectStreamedEqualsAccumulated(Grid(30, SweepDirection::kBoth, 3, chunks));
  }
}

// A slow consumer (2 ms a value) of one direction in two chunks: without back-pressure the second
// chunk's worker would finish all its values long before the first chunk's are handed over.
// The values finished but not yet handed over stay within 3 x threads (the buffer's bound:
// `threads` waiting ahead, `threads` ready, one in each worker's hand), which the progress
// callback (on the calling thread, fraction = values finished / all) checks throughout.
TEST(SweepStream, BufferStaysBoundedBehindASlowConsumer) {
  DO model;
  const int threads = 2;
  const SweepOptions o = Grid(60, SweepDirection::kUp, threads, 2);
  int delivered = 0;
  long long most_held = 0;
  const SweepResult r = Sweep(
      model, Exact(model), testing::ReferenceParams(), DefaultInitialState(model), o,
      [&](double fraction) {
        const long long finished = std::llround(fraction * 60);
        most_held = std::max(most_held, finished - delivered);
        return true;
      },
      {},
      [&](SweepDirection, int index, SweepPoint&&) {
        EXPECT_EQ(index, delivered);
        ++delivered;
        std::this_thread::sleep_for(milliseconds(2));
        return true;
      });
  ASSERT_EQ(r.summary.termination, Termination::kCompleted);
  EXPECT_EQ(delivered, 60);
  EXPECT_GT(most_held, 0);  // the check saw values in flight
  EXPECT_LE(most_held, 3 * threads);
}

// A consumer that returns false stops the sweep: CANCELLED, and it is called no more.
TEST(SweepStream, AConsumerCanStopTheSweep) {
  DO model;
  const SweepOptions o = Grid(200, SweepDirection::kBoth, 2, 1);
  int calls = 0;
  const SweepResult r =
      Sweep(model, Exact(model), testing::ReferenceParams(), DefaultInitialState(model), o, {}, {},
            [&](SweepDirection, int, SweepPoint&&) { return ++calls < 5; });
  EXPECT_EQ(r.summary.termination, Termination::kCancelled);
  EXPECT_EQ(r.summary.status.code(), StatusCode::kCancelled);
  EXPECT_EQ(calls, 5);
}

}  // namespace
}  // namespace drillbif
