// Streaming a simulation's outputs to a SimulationSink: the sink receives exactly what the
// accumulating run stores (bit for bit, in order), the result's vectors stay empty however long
// the run, and a sink can stop the run.
#include <gtest/gtest.h>

#include <cstdint>
#include <cstring>
#include <vector>

#include "drillbif/flow/exact_propagator.h"
#include "drillbif/simulate/simulator.h"
#include "problems/drifting_reference.h"
#include "support/same_bits.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;
using testing::SameBits;

// Keeps everything it receives.
class RecordingSink : public SimulationSink {
 public:
  bool OnPoincare(const PoincareSample& s) override {
    poincare.push_back(s);
    return true;
  }
  bool OnEvent(const EventRecord& e) override {
    events.push_back(e);
    return true;
  }
  bool OnPeriodModes(int64_t period, const std::vector<int>& modes) override {
    mode_periods.push_back(period);
    period_modes.push_back(modes);
    return true;
  }
  bool OnTrajectoryPoint(const TrajectoryPoint& p) override {
    trajectory.push_back(p);
    return true;
  }
  std::vector<PoincareSample> poincare;
  std::vector<EventRecord> events;
  std::vector<int64_t> mode_periods;
  std::vector<std::vector<int>> period_modes;
  std::vector<TrajectoryPoint> trajectory;
};

// Counts, keeps nothing; stops after `stop_after` Poincare samples (0: never).
class CountingSink : public SimulationSink {
 public:
  explicit CountingSink(int64_t stop_after = 0) : stop_after_(stop_after) {}
  bool OnPoincare(const PoincareSample&) override {
    ++poincare;
    return stop_after_ == 0 || poincare < stop_after_;
  }
  bool OnEvent(const EventRecord&) override {
    ++events;
    return true;
  }
  bool OnPeriodModes(int64_t, const std::vector<int>&) override {
    ++period_modes;
    return true;
  }
  bool OnTrajectoryPoint(const TrajectoryPoint&) override {
    ++trajectory;
    return true;
  }
  int64_t poincare = 0, events = 0, period_modes = 0, trajectory = 0;

 private:
  int64_t stop_after_;
};

SimulationOptions AllOutputs(int64_t transient, int64_t samples) {
  SimulationOptions o;
  o.transient_periods = transient;
  o.sample_periods = samples;
  o.outputs.measures = true;
  o.outputs.poincare = true;
  o.outputs.events = true;
  o.outputs.modes = true;
  o.outputs.trajectory_dt = 0.7;
  return o;
}

void ExpectSameAsAccumulated(const SimulationOptions& options) {
  DO model;
  ExactPropagator prop(model);
  const Params prm = testing::ReferenceParams();
  const StateVector x0 = DefaultInitialState(model);
  const SimulationResult kept = Simulate(model, prop, prm, x0, options);
  ASSERT_EQ(kept.summary.termination, Termination::kCompleted) << kept.summary.status.ToString();
  RecordingSink sink;
  SimulationOptions streamed = options;
  streamed.sink = &sink;
  const SimulationResult r = Simulate(model, prop, prm, x0, streamed);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.status.ToString();
  // Nothing accumulated; the counters, measures and final state as without the sink.
  EXPECT_TRUE(r.poincare.empty());
  EXPECT_TRUE(r.events.empty());
  EXPECT_TRUE(r.period_modes.empty());
  EXPECT_TRUE(r.trajectory.empty());
  EXPECT_EQ(r.summary.segments, kept.summary.segments);
  EXPECT_EQ(r.summary.events, kept.summary.events);
  ASSERT_EQ(r.measure_means.size(), kept.measure_means.size());
  for (size_t k = 0; k < r.measure_means.size(); ++k) {
    EXPECT_TRUE(SameBits(r.measure_means[k], kept.measure_means[k])) << k;
  }
  EXPECT_TRUE(SameBits(r.final_state, kept.final_state));

  ASSERT_EQ(sink.poincare.size(), kept.poincare.size());
  for (size_t k = 0; k < kept.poincare.size(); ++k) {
    EXPECT_EQ(sink.poincare[k].period, kept.poincare[k].period) << k;
    EXPECT_EQ(sink.poincare[k].mode, kept.poincare[k].mode) << k;
    EXPECT_TRUE(SameBits(sink.poincare[k].x, kept.poincare[k].x)) << k;
  }
  ASSERT_EQ(sink.events.size(), kept.events.size());
  for (size_t k = 0; k < kept.events.size(); ++k) {
    const EventRecord &a = sink.events[k], &b = kept.events[k];
    EXPECT_EQ(a.period, b.period) << k;
    EXPECT_TRUE(SameBits(a.s, b.s) && SameBits(a.t, b.t)) << k;
    EXPECT_EQ(a.guard, b.guard) << k;
    EXPECT_EQ(a.from_mode, b.from_mode) << k;
    EXPECT_EQ(a.to_mode, b.to_mode) << k;
    EXPECT_EQ(a.tangential, b.tangential) << k;
    EXPECT_TRUE(SameBits(a.x, b.x)) << k;
  }
  ASSERT_EQ(sink.period_modes, kept.period_modes);
  ASSERT_EQ(sink.mode_periods.size(), kept.period_modes.size());
  for (size_t k = 0; k < sink.mode_periods.size(); ++k) {
    // The window's k-th period.
    EXPECT_EQ(sink.mode_periods[k], options.transient_periods + static_cast<int64_t>(k));
  }
  ASSERT_EQ(sink.trajectory.size(), kept.trajectory.size());
  for (size_t k = 0; k < kept.trajectory.size(); ++k) {
    EXPECT_TRUE(SameBits(sink.trajectory[k].t, kept.trajectory[k].t)) << k;
    EXPECT_EQ(sink.trajectory[k].mode, kept.trajectory[k].mode) << k;
    EXPECT_TRUE(SameBits(sink.trajectory[k].x, kept.trajectory[k].x)) << k;
  }
}

TEST(SimulationSink, ReceivesExactlyWhatTheRunAccumulates) {
  ExpectSameAsAccumulated(AllOutputs(20, 40));
}

// Without a transient the first mode list starts at the initial state.
TEST(SimulationSink, ReceivesExactlyWhatTheRunAccumulatesWithoutTransient) {
  ExpectSameAsAccumulated(AllOutputs(0, 25));
}

// 20000 window periods: the sink receives one Poincare sample and one mode list per period, four
// events per period (the reference orbit's impact, progression, stick, separation), and the
// result holds none of them.
TEST(SimulationSink, ResultStaysEmptyHoweverLongTheRun) {
  DO model;
  ExactPropagator prop(model);
  CountingSink sink;
  SimulationOptions o = AllOutputs(100, 20000);
  o.outputs.trajectory_dt = 0.0;
  o.sink = &sink;
  const SimulationResult r =
      Simulate(model, prop, testing::ReferenceParams(), DefaultInitialState(model), o);
  ASSERT_EQ(r.summary.termination, Termination::kCompleted) << r.summary.status.ToString();
  EXPECT_EQ(sink.poincare, 20000);
  EXPECT_EQ(sink.period_modes, 20000);
  EXPECT_EQ(sink.events, 4 * 20000);
  EXPECT_EQ(r.poincare.capacity(), 0u);
  EXPECT_EQ(r.events.capacity(), 0u);
  EXPECT_EQ(r.period_modes.capacity(), 0u);
  EXPECT_EQ(r.trajectory.capacity(), 0u);
}

// A sink that returns false stops the run: CANCELLED, and it is called no more.
TEST(SimulationSink, ASinkCanStopTheRun) {
  DO model;
  ExactPropagator prop(model);
  CountingSink sink(/*stop_after=*/10);
  SimulationOptions o = AllOutputs(0, 1000);
  o.sink = &sink;
  const SimulationResult r =
      Simulate(model, prop, testing::ReferenceParams(), DefaultInitialState(model), o);
  EXPECT_EQ(r.summary.termination, Termination::kCancelled);
  EXPECT_EQ(r.summary.status.code(), StatusCode::kCancelled);
  EXPECT_EQ(sink.poincare, 10);
  // The mode list of the period that ended with the tenth sample was handed over before it;
  // after the stop, none.
  EXPECT_EQ(sink.period_modes, 10);
}

}  // namespace
}  // namespace drillbif
