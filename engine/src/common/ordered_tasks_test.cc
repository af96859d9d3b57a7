// OrderedTasks: results in queue order whatever the schedule; one thread computing only when a
// result is taken; two threads computing at once.
#include "ordered_tasks.h"

#include <gtest/gtest.h>

#include <atomic>
#include <chrono>
#include <condition_variable>
#include <mutex>
#include <stdexcept>
#include <thread>
#include <vector>

namespace drillbif::internal {
namespace {

using std::chrono::milliseconds;

TEST(OrderedTasks, ResultsComeInQueueOrderWhateverOrderTheyFinishIn) {
  OrderedTasks<int> tasks(3);
  // The first queued finishes last: 30, 20, 10, 0 ms of work.
  for (int k = 0; k < 4; ++k) {
    tasks.Push([k](int) {
      std::this_thread::sleep_for(milliseconds(30 - 10 * k));
      return k;
    });
  }
  for (int k = 0; k < 4; ++k) EXPECT_EQ(tasks.TakeFront(), k);
  EXPECT_FALSE(tasks.TakeFront().has_value());
}

TEST(OrderedTasks, OneThreadRunsATaskOnlyWhenItsResultIsTaken) {
  std::vector<int> ran;
  OrderedTasks<int> tasks(1);
  tasks.Push([&](int worker) {
    ran.push_back(1);
    return worker;
  });
  tasks.Push([&](int) {
    ran.push_back(2);
    return 0;
  });
  EXPECT_TRUE(ran.empty());
  EXPECT_EQ(tasks.TakeFront(), 0);  // worker 0: the calling thread's resources
  EXPECT_EQ(ran, std::vector<int>{1});
  tasks.DropFront();  // never run
  EXPECT_EQ(ran, std::vector<int>{1});
  EXPECT_EQ(tasks.pending(), 0u);
}

TEST(OrderedTasks, TwoThreadsRunTwoTasksAtOnceOnTwoWorkers) {
  // Each task waits (up to 10 s) until both have started: only two tasks running at the same
  // time on different workers get past it.
  std::mutex m;
  std::condition_variable cv;
  int started = 0;
  std::vector<int> workers;
  auto task = [&](int worker) {
    std::unique_lock<std::mutex> lock(m);
    ++started;
    workers.push_back(worker);
    cv.notify_all();
    return cv.wait_for(lock, std::chrono::seconds(10), [&] { return started == 2; });
  };
  OrderedTasks<bool> tasks(2);
  tasks.Push(task);
  tasks.Push(task);
  EXPECT_EQ(tasks.TakeFront(), true);
  EXPECT_EQ(tasks.TakeFront(), true);
  ASSERT_EQ(workers.size(), 2u);
  EXPECT_NE(workers[0], workers[1]);
}

TEST(OrderedTasks, ATasksExceptionIsRethrownWhereItsResultIsTaken) {
  for (const int threads : {1, 2}) {
    OrderedTasks<int> tasks(threads);
    tasks.Push([](int) -> int { throw std::runtime_error("boom"); });
    tasks.Push([](int) { return 7; });
    EXPECT_THROW(tasks.TakeFront(), std::runtime_error) << threads << " threads";
    EXPECT_EQ(tasks.TakeFront(), 7) << threads << " threads";
  }
}

TEST(OrderedTasks, TheWaitCallbackIsPolledWhileATaskRuns) {
  OrderedTasks<int> tasks(2);
  std::atomic<bool> release{false};
  tasks.Push([&](int) {
    while (!release.load()) std::this_thread::sleep_for(milliseconds(1));
    return 5;
  });
  int polls = 0;
  // The wait releases the task on its third poll: the result comes only after three polls.
  EXPECT_EQ(tasks.TakeFront([&] { release = ++polls >= 3; }, milliseconds(1)), 5);
  EXPECT_GE(polls, 3);
}

TEST(OrderedTasks, DestroyingDropsTasksNotStarted) {
  std::atomic<int> ran{0};
  std::atomic<bool> release{false};
  std::thread releaser;
  {
    OrderedTasks<int> tasks(2);
    // Two tasks hold both workers until after the destructor has begun; the third never starts.
    for (int k = 0; k < 2; ++k) {
      tasks.Push([&](int) {
        ++ran;
        while (!release.load()) std::this_thread::sleep_for(milliseconds(1));
        return 0;
      });
    }
    tasks.Push([&](int) { return ++ran; });
    while (ran.load() < 2) std::this_thread::sleep_for(milliseconds(1));
    releaser = std::thread([&] {
      std::this_thread::sleep_for(milliseconds(20));
      release = true;
    });
    // The destructor clears the queue, then waits for the two running tasks.
  }
  releaser.join();
  EXPECT_EQ(ran.load(), 2);
}

}  // namespace
}  // namespace drillbif::internal
