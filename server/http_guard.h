// ConnectionGuard: what libmicrohttpd's event loop does not do for the REST gateway's
// connections, on one thread of its own:
//
// - Deadlines that span many reads or writes. MHD's connection timeout restarts at every byte
//   (a client sending one byte per second never reaches it); a deadline here is absolute: when it
//   passes, the guard shuts the socket down (shutdown(2), not close: MHD still owns the
//   descriptor) and MHD, seeing the socket fail, closes the connection and frees its memory.
// - Noticing a client that hangs up while its connection is suspended. MHD does not watch a
//   suspended connection at all, and a connection stays suspended while its call into the
//   services runs or its event stream waits for the next change; the guard watches the socket
//   for the peer's close (EPOLLRDHUP, EPOLLHUP, EPOLLERR) and runs the connection's hang-up
//   callback once, which cancels the call.
//
// Connections are identified by an opaque key (the MHD connection) and carry their socket. Remove
// must be called before the socket is closed (MHD's connection-closed notification comes
// first), so that the guard never touches a descriptor number that was reused.
#ifndef DRILLBIF_SERVER_HTTP_GUARD_H_
#define DRILLBIF_SERVER_HTTP_GUARD_H_

#include <atomic>
#include <chrono>
#include <cstdint>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <unordered_map>

#include "drillbif/common/status.h"

namespace drillbif::server {

// The guard. Thread-safe.
class ConnectionGuard {
 public:
  using Key = const void*;
  using Clock = std::chrono::steady_clock;

  // Starts the thread. UNAVAILABLE when epoll or eventfd cannot be created (out of descriptors).
  static StatusOr<std::unique_ptr<ConnectionGuard>> Start();

  // Stop().
  ~ConnectionGuard();

  ConnectionGuard(const ConnectionGuard&) = delete;
  ConnectionGuard& operator=(const ConnectionGuard&) = delete;

  // Starts guarding the connection `key` whose socket is `fd` (no deadline, no watch yet).
  void Add(Key key, int fd);

  // Sets the connection's deadline (Clock::time_point::max(): none). When it passes, the socket
  // is shut down in both directions.
  void SetDeadline(Key key, Clock::time_point deadline);

  // Runs `on_hangup` once, on the guard's thread, when the peer closes or resets the socket,
  // unless UnwatchHangup or Remove comes first. Replaces a previous watch.
  void WatchHangup(Key key, std::function<void()> on_hangup);

  // Stops watching for the peer's close (the callback will not run).
  void UnwatchHangup(Key key);

  // Forgets the connection. Call before its socket is closed.
  void Remove(Key key);

  // Deadlines that passed so far (each shut a socket down).
  int64_t deadlines_expired() const { return deadlines_expired_.load(); }

  // Hang-ups seen so far (each ran a callback).
  int64_t hangups() const { return hangups_.load(); }

  // Joins the thread; callbacks no longer run. Idempotent.
  void Stop();

 private:
  struct Entry {
    int fd = -1;
    uint64_t token = 0;  // epoll's data: never reused, unlike keys and descriptors.
    Clock::time_point deadline = Clock::time_point::max();
    std::function<void()> on_hangup;
    bool in_epoll = false;
  };

  ConnectionGuard(int epoll_fd, int wake_fd);
  void Loop();
  void Wake();
  // Shuts down the sockets whose deadline passed; returns how long to wait for the next one.
  int ExpireLocked(Clock::time_point now);

  const int epoll_fd_;
  const int wake_fd_;
  std::mutex mutex_;
  std::unordered_map<Key, Entry> entries_;
  std::unordered_map<uint64_t, Key> keys_by_token_;
  uint64_t next_token_ = 1;  // 0 is the wake descriptor's.
  bool stopping_ = false;
  std::atomic<int64_t> deadlines_expired_{0};
  std::atomic<int64_t> hangups_{0};
  std::thread thread_;
};

}  // namespace drillbif::server

#endif  // DRILLBIF_SERVER_HTTP_GUARD_H_
