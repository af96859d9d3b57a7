// A drillbif-server binary run as a child process for tests: its own SQLite file and free ports
// of 127.0.0.1, extra flags, its peak RSS, submits of any kind through the generic stub, and
// waiting for an operation. The binary's path comes from the build (DRILLBIF_SERVER_BINARY,
// server/CMakeLists.txt).
#ifndef DRILLBIF_TESTS_SERVER_CHILD_SERVER_H_
#define DRILLBIF_TESTS_SERVER_CHILD_SERVER_H_

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
#include <fstream>
#include <memory>
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

using google::longrunning::Operation;
using google::protobuf::Message;

// A drillbif-server child process on free ports of 127.0.0.1 with its own SQLite file
// (dir/jobs.db), one worker, and `flags` after those; killed (SIGKILL) when destroyed.
class ServerProcess {
 public:
  ServerProcess(const std::string& dir, const std::vector<std::string>& flags) {
    const std::string port_file = dir + "/port";
    log_ = dir + "/server.log";
    std::vector<std::string> args = {
        DRILLBIF_SERVER_BINARY, "--grpc-port", "0", "--http-port", "0",      "--db",
        dir + "/jobs.db",       "--workers",   "1", "--port-file", port_file};
    args.insert(args.end(), flags.begin(), flags.end());
    // argv and the log file are made before fork: between fork and exec the child of a
    // multithreaded process may only call async-signal-safe functions.
    std::vector<char*> argv;
    for (std::string& a : args) argv.push_back(a.data());
    argv.push_back(nullptr);
    const int log_fd = open(log_.c_str(), O_WRONLY | O_CREAT | O_APPEND, 0644);
    pid_ = fork();
    if (pid_ == 0) {
      if (log_fd >= 0) {
        dup2(log_fd, STDOUT_FILENO);
        dup2(log_fd, STDERR_FILENO);
      }
      execv(argv[0], argv.data());
      _exit(127);
    }
    if (log_fd >= 0) close(log_fd);
    // The port file appears (renamed into place) once the server serves.
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(30);
    while (std::chrono::steady_clock::now() < give_up && port_ == 0) {
      std::ifstream in(port_file);
      if (!(in >> port_)) port_ = 0;
      if (port_ != 0) break;
      int status = 0;
      if (waitpid(pid_, &status, WNOHANG) == pid_) {  // it ended without serving
        exit_code_ = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
        pid_ = -1;
        return;
      }
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
    if (port_ > 0) {
      channel_ = grpc::CreateChannel("127.0.0.1:" + std::to_string(port_),
                                     grpc::InsecureChannelCredentials());
    }
  }
  ~ServerProcess() {
    if (pid_ > 0) {
      kill(pid_, SIGKILL);
      waitpid(pid_, nullptr, 0);
    }
  }
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  bool serving() const { return channel_ != nullptr; }
  // The exit code of a process that ended before serving (128 + the signal if killed); -1 else.
  int exit_code() const { return exit_code_; }
  pid_t pid() const { return pid_; }
  // The file of its stdout and stderr.
  const std::string& log() const { return log_; }
  std::shared_ptr<grpc::Channel> channel() const { return channel_; }

 private:
  pid_t pid_ = -1;
  int port_ = 0;
  int exit_code_ = -1;
  std::string log_;
  std::shared_ptr<grpc::Channel> channel_;
};

// The peak resident set of a process (VmHWM), in bytes; -1 when unreadable.
inline int64_t PeakRssBytes(pid_t pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) return std::stoll(line.substr(6)) * 1024;  // "... kB"
  }
  return -1;
}

// Submits `request` (of `kind`'s request type) through the kind's Submit rpc.
inline grpc::Status Submit(const ServerProcess& server, const jobs::JobKindSpec& kind,
                           const Message& request, Operation* op) {
  const google::protobuf::Descriptor* type =
      // Through a message of service.proto, so that its descriptors are linked in.
      v1::SubmitSimulateRequest::descriptor()->file()->FindMessageTypeByName(kind.submit_method +
                                                                             "Request");
  if (type == nullptr) return grpc::Status(grpc::StatusCode::INTERNAL, "no submit message");
  std::unique_ptr<Message> submit(
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

// Waits (WaitOperation, 5 s at a time) until the operation is done or `seconds` pass.
inline Operation WaitDone(const ServerProcess& server, const std::string& name, int seconds) {
  auto stub = google::longrunning::Operations::NewStub(server.channel());
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(seconds);
  Operation op;
  while (std::chrono::steady_clock::now() < give_up) {
    google::longrunning::WaitOperationRequest request;
    request.set_name(name);
    request.mutable_timeout()->set_seconds(5);
    grpc::ClientContext context;
    context.set_deadline(std::chrono::system_clock::now() + std::chrono::seconds(10));
    const grpc::Status s = stub->WaitOperation(&context, request, &op);
    if (!s.ok()) {
      ADD_FAILURE() << s.error_message();
      return op;
    }
    if (op.done()) return op;
  }
  ADD_FAILURE() << name << " not done within " << seconds << " s";
  return op;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SERVER_CHILD_SERVER_H_
