// The drillbif-server binary as a child process of a test: started on free ports of 127.0.0.1
// with the given flags, its log appended to a file, signalled, and waited for with a timeout;
// its peak RSS, submits of any job kind through the generic stub, and waiting for an operation.
//
// The binary's path comes from the build: a test that includes this header is compiled with
// DRILLBIF_SERVER_BINARY (server/CMakeLists.txt).
#ifndef DRILLBIF_TESTS_SUPPORT_SERVER_PROCESS_H_
#define DRILLBIF_TESTS_SUPPORT_SERVER_PROCESS_H_

#include <fcntl.h>
#include <google/protobuf/descriptor.h>
#include <google/protobuf/message.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "jobs/registry.h"
#include "support/generic_call.h"

#ifndef DRILLBIF_SERVER_BINARY
#error "DRILLBIF_SERVER_BINARY must name the drillbif-server executable"
#endif

namespace drillbif::testing {

// How a server process ended (ServerProcess::WaitExit).
struct ServerExit {
  // The wait status (waitpid): WIFEXITED / WEXITSTATUS, WIFSIGNALED / WTERMSIG.
  int status = 0;
  // Time from the last Signal() (or from the start, when none was sent) to the exit. Milliseconds.
  double ms = 0;

  bool exited() const { return WIFEXITED(status); }
  // The exit code, or -1 when a signal ended the process.
  int code() const { return WIFEXITED(status) ? WEXITSTATUS(status) : -1; }
};

// A drillbif-server child process on free ports of 127.0.0.1 (--grpc-port 0 --http-port 0),
// its ports read from --port-file. Killed with SIGKILL when destroyed, if still running.
class ServerProcess {
 public:
  using Clock = std::chrono::steady_clock;

  // Starts the server on the SQLite file `db` with `flags` appended (e.g. {"--workers", "2"});
  // the port file and the log (`log_path()`, appended across restarts) go to `dir`. Returns
  // once the server serves (its port file is written), or after `start_timeout` or an exit
  // before serving with a test failure.
  ServerProcess(const std::string& dir, const std::string& db,
                const std::vector<std::string>& flags = {"--workers", "1"},
                std::chrono::seconds start_timeout = std::chrono::seconds(20))
      : ServerProcess(dir, db, flags, start_timeout, /*must_serve=*/true) {}

  // Starts a server that the test expects to stop before serving (a bad flag or config file):
  // as the constructor, but returns without a test failure when the process exits first, so
  // that the test checks serving() and WaitExit()'s exit code itself. Copy elision returns the
  // process in place.
  static ServerProcess ExpectingEarlyExit(
      const std::string& dir, const std::string& db, const std::vector<std::string>& flags,
      std::chrono::seconds start_timeout = std::chrono::seconds(20)) {
    return ServerProcess(dir, db, flags, start_timeout, /*must_serve=*/false);
  }

  ~ServerProcess() { Kill(SIGKILL); }
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  // Whether the server served: its port file was read at start.
  bool serving() const { return port_ > 0; }

  // Whether the process has not been reaped yet (it may have exited: a zombie counts).
  bool running() const { return pid_ > 0 && !exit_; }

  // Sends `signal` (unless the process was reaped) and notes the time, from which WaitExit
  // measures.
  void Signal(int signal) {
    if (!running()) return;
    signalled_at_ = Clock::now();
    kill(pid_, signal);
  }

  // Waits up to `timeout` for the process to exit and reaps it; nullopt when it still runs.
  // Polls every millisecond, so the time measured is within about a millisecond of the exit.
  std::optional<ServerExit> WaitExit(std::chrono::milliseconds timeout) {
    if (exit_) return exit_;
    if (pid_ <= 0) return std::nullopt;
    const auto give_up = Clock::now() + timeout;
    for (;;) {
      int status = 0;
      const pid_t r = waitpid(pid_, &status, WNOHANG);
      if (r == pid_) {
        exit_ = ServerExit{
            status,
            std::chrono::duration<double, std::milli>(Clock::now() - signalled_at_).count()};
        return exit_;
      }
      if (r < 0 || Clock::now() >= give_up) return std::nullopt;
      std::this_thread::sleep_for(std::chrono::milliseconds(1));
    }
  }

  // Sends `signal` and waits for the exit, however long it takes; returns the wait status.
  int Kill(int signal) {
    Signal(signal);
    if (pid_ > 0 && !exit_) {
      int status = 0;
      waitpid(pid_, &status, 0);
      exit_ = ServerExit{
          status, std::chrono::duration<double, std::milli>(Clock::now() - signalled_at_).count()};
    }
    return exit_ ? exit_->status : 0;
  }

  pid_t pid() const { return pid_; }
  int grpc_port() const { return port_; }
  // The HTTP port (REST, /metrics); 0 when the server did not start.
  int http_port() const { return http_port_; }
  const std::string& log_path() const { return log_path_; }
  std::shared_ptr<grpc::Channel> channel() const { return channel_; }

 private:
  // Starts the server (see the public constructor); an exit before serving is a test failure
  // only when `must_serve`.
  ServerProcess(const std::string& dir, const std::string& db,
                const std::vector<std::string>& flags, std::chrono::seconds start_timeout,
                bool must_serve)
      : log_path_(dir + "/server.log") {
    const std::string port_file = dir + "/port";
    std::filesystem::remove(port_file);
    std::vector<std::string> args = {
        DRILLBIF_SERVER_BINARY, "--grpc-port", "0", "--http-port", "0", "--db", db,
        "--port-file",          port_file};
    args.insert(args.end(), flags.begin(), flags.end());
    // Everything the child needs is made before fork: between fork and exec the child of a
    // multithreaded process may only call async-signal-safe functions (dup2, execv, _exit).
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const int log_fd = open(log_path_.c_str(), O_WRONLY | O_CREAT | O_APPEND | O_CLOEXEC, 0644);
    signalled_at_ = Clock::now();  // WaitExit measures from the start until a signal is sent
    pid_ = fork();
    if (pid_ == 0) {
      if (log_fd >= 0) {
        dup2(log_fd, STDOUT_FILENO);  // dup2 clears O_CLOEXEC on the copies
        dup2(log_fd, STDERR_FILENO);
      }
      execv(argv[0], argv.data());
      _exit(127);
    }
    if (log_fd >= 0) close(log_fd);
    // The port file appears (renamed into place) once the server serves.
    const auto give_up = Clock::now() + start_timeout;
    while (Clock::now() < give_up && !WaitExit(std::chrono::milliseconds(0))) {
      std::ifstream in(port_file);
      if (in >> port_) {
        in >> http_port_;
        break;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    if (must_serve) {
      EXPECT_GT(port_, 0) << "the server did not start; see " << log_path_;
    }
    // A channel even to a server that did not start, so that a test's calls fail with a status
    // rather than on a null channel.
    channel_ = grpc::CreateChannel("127.0.0.1:" + std::to_string(port_),
                                   grpc::InsecureChannelCredentials());
  }

  std::string log_path_;
  pid_t pid_ = -1;
  int port_ = 0;
  int http_port_ = 0;
  Clock::time_point signalled_at_;
  std::optional<ServerExit> exit_;
  std::shared_ptr<grpc::Channel> channel_;
};

// The peak resident set of a process (VmHWM of /proc/PID/status), in bytes; -1 when unreadable.
inline int64_t PeakRssBytes(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) return std::stoll(line.substr(6)) * 1024;  // "... kB"
  }
  return -1;
}

// Submits `request` (of `kind`'s request type) through the kind's Submit rpc, by the generic
// stub: one call for every kind of the registry, without a typed stub method per kind.
inline grpc::Status Submit(const ServerProcess& server, const jobs::JobKindSpec& kind,
                           const google::protobuf::Message& request,
                           google::longrunning::Operation* op) {
  const google::protobuf::Descriptor* type =
      // Through a message of service.proto, so that its descriptors are linked in.
      v1::SubmitSimulateRequest::descriptor()->file()->FindMessageTypeByName(kind.submit_method +
                                                                             "Request");
  if (type == nullptr) return grpc::Status(grpc::StatusCode::INTERNAL, "no submit message");
  std::unique_ptr<google::protobuf::Message> submit(
      google::protobuf::MessageFactory::generated_factory()->GetPrototype(type)->New());
  submit->GetReflection()
      ->MutableMessage(submit.get(), type->FindFieldByName("request"))
      ->CopyFrom(request);
  std::string response;
  grpc::Status s = GenericUnary(server.channel(), "/drillbif.v1.Jobs/" + kind.submit_method,
                                submit->SerializeAsString(), &response);
  if (s.ok() && !op->ParseFromString(response)) {
    return grpc::Status(grpc::StatusCode::INTERNAL, "unparsable operation");
  }
  return s;
}

// A client context whose deadline is `seconds` from now.
inline std::unique_ptr<grpc::ClientContext> ContextWithDeadline(double seconds = 20) {
  auto context = std::make_unique<grpc::ClientContext>();
  context->set_deadline(std::chrono::system_clock::now() +
                        std::chrono::milliseconds(static_cast<int>(seconds * 1000)));
  return context;
}

// GetOperation, expected to succeed.
inline google::longrunning::Operation GetOperation(google::longrunning::Operations::Stub& stub,
                                                   const std::string& name) {
  google::longrunning::GetOperationRequest request;
  request.set_name(name);
  google::longrunning::Operation op;
  auto context = ContextWithDeadline();
  const grpc::Status s = stub.GetOperation(context.get(), request, &op);
  EXPECT_TRUE(s.ok()) << s.error_message();
  return op;
}

// The operation once done (WaitOperation in 5 s slices), or as it is after `seconds` or a failed
// call with a test failure.
inline google::longrunning::Operation WaitDone(google::longrunning::Operations::Stub& stub,
                                               const std::string& name, double seconds = 60) {
  const auto give_up =
      std::chrono::steady_clock::now() + std::chrono::milliseconds(static_cast<int>(seconds * 1e3));
  google::longrunning::Operation op;
  while (std::chrono::steady_clock::now() < give_up) {
    google::longrunning::WaitOperationRequest request;
    request.set_name(name);
    request.mutable_timeout()->set_seconds(5);
    auto context = ContextWithDeadline(10);
    const grpc::Status s = stub.WaitOperation(context.get(), request, &op);
    EXPECT_TRUE(s.ok()) << s.error_message();
    if (!s.ok() || op.done()) return op;
  }
  ADD_FAILURE() << name << " not done after " << seconds << " s";
  return op;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_SERVER_PROCESS_H_
