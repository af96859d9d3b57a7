// WorkerPropagators: a worker's computation stopped once its result is moot, the workers'
// propagators ready again after it, and Abandon() still final.
#include "curve_tasks.h"

#include <gtest/gtest.h>

#include <chrono>
#include <thread>

#include "drillbif/flow/exact_propagator.h"
#include "drillbif/model/drifting_oscillator.h"

namespace drillbif::internal {
namespace {

// Polls `p` as a long computation does until it is stopped, for at most `limit`: whether it was.
bool PollUntilStopped(Propagator& p, std::chrono::milliseconds limit) {
  const auto end = std::chrono::steady_clock::now() + limit;
  while (std::chrono::steady_clock::now() < end) {
    if (!p.progress()->Continue()) return true;
    std::this_thread::sleep_for(std::chrono::microseconds(100));
  }
  return false;
}

class WorkerPropagatorsTest : public ::testing::Test {
 protected:
  DriftingOscillator model_;
  ExactPropagator own_{model_};
};

TEST_F(WorkerPropagatorsTest, AMootComputationStopsAndItsWorkerGoesOn) {
  WorkerPropagators workers(own_, 2);
  ASSERT_EQ(workers.threads(), 2);
  int looks = 0;
  bool stopped = false;
  const bool finished = workers.UnlessMoot(
      0, [&] { return ++looks == 3; },
      [&] { stopped = PollUntilStopped(workers.at(0), std::chrono::seconds(10)); });
  EXPECT_TRUE(stopped);
  EXPECT_FALSE(finished);
  EXPECT_EQ(looks, 3);
  // Ready for the next computation; the other worker was never stopped.
  EXPECT_FALSE(workers.at(0).stopped());
  EXPECT_FALSE(workers.at(1).stopped());
  // With the test gone, the worker's polls no longer call it.
  EXPECT_FALSE(PollUntilStopped(workers.at(0), std::chrono::milliseconds(20)));
  EXPECT_EQ(looks, 3);
}

TEST_F(WorkerPropagatorsTest, AComputationWhoseResultStaysWantedRunsToItsEnd) {
  WorkerPropagators workers(own_, 2);
  int looks = 0;
  bool stopped = true;
  const bool finished = workers.UnlessMoot(
      1, [&] { return ++looks < 0; },
      [&] { stopped = PollUntilStopped(workers.at(1), std::chrono::milliseconds(20)); });
  EXPECT_TRUE(finished);
  EXPECT_FALSE(stopped);
  EXPECT_GT(looks, 0);  // it was looked at while it ran
}

TEST_F(WorkerPropagatorsTest, AnAbandonedWorkerStaysStoppedAfterAMootStop) {
  WorkerPropagators workers(own_, 2);
  const bool finished = workers.UnlessMoot(
      0,
      [&] {
        workers.Abandon();
        return true;
      },
      [&] { PollUntilStopped(workers.at(0), std::chrono::seconds(10)); });
  EXPECT_FALSE(finished);
  EXPECT_TRUE(workers.at(0).stopped());  // the stage's end decides, not the moot stop
  workers.Resume();
  EXPECT_FALSE(workers.at(0).stopped());
}

TEST_F(WorkerPropagatorsTest, OneThreadRunsOnTheOwnPropagatorWithoutLooking) {
  WorkerPropagators workers(own_, 1);
  ASSERT_EQ(workers.threads(), 1);
  EXPECT_EQ(&workers.at(0), &own_);
  int looks = 0;
  bool ran = false;
  EXPECT_TRUE(workers.UnlessMoot(
      0, [&] { return ++looks > 0; }, [&] { ran = true; }));
  EXPECT_TRUE(ran);
  EXPECT_EQ(looks, 0);
}

}  // namespace
}  // namespace drillbif::internal
