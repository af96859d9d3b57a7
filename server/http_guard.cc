#include "server/http_guard.h"

#include <sys/epoll.h>
#include <sys/eventfd.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <vector>

namespace drillbif::server {

StatusOr<std::unique_ptr<ConnectionGuard>> ConnectionGuard::Start() {
  const int epoll_fd = epoll_create1(EPOLL_CLOEXEC);
  if (epoll_fd < 0) {
    return Status(StatusCode::kUnavailable,
                  std::string("HTTP connection guard: epoll_create1: ") + std::strerror(errno));
  }
  const int wake_fd = eventfd(0, EFD_CLOEXEC | EFD_NONBLOCK);
  if (wake_fd < 0) {
    const int error = errno;
    close(epoll_fd);
    return Status(StatusCode::kUnavailable,
                  std::string("HTTP connection guard: eventfd: ") + std::strerror(error));
  }
  epoll_event event{};
  event.events = EPOLLIN;
  event.data.u64 = 0;
  epoll_ctl(epoll_fd, EPOLL_CTL_ADD, wake_fd, &event);
  return std::unique_ptr<ConnectionGuard>(new ConnectionGuard(epoll_fd, wake_fd));
}

ConnectionGuard::ConnectionGuard(int epoll_fd, int wake_fd)
    : epoll_fd_(epoll_fd), wake_fd_(wake_fd), thread_([this] { Loop(); }) {}

ConnectionGuard::~ConnectionGuard() {
  Stop();
  close(wake_fd_);
  close(epoll_fd_);
}

void ConnectionGuard::Add(Key key, int fd) {
  std::lock_guard<std::mutex> lock(mutex_);
  Entry& entry = entries_[key];
  entry = Entry();
  entry.fd = fd;
  entry.token = next_token_++;
  keys_by_token_[entry.token] = key;
}

void ConnectionGuard::SetDeadline(Key key, Clock::time_point deadline) {
  bool sooner = false;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = entries_.find(key);
    if (it == entries_.end()) return;
    sooner = deadline < it->second.deadline;
    it->second.deadline = deadline;
  }
  // The thread may be sleeping towards a later deadline.
  if (sooner) Wake();
}

void ConnectionGuard::WatchHangup(Key key, std::function<void()> on_hangup) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = entries_.find(key);
  if (it == entries_.end()) return;
  Entry& entry = it->second;
  entry.on_hangup = std::move(on_hangup);
  epoll_event event{};
  // EPOLLHUP and EPOLLERR are always reported; one shot: the callback runs once.
  event.events = EPOLLRDHUP | EPOLLONESHOT;
  event.data.u64 = entry.token;
  if (epoll_ctl(epoll_fd_, entry.in_epoll ? EPOLL_CTL_MOD : EPOLL_CTL_ADD, entry.fd, &event) == 0) {
    entry.in_epoll = true;
  }
}

void ConnectionGuard::UnwatchHangup(Key key) {
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = entries_.find(key);
  if (it == entries_.end()) return;
  it->second.on_hangup = nullptr;
  if (it->second.in_epoll) {
    epoll_ctl(epoll_fd_, EPOLL_CTL_DEL, it->second.fd, nullptr);
    it->second.in_epoll = false;
  }
}

void ConnectionGuard::Remove(Key key) {
  std::function<void()> dropped;  // Destroyed outside the lock.
  std::lock_guard<std::mutex> lock(mutex_);
  auto it = entries_.find(key);
  if (it == entries_.end()) return;
  if (it->second.in_epoll) epoll_ctl(epoll_fd_, EPOLL_CTL_DEL, it->second.fd, nullptr);
  dropped = std::move(it->second.on_hangup);
  keys_by_token_.erase(it->second.token);
  entries_.erase(it);
}

void ConnectionGuard::Stop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (stopping_) return;
    stopping_ = true;
  }
  Wake();
  if (thread_.joinable()) thread_.join();
}

void ConnectionGuard::Wake() {
  const uint64_t one = 1;
  [[maybe_unused]] const ssize_t n = write(wake_fd_, &one, sizeof(one));
}

int ConnectionGuard::ExpireLocked(Clock::time_point now) {
  Clock::time_point next = Clock::time_point::max();
  for (auto& [key, entry] : entries_) {
    if (entry.deadline <= now) {
      // The descriptor is still MHD's (Remove comes before its close): a shutdown only makes
      // MHD's next read or write fail, and MHD closes the connection.
      deadlines_expired_.fetch_add(1);  // Counted first: the peer may look at once.
      shutdown(entry.fd, SHUT_RDWR);
      entry.deadline = Clock::time_point::max();
    } else {
      next = std::min(next, entry.deadline);
    }
  }
  if (next == Clock::time_point::max()) return -1;
  const auto wait = std::chrono::ceil<std::chrono::milliseconds>(next - now).count();
  return static_cast<int>(std::clamp<int64_t>(wait, 1, 60'000));
}

void ConnectionGuard::Loop() {
  std::vector<epoll_event> events(64);
  int timeout_ms = -1;
  for (;;) {
    const int n = epoll_wait(epoll_fd_, events.data(), static_cast<int>(events.size()), timeout_ms);
    std::vector<std::function<void()>> callbacks;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (stopping_) return;
      for (int i = 0; i < n; ++i) {
        if (events[i].data.u64 == 0) {
          uint64_t count;
          [[maybe_unused]] const ssize_t r = read(wake_fd_, &count, sizeof(count));
          continue;
        }
        auto key = keys_by_token_.find(events[i].data.u64);
        if (key == keys_by_token_.end()) continue;
        Entry& entry = entries_.at(key->second);
        if (entry.on_hangup) {
          callbacks.push_back(std::move(entry.on_hangup));
          entry.on_hangup = nullptr;
        }
      }
      timeout_ms = ExpireLocked(Clock::now());
    }
    for (auto& callback : callbacks) {
      hangups_.fetch_add(1);
      callback();
    }
  }
}

}  // namespace drillbif::server
