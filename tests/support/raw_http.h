// HTTP/1.1 over a raw client socket, for tests that send what an attacker would (bytes no HTTP
// library would produce: lying lengths, floods, invalid UTF-8, one byte at a time), and the
// helpers that read the answer: its status, its body, and the service's JSON error body.
#ifndef DRILLBIF_TESTS_SUPPORT_RAW_HTTP_H_
#define DRILLBIF_TESTS_SUPPORT_RAW_HTTP_H_

#include <arpa/inet.h>
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>
#include <netinet/in.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <set>
#include <string>
#include <string_view>

namespace drillbif::testing {

// A client socket to 127.0.0.1:port that sends exactly what it is given.
class RawConnection {
 public:
  using Clock = std::chrono::steady_clock;

  explicit RawConnection(int port) {
    fd_ = socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in address{};
    address.sin_family = AF_INET;
    address.sin_port = htons(static_cast<uint16_t>(port));
    address.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = connect(fd_, reinterpret_cast<sockaddr*>(&address), sizeof(address)) == 0;
  }
  ~RawConnection() { Close(); }
  RawConnection(const RawConnection&) = delete;
  RawConnection& operator=(const RawConnection&) = delete;

  bool connected() const { return connected_; }

  // Sends all of `data` (false if the server closed meanwhile).
  bool Send(std::string_view data) {
    size_t sent = 0;
    while (sent < data.size()) {
      const ssize_t n = send(fd_, data.data() + sent, data.size() - sent, MSG_NOSIGNAL);
      if (n <= 0) return false;
      sent += static_cast<size_t>(n);
    }
    return true;
  }

  // Reads until `done(received)` holds, the connection closes, or `wait` passes. Returns what
  // arrived; *closed tells whether the server closed the connection.
  template <typename Done>
  std::string ReadUntil(Done done, std::chrono::milliseconds wait, bool* closed = nullptr) {
    const auto end = Clock::now() + wait;
    bool eof = false;
    while (!done(received_)) {
      const auto left =
          std::chrono::duration_cast<std::chrono::milliseconds>(end - Clock::now()).count();
      if (left <= 0) break;
      pollfd p{fd_, POLLIN, 0};
      if (poll(&p, 1, static_cast<int>(left)) <= 0) break;
      char buffer[16384];
      const ssize_t n = recv(fd_, buffer, sizeof(buffer), 0);
      if (n <= 0) {
        eof = true;
        break;
      }
      received_.append(buffer, static_cast<size_t>(n));
    }
    if (closed != nullptr) *closed = eof;
    return received_;
  }

  // Reads one whole response (headers and Content-Length bytes), or what came before the
  // connection closed or `wait` passed.
  std::string ReadResponse(std::chrono::milliseconds wait, bool* closed = nullptr) {
    return ReadUntil([](const std::string& r) { return ResponseComplete(r); }, wait, closed);
  }

  // Whether the server closes the connection within `wait` (reading and dropping what comes).
  bool ClosedWithin(std::chrono::milliseconds wait) {
    bool closed = false;
    ReadUntil([](const std::string&) { return false; }, wait, &closed);
    return closed;
  }

  // Whether nothing is readable now (the answer has not come).
  bool NothingYet() {
    pollfd p{fd_, POLLIN, 0};
    return poll(&p, 1, 0) == 0;
  }

  void Close() {
    if (fd_ >= 0) close(fd_);
    fd_ = -1;
  }

  // Whether `r` holds a whole response with a Content-Length (a streamed answer never is).
  static bool ResponseComplete(const std::string& r) {
    const size_t end = r.find("\r\n\r\n");
    if (end == std::string::npos) return false;
    const size_t at = r.find("Content-Length: ");
    if (at == std::string::npos || at > end) return false;
    return r.size() >= end + 4 + std::stoul(r.substr(at + 16));
  }

 private:
  int fd_ = -1;
  bool connected_ = false;
  std::string received_;
};

// The status code of an HTTP/1.1 response; 0 when `response` is not one.
inline int StatusOf(const std::string& response) {
  if (response.rfind("HTTP/1.1 ", 0) != 0 || response.size() < 12) return 0;
  return std::atoi(response.substr(9, 3).c_str());
}

// What follows the response's headers.
inline std::string BodyOf(const std::string& response) {
  const size_t end = response.find("\r\n\r\n");
  return end == std::string::npos ? std::string() : response.substr(end + 4);
}

// Expects a JSON error body {"code": code, "message", "details": []}; returns the message.
inline std::string ExpectJsonError(const std::string& body, const char* code) {
  google::protobuf::Struct parsed;
  const auto status = google::protobuf::util::JsonStringToMessage(body, &parsed);
  EXPECT_TRUE(status.ok()) << "not JSON: " << body.substr(0, 300);
  std::set<std::string> keys;
  for (const auto& [key, value] : parsed.fields()) keys.insert(key);
  EXPECT_EQ(keys, (std::set<std::string>{"code", "message", "details"})) << body;
  if (parsed.fields().count("code") == 0) return {};
  EXPECT_EQ(parsed.fields().at("code").string_value(), code) << body;
  return parsed.fields().count("message") == 0 ? std::string()
                                               : parsed.fields().at("message").string_value();
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_RAW_HTTP_H_
