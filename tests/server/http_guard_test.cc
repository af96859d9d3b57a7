// The HTTP connection guard on socket pairs: a passed deadline shuts the socket down (the peer
// reads end-of-file), a cleared one does not; the peer's close runs the hang-up callback once, and
// not after UnwatchHangup or Remove.
#include "server/http_guard.h"

#include <gtest/gtest.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <atomic>
#include <chrono>
#include <thread>

namespace drillbif::server {
namespace {

using Clock = std::chrono::steady_clock;
using std::chrono::milliseconds;

// A connected pair of stream sockets, closed at the end.
struct SocketPair {
  SocketPair() { EXPECT_EQ(socketpair(AF_UNIX, SOCK_STREAM, 0, fd), 0); }
  ~SocketPair() {
    if (fd[0] >= 0) close(fd[0]);
    if (fd[1] >= 0) close(fd[1]);
  }
  int fd[2] = {-1, -1};
};

// Whether `fd` reads end-of-file within `wait` (the other side was shut down or closed).
bool ReadsEof(int fd, milliseconds wait) {
  pollfd p{fd, POLLIN, 0};
  if (poll(&p, 1, static_cast<int>(wait.count())) <= 0) return false;
  char byte;
  return recv(fd, &byte, 1, MSG_DONTWAIT) == 0;
}

// Waits up to `wait` for `flag`.
bool Eventually(const std::atomic<int>& value, int expected, milliseconds wait) {
  const auto end = Clock::now() + wait;
  while (Clock::now() < end) {
    if (value.load() == expected) return true;
    std::this_thread::sleep_for(milliseconds(2));
  }
  return value.load() == expected;
}

std::unique_ptr<ConnectionGuard> NewGuard() {
  StatusOr<std::unique_ptr<ConnectionGuard>> guard = ConnectionGuard::Start();
  EXPECT_TRUE(guard.ok()) << guard.status().ToString();
  return guard.ok() ? std::move(guard).value() : nullptr;
}

TEST(ConnectionGuard, ShutsTheSocketDownWhenItsDeadlinePasses) {
  auto guard = NewGuard();
  ASSERT_NE(guard, nullptr);
  SocketPair pair;
  const int key = 0;
  guard->Add(&key, pair.fd[0]);
  const auto start = Clock::now();
  guard->SetDeadline(&key, start + milliseconds(100));
  // The bound: 100 ms of deadline plus scheduling on a loaded 2-core machine; a guard that never
  // fires fails after 5 s.
  EXPECT_TRUE(ReadsEof(pair.fd[1], milliseconds(5000)));
  const double ms = std::chrono::duration<double, std::milli>(Clock::now() - start).count();
  EXPECT_GE(ms, 90);  // Not before the deadline (poll's clock may round by a few ms).
  EXPECT_EQ(guard->deadlines_expired(), 1);
  guard->Remove(&key);
}

TEST(ConnectionGuard, AClearedOrMovedDeadlineDoesNotFire) {
  auto guard = NewGuard();
  ASSERT_NE(guard, nullptr);
  SocketPair pair;
  const int key = 0;
  guard->Add(&key, pair.fd[0]);
  guard->SetDeadline(&key, Clock::now() + milliseconds(50));
  guard->SetDeadline(&key, Clock::time_point::max());
  EXPECT_FALSE(ReadsEof(pair.fd[1], milliseconds(300)));
  guard->SetDeadline(&key, Clock::now() + milliseconds(50));
  guard->Remove(&key);  // Forgotten: its deadline goes with it.
  EXPECT_FALSE(ReadsEof(pair.fd[1], milliseconds(300)));
  EXPECT_EQ(guard->deadlines_expired(), 0);
}

TEST(ConnectionGuard, PeerCloseRunsTheHangupCallbackOnce) {
  auto guard = NewGuard();
  ASSERT_NE(guard, nullptr);
  SocketPair pair;
  const int key = 0;
  guard->Add(&key, pair.fd[0]);
  std::atomic<int> calls{0};
  guard->WatchHangup(&key, [&calls] { ++calls; });
  // Data from the peer is not a hang-up.
  ASSERT_EQ(send(pair.fd[1], "x", 1, 0), 1);
  std::this_thread::sleep_for(milliseconds(100));
  EXPECT_EQ(calls.load(), 0);
  close(pair.fd[1]);
  pair.fd[1] = -1;
  EXPECT_TRUE(Eventually(calls, 1, milliseconds(5000)));
  std::this_thread::sleep_for(milliseconds(100));
  EXPECT_EQ(calls.load(), 1);
  EXPECT_EQ(guard->hangups(), 1);
  guard->Remove(&key);
}

TEST(ConnectionGuard, NoCallbackAfterUnwatchOrRemove) {
  auto guard = NewGuard();
  ASSERT_NE(guard, nullptr);
  SocketPair first, second;
  const int key1 = 0, key2 = 0;
  guard->Add(&key1, first.fd[0]);
  guard->Add(&key2, second.fd[0]);
  std::atomic<int> calls{0};
  guard->WatchHangup(&key1, [&calls] { ++calls; });
  guard->WatchHangup(&key2, [&calls] { ++calls; });
  guard->UnwatchHangup(&key1);
  guard->Remove(&key2);
  close(first.fd[1]);
  first.fd[1] = -1;
  close(second.fd[1]);
  second.fd[1] = -1;
  std::this_thread::sleep_for(milliseconds(300));
  EXPECT_EQ(calls.load(), 0);
  guard->Stop();
  guard->Stop();  // Idempotent.
}

}  // namespace
}  // namespace drillbif::server
