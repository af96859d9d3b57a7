// drillctl's server mode end to end: a real drillbif-server child process (127.0.0.1, port 0,
// a SQLite file in a temp dir, a token) and the drillctl binary run as child processes. Each
// subcommand through --server prints what --local prints (JSON compared byte for byte after the
// wall-time fields are zeroed; CSV, which prints no times, as is), also when the result comes in
// many GetResult pages and when it is larger than gRPC's default 4 MiB message limit; --detach
// then `jobs result` gives the same; `jobs list|get|watch|cancel` work; bad flags, a server-side
// invalid request and a refused token exit 2 with a clear message; an unreachable server exits
// 1; Ctrl-C cancels the job on the server and exits 130; `health` prints SERVING. A second
// server with a throwaway self-signed certificate serves TLS: drillctl reaches it with --tls-ca
// (or DRILLBIF_TLS_CA), and without the certificate fails with a message naming --tls-ca.
// The binaries' paths come from the build (client/CMakeLists.txt: DRILLCTL_BINARY,
// DRILLBIF_SERVER_BINARY).
#include <fcntl.h>
#include <gmock/gmock.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <regex>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/sweep.pb.h"
#include "support/postgres_cluster.h"
#include "support/temp_dir.h"

#ifndef DRILLCTL_BINARY
#error "DRILLCTL_BINARY must name the drillctl executable"
#endif
#ifndef DRILLBIF_SERVER_BINARY
#error "DRILLBIF_SERVER_BINARY must name the drillbif-server executable"
#endif

extern char** environ;

namespace drillbif::client {
namespace {

using ::testing::HasSubstr;
using Args = std::vector<std::string>;

Args Concat(const Args& a, const Args& b) {
  Args out = a;
  out.insert(out.end(), b.begin(), b.end());
  return out;
}

constexpr char kToken[] = "test-token";

std::string ReadFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream text;
  text << in.rdbuf();
  return text.str();
}

// The environment of this process without DRILLBIF_SERVER, DRILLBIF_TOKEN and DRILLBIF_TLS_CA,
// plus `extra` ("NAME=value" entries).
std::vector<std::string> Environment(const Args& extra) {
  std::vector<std::string> env;
  for (char** e = environ; *e != nullptr; ++e) {
    const std::string entry(*e);
    if (entry.rfind("DRILLBIF_SERVER=", 0) == 0 || entry.rfind("DRILLBIF_TOKEN=", 0) == 0 ||
        entry.rfind("DRILLBIF_TLS_CA=", 0) == 0) {
      continue;
    }
    env.push_back(entry);
  }
  env.insert(env.end(), extra.begin(), extra.end());
  return env;
}

std::vector<char*> Pointers(std::vector<std::string>& strings) {
  std::vector<char*> out;
  for (std::string& s : strings) out.push_back(s.data());
  out.push_back(nullptr);
  return out;
}

// Starts `binary args...` with stdout and stderr redirected to files; returns its pid.
pid_t Spawn(const std::string& binary, const Args& args, const Args& env_extra,
            const std::string& out_path, const std::string& err_path) {
  std::vector<std::string> argv_strings{binary};
  argv_strings.insert(argv_strings.end(), args.begin(), args.end());
  std::vector<std::string> env_strings = Environment(env_extra);
  std::vector<char*> argv = Pointers(argv_strings);
  std::vector<char*> envp = Pointers(env_strings);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, out_path.c_str(),
                                   O_WRONLY | O_CREAT | O_TRUNC, 0644);
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err_path.c_str(),
                                   O_WRONLY | O_CREAT | O_TRUNC, 0644);
  pid_t pid = -1;
  const int rc = posix_spawn(&pid, binary.c_str(), &actions, nullptr, argv.data(), envp.data());
  posix_spawn_file_actions_destroy(&actions);
  EXPECT_EQ(rc, 0) << "cannot start " << binary << ": " << std::strerror(rc);
  return rc == 0 ? pid : -1;
}

struct Outcome {
  int exit_code = -1;
  std::string out;
  std::string err;
};

// Waits for a spawned process; exit code, or 128 + signal.
int Reap(pid_t pid) {
  int status = 0;
  if (pid <= 0 || waitpid(pid, &status, 0) != pid) return -1;
  if (WIFEXITED(status)) return WEXITSTATUS(status);
  return WIFSIGNALED(status) ? 128 + WTERMSIG(status) : -1;
}

// A drillbif-server child process on a free port of 127.0.0.1 with a token, one SQLite file,
// and `extra` flags.
class ServerProcess {
 public:
  explicit ServerProcess(const std::string& dir, const Args& extra = {}) : dir_(dir) {
    const std::string port_file = dir + "/port";
    Args args = {"--grpc-port", "0", "--http-port", "0",    "--db",        dir + "/jobs.db",
                 "--workers",   "2", "--token",     kToken, "--port-file", port_file};
    args.insert(args.end(), extra.begin(), extra.end());
    pid_ = Spawn(DRILLBIF_SERVER_BINARY, args, {}, dir + "/server.out", dir + "/server.log");
    // The port file (gRPC port on its first line) appears, renamed into place, once serving.
    const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(20);
    while (std::chrono::steady_clock::now() < give_up) {
      std::ifstream in(port_file);
      if (in >> port_) break;
      std::this_thread::sleep_for(std::chrono::milliseconds(10));
    }
  }
  ~ServerProcess() {
    if (pid_ > 0) {
      kill(pid_, SIGTERM);
      Reap(pid_);
    }
  }
  ServerProcess(const ServerProcess&) = delete;
  ServerProcess& operator=(const ServerProcess&) = delete;

  int port() const { return port_; }
  std::string address() const { return "127.0.0.1:" + std::to_string(port_); }
  std::string log() const { return ReadFile(dir_ + "/server.log"); }

 private:
  std::string dir_;
  pid_t pid_ = -1;
  int port_ = 0;
};

// A server per test process (CTest runs each test in its own process; started in
// SetUpTestSuite, so a whole-binary run shares one): starting one costs ~0.1 s.
class DrillctlServer : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir("drillctl_server");
    server_ = new ServerProcess(dir_->path());
  }
  static void TearDownTestSuite() {
    delete server_;
    delete dir_;
    server_ = nullptr;
    dir_ = nullptr;
  }
  void SetUp() override {
    ASSERT_GT(server_->port(), 0) << "the server did not start:\n" << server_->log();
  }

  // Runs drillctl with `args` (nothing added) and `env` entries; waits for it.
  static Outcome Drillctl(const Args& args, const Args& env = {}) {
    static int serial = 0;
    const std::string stem = dir_->path() + "/drillctl" + std::to_string(++serial);
    const pid_t pid = Spawn(DRILLCTL_BINARY, args, env, stem + ".out", stem + ".err");
    Outcome outcome;
    outcome.exit_code = Reap(pid);
    outcome.out = ReadFile(stem + ".out");
    outcome.err = ReadFile(stem + ".err");
    return outcome;
  }
  // drillctl --server <the server> --token <its token> args...
  static Outcome Remote(const Args& args) {
    Args all{"--server", server_->address(), "--token", kToken};
    all.insert(all.end(), args.begin(), args.end());
    return Drillctl(all);
  }
  static Outcome Local(const Args& args) {
    Args all{"--local"};
    all.insert(all.end(), args.begin(), args.end());
    return Drillctl(all);
  }

  // Runs `args` locally and through the server (with `remote_flags` too); both exit 0 and print
  // the same (wall times zeroed in JSON). Returns the local output.
  static std::string ExpectSameAsLocal(const Args& args, const Args& remote_flags = {}) {
    const Outcome local = Local(args);
    const Outcome remote = Remote(Concat(remote_flags, args));
    EXPECT_EQ(local.exit_code, 0) << local.err;
    EXPECT_EQ(remote.exit_code, 0) << remote.err;
    EXPECT_FALSE(local.out.empty());
    ExpectSameText(WithoutTimes(remote.out), WithoutTimes(local.out));
    return local.out;
  }

  // EXPECT_EQ of two outputs, reporting where they first differ (gtest's diff of megabyte
  // strings takes minutes).
  static void ExpectSameText(const std::string& got, const std::string& want) {
    if (got == want) return;
    const size_t n = std::min(got.size(), want.size());
    size_t at = 0;
    while (at < n && got[at] == want[at]) ++at;
    const size_t from = at < 80 ? 0 : at - 80;
    ADD_FAILURE() << "outputs of " << got.size() << " and " << want.size()
                  << " bytes differ at byte " << at << ":\n got: ..." << got.substr(from, 160)
                  << "\nwant: ..." << want.substr(from, 160);
  }

  // The output with every "...Seconds": value (wallSeconds, traceSeconds, regionSeconds,
  // querySeconds, checkSeconds: run times, which differ between runs) replaced by 0, JSON
  // pretty or compact: "<name>Seconds": 0. (By hand: std::regex takes seconds on megabytes.)
  static std::string WithoutTimes(const std::string& text) {
    static const std::regex name("[A-Za-z]*");
    std::string out;
    out.reserve(text.size());
    size_t copied = 0;
    for (size_t at = text.find("Seconds\":"); at != std::string::npos;
         at = text.find("Seconds\":", at + 1)) {
      const size_t quote = text.rfind('"', at);
      if (quote == std::string::npos ||
          !std::regex_match(text.begin() + quote + 1, text.begin() + at, name)) {
        continue;
      }
      size_t end = at + std::strlen("Seconds\":");
      while (end < text.size() && text[end] == ' ') ++end;
      const size_t number = end;
      while (end < text.size() && std::strchr("-+0123456789.eE", text[end]) != nullptr) ++end;
      if (end == number) continue;
      out.append(text, copied, at - copied).append("Seconds\": 0");
      copied = end;
    }
    out.append(text, copied);
    return out;
  }

  // The operation name on the first line of --detach's output.
  static std::string NameOf(const Outcome& detached) {
    return detached.out.substr(0, detached.out.find('\n'));
  }

  static testing::TempDir* dir_;
  static ServerProcess* server_;
};

testing::TempDir* DrillctlServer::dir_ = nullptr;
ServerProcess* DrillctlServer::server_ = nullptr;

// Small inputs (each well under a second of engine time): 20 simulated periods, a 20-value sweep
// both ways, the b-branch over [0.14, 0.16], and the small trace box of
// tests/support/small_requests.h (omega in [0.05, 0.15], a in [0.25, 0.6]) with a 21 x 21 grid.
const Args kSimulate = {"simulate", "--transient", "20", "--samples", "20"};
const Args kSweep = {"sweep", "--param",     "b",       "--min",     "0.1",
                     "--max", "0.2",         "--steps", "20",        "--direction",
                     "both",  "--transient", "20",      "--samples", "5"};
const Args kContinue = {"continue", "--param", "b", "--min", "0.14", "--max", "0.16"};
const Args kBox = {"--params", "omega,a", "--min", "0.05,0.25", "--max", "0.15,0.6"};

TEST_F(DrillctlServer, SimulatePrintsWhatLocalPrints) {
  ExpectSameAsLocal(Concat(kSimulate, {"--format", "csv"}));
  ExpectSameAsLocal(Concat(kSimulate, {"--events", "--measures"}));
}

TEST_F(DrillctlServer, SweepPrintsWhatLocalPrints) {
  ExpectSameAsLocal(Concat(kSweep, {"--format", "csv"}));
}

TEST_F(DrillctlServer, ContinuePrintsWhatLocalPrints) {
  ExpectSameAsLocal(kContinue);
  ExpectSameAsLocal(Concat(kContinue, {"--format", "csv"}));
}

TEST_F(DrillctlServer, TracePrintsWhatLocalPrints) {
  ExpectSameAsLocal(Concat(Concat({"trace"}, kBox), {"--format", "csv"}));
}

TEST_F(DrillctlServer, OptimumPrintsWhatLocalPrints) {
  const Args optimum =
      Concat(Concat({"optimum"}, kBox), {"--margin", "0.01,0.02", "--grid", "21,21"});
  ExpectSameAsLocal(optimum);
  ExpectSameAsLocal(Concat(optimum, {"--format", "csv"}));
}

TEST_F(DrillctlServer, DetachThenJobsResultPrintsWhatLocalPrints) {
  // A request no other test submits (another direction), so that it really runs.
  const Args request = Concat(kContinue, {"--direction", "increasing"});
  const Outcome detached = Remote(Concat({"--detach"}, request));
  ASSERT_EQ(detached.exit_code, 0) << detached.err;
  const std::string name = NameOf(detached);
  EXPECT_THAT(name, ::testing::MatchesRegex("operations/[0-9a-f]{32}"));

  const Outcome watched = Remote({"jobs", "watch", name});
  EXPECT_EQ(watched.exit_code, 0) << watched.err;
  EXPECT_THAT(watched.out, HasSubstr("\"state\":\"SUCCEEDED\""));

  const Outcome result = Remote({"jobs", "result", name});
  const Outcome local = Local(request);
  ASSERT_EQ(result.exit_code, 0) << result.err;
  EXPECT_EQ(WithoutTimes(result.out), WithoutTimes(local.out));
  // The bare id works too, and CSV is the command's CSV.
  const Outcome csv =
      Remote({"jobs", "result", name.substr(std::strlen("operations/")), "--format", "csv"});
  EXPECT_EQ(csv.out, Local(Concat(request, {"--format", "csv"})).out);
}

TEST_F(DrillctlServer, JobsListGetAndCancel) {
  const Outcome detached = Remote(Concat({"--detach"}, kSimulate));
  ASSERT_EQ(detached.exit_code, 0) << detached.err;
  const std::string name = NameOf(detached);
  ASSERT_EQ(Remote(Concat({"--detach"}, kSweep)).exit_code, 0);

  const Outcome all = Remote({"jobs", "list", "--all", "--format", "csv"});
  ASSERT_EQ(all.exit_code, 0) << all.err;
  EXPECT_THAT(all.out, ::testing::StartsWith("name,kind,state,progress,points,cache_hit,"));
  EXPECT_THAT(all.out, HasSubstr(name + ",simulate,"));

  // Pages of one job: a token to the next page, which lists another job.
  const Outcome first = Remote({"jobs", "list", "--page-size", "1", "--format", "csv"});
  ASSERT_EQ(first.exit_code, 0) << first.err;
  std::smatch token;
  ASSERT_TRUE(std::regex_search(first.out, token, std::regex("# next_page_token=(\\S+)")))
      << first.out;
  const Outcome second =
      Remote({"jobs", "list", "--page-size", "1", "--page-token", token[1].str(), "--compact"});
  ASSERT_EQ(second.exit_code, 0) << second.err;
  EXPECT_THAT(second.out, HasSubstr("\"operations\":[{\"name\":\"operations/"));
  EXPECT_THAT(second.out, HasSubstr("\"nextPageToken\":"));

  const Outcome filtered = Remote({"jobs", "list", "--all", "--kind", "sweep", "--format", "csv"});
  ASSERT_EQ(filtered.exit_code, 0) << filtered.err;
  EXPECT_THAT(filtered.out, ::testing::Not(HasSubstr(",simulate,")));

  const Outcome got = Remote({"jobs", "get", name, "--compact"});
  ASSERT_EQ(got.exit_code, 0) << got.err;
  EXPECT_THAT(got.out, HasSubstr("\"name\":\"" + name + "\""));
  EXPECT_THAT(got.out, HasSubstr("\"@type\":\"type.googleapis.com/drillbif.v1.JobMetadata\""));

  // A long sweep cancelled with `jobs cancel`: CANCELLED, and `jobs result` says it has none.
  const Outcome long_sweep =
      Remote({"--detach", "sweep", "--param", "b", "--min", "0", "--max", "0.2", "--steps",
              "100000", "--samples", "1", "--threads", "1"});
  ASSERT_EQ(long_sweep.exit_code, 0) << long_sweep.err;
  const std::string sweep = NameOf(long_sweep);
  const Outcome cancelled = Remote({"jobs", "cancel", sweep, "--format", "csv"});
  ASSERT_EQ(cancelled.exit_code, 0) << cancelled.err;
  EXPECT_THAT(cancelled.out, HasSubstr(sweep + ",sweep,CANCELLED,"));
  const Outcome no_result = Remote({"jobs", "result", sweep});
  EXPECT_EQ(no_result.exit_code, 1);
  EXPECT_THAT(no_result.err, HasSubstr("was cancelled; it has no result"));

  const Outcome unknown = Remote({"jobs", "get", std::string(32, '0')});
  EXPECT_EQ(unknown.exit_code, 2);
  EXPECT_THAT(unknown.err, HasSubstr("drillctl: invalid input:"));
}

TEST_F(DrillctlServer, CtrlCCancelsTheJobOnTheServerAndExits130) {
  // ~10 s of engine time: interrupted once the server runs it.
  const std::string stem = dir_->path() + "/interrupted";
  const pid_t pid =
      Spawn(DRILLCTL_BINARY,
            {"--server", server_->address(), "--token", kToken, "sweep", "--param", "b", "--min",
             "0", "--max", "0.2", "--steps", "9999", "--threads", "1", "--compact"},
            {}, stem + ".out", stem + ".err");
  const auto give_up = std::chrono::steady_clock::now() + std::chrono::seconds(10);
  bool running = false;
  while (!running && std::chrono::steady_clock::now() < give_up) {
    running = Remote({"jobs", "list", "--all", "--state", "RUNNING", "--format", "csv"})
                  .out.find(",sweep,RUNNING,") != std::string::npos;
    if (!running) std::this_thread::sleep_for(std::chrono::milliseconds(20));
  }
  EXPECT_TRUE(running);
  kill(pid, SIGINT);
  EXPECT_EQ(Reap(pid), 130);
  EXPECT_THAT(ReadFile(stem + ".out"), HasSubstr("\"status\":\"CANCELLED\""));
  EXPECT_THAT(ReadFile(stem + ".err"), HasSubstr("drillctl: interrupted: cancelled on the server"));
  const Outcome cancelled =
      Remote({"jobs", "list", "--all", "--state", "CANCELLED", "--format", "csv"});
  EXPECT_THAT(cancelled.out, HasSubstr(",sweep,CANCELLED,"));
}

TEST_F(DrillctlServer, EnvironmentVariablesNameTheServerAndToken) {
  const Outcome outcome =
      Drillctl(Concat(kSimulate, {"--format", "csv"}),
               {"DRILLBIF_SERVER=" + server_->address(), std::string("DRILLBIF_TOKEN=") + kToken});
  EXPECT_EQ(outcome.exit_code, 0) << outcome.err;
  EXPECT_EQ(outcome.out, Local(Concat(kSimulate, {"--format", "csv"})).out);
}

TEST_F(DrillctlServer, BadFlagsExit2BeforeAnyRpc) {
  const Outcome unknown = Remote({"simulate", "--no-such-flag"});
  EXPECT_EQ(unknown.exit_code, 2);
  EXPECT_THAT(unknown.err, HasSubstr("--no-such-flag"));
  const Outcome both = Remote({"--local", "simulate"});
  EXPECT_EQ(both.exit_code, 2);
  EXPECT_THAT(both.err, HasSubstr("excludes"));
  const Outcome state = Remote({"jobs", "list", "--state", "DONE"});
  EXPECT_EQ(state.exit_code, 2);
  const Outcome local_jobs = Drillctl({"--local", "jobs", "list"});
  EXPECT_EQ(local_jobs.exit_code, 2);
  EXPECT_THAT(local_jobs.err, HasSubstr("drop --local"));
}

TEST_F(DrillctlServer, InvalidRequestExits2AsLocal) {
  // Refused by the job runner on the server (a FAILED operation): the same message as --local.
  const Args args = {"continue", "--param", "b", "--min", "0", "--max", "0.1"};
  const Outcome local = Local(args);
  const Outcome remote = Remote(args);
  EXPECT_EQ(local.exit_code, 2);
  EXPECT_EQ(remote.exit_code, 2);
  EXPECT_EQ(remote.err, local.err);
  // Refused at submit (xi <= 0): exit 2, naming the parameter.
  const Outcome xi = Remote({"simulate", "--xi", "-1"});
  EXPECT_EQ(xi.exit_code, 2);
  EXPECT_THAT(xi.err, HasSubstr("invalid input: "));
  EXPECT_THAT(xi.err, HasSubstr("xi must be > 0"));
}

TEST_F(DrillctlServer, WrongOrMissingTokenExits2WithAClearMessage) {
  const Outcome wrong =
      Drillctl({"--server", server_->address(), "--token", "not-the-token", "simulate"});
  EXPECT_EQ(wrong.exit_code, 2);
  EXPECT_TRUE(wrong.out.empty());
  EXPECT_THAT(wrong.err, HasSubstr("refused the call"));
  EXPECT_THAT(wrong.err, HasSubstr("is not the server's"));
  const Outcome missing = Drillctl({"--server", server_->address(), "jobs", "list"});
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_THAT(missing.err, HasSubstr("pass --token or set DRILLBIF_TOKEN"));
}

TEST_F(DrillctlServer, HealthPrintsServingWithoutAToken) {
  const Outcome outcome = Drillctl({"--server", server_->address(), "health"});
  EXPECT_EQ(outcome.exit_code, 0) << outcome.err;
  EXPECT_EQ(outcome.out, "SERVING\n");
}

// A worker process (--role worker, on a throwaway PostgreSQL store) takes no requests: drillctl
// says so and names what to do, exit 1 as for a server it cannot use.
TEST(DrillctlWorkerProcess, SubmittingToAWorkerSaysToNameAnApiProcess) {
  testing::PostgresCluster cluster;
  ASSERT_TRUE(cluster.ok() && cluster.CreateDatabase("jobs")) << cluster.error();
  testing::TempDir dir("drillctl_worker");
  ServerProcess worker(dir.path(), {"--store", cluster.Uri("jobs"), "--role", "worker"});
  ASSERT_GT(worker.port(), 0) << worker.log();
  const std::string stem = dir.path() + "/drillctl";
  const pid_t pid =
      Spawn(DRILLCTL_BINARY, {"--server", worker.address(), "--token", kToken, "simulate"}, {},
            stem + ".out", stem + ".err");
  EXPECT_EQ(Reap(pid), 1);
  const std::string err = ReadFile(stem + ".err");
  EXPECT_THAT(err, HasSubstr("does not serve this call"));
  EXPECT_THAT(err, HasSubstr("--role worker"));
  EXPECT_THAT(err, HasSubstr("name an API process"));
}

TEST_F(DrillctlServer, UnreachableServerExits1) {
  // Port 1 on 127.0.0.1: nothing listens (connection refused at once).
  const Outcome outcome = Drillctl({"--server", "127.0.0.1:1", "--timeout", "5", "simulate"});
  EXPECT_EQ(outcome.exit_code, 1);
  EXPECT_THAT(outcome.err, HasSubstr("the drillbif server at 127.0.0.1:1 is not available"));
  EXPECT_EQ(Drillctl({"--server", "127.0.0.1:1", "--timeout", "5", "health"}).exit_code, 1);
}

// Results in many GetResult pages (--result-page-size 3, a hidden flag: 3 items a page) print
// what --local prints: a simulation's Poincare samples, events, modes and trajectory (pages cross
// from one output to the next), a sweep both ways (JSON and CSV), a continuation with its
// period-doubled branch (in the first page only; JSON and CSV), a trace with its region, and
// `jobs result` of such a result in pages of 2. (Each kind's CSV in pages: result_printer_test.)
TEST_F(DrillctlServer, ResultsOfManyPagesPrintWhatLocalPrints) {
  const Args pages = {"--result-page-size", "3"};
  const std::string simulate = ExpectSameAsLocal(
      Concat(kSimulate,
             {"--measures", "--poincare", "--events", "--modes", "--trajectory-dt", "20"}),
      pages);
  EXPECT_GT(std::count(simulate.begin(), simulate.end(), '{'), 4 * 3);  // more than 4 pages
  const std::string sweep = ExpectSameAsLocal(kSweep, pages);
  EXPECT_THAT(sweep, HasSubstr("\"down\": [\n  {"));  // 40 values: 14 pages
  ExpectSameAsLocal(Concat(kSweep, {"--format", "csv"}), pages);
  const Args follow_pd = {"continue", "--param",     "b",        "--min", "0.09",
                          "--max",    "0.12",        "--b",      "0.115", "--max-steps",
                          "200",      "--follow-pd", "--compact"};
  const std::string continued = ExpectSameAsLocal(follow_pd, pages);
  EXPECT_THAT(continued, HasSubstr("\"periodDoubledBranch\":{\"status\":\"COMPLETED\""));
  ExpectSameAsLocal(Concat(follow_pd, {"--format", "csv"}), pages);
  ExpectSameAsLocal(Concat(Concat({"trace"}, kBox), {"--grid", "21,21"}), pages);

  const Outcome detached = Remote(Concat({"--detach"}, kSweep));  // done: a cache hit
  ASSERT_EQ(detached.exit_code, 0) << detached.err;
  const Outcome result = Remote({"--result-page-size", "2", "jobs", "result", NameOf(detached)});
  ASSERT_EQ(result.exit_code, 0) << result.err;
  ExpectSameText(WithoutTimes(result.out), WithoutTimes(sweep));
}

// A result of ~9 MB whose two items (sweep values of 130000 Poincare samples, 35 bytes each) are
// ~4.5 MB each: whatever the page size, a GetResult message is larger than gRPC's default 4 MiB
// receive limit. It comes through (in the default pages) as --local prints it.
TEST_F(DrillctlServer, ResultLargerThanFourMegabytesComesThrough) {
  const Args sweep = {"--compact", "sweep",  "--param",   "b", "--min",       "0.15",
                      "--max",     "0.151",  "--steps",   "2", "--transient", "0",
                      "--samples", "130000", "--threads", "2"};
  const Outcome local = Local(sweep);
  ASSERT_EQ(local.exit_code, 0) << local.err;
  v1::SweepResult parsed;
  ASSERT_TRUE(google::protobuf::util::JsonStringToMessage(local.out, &parsed).ok());
  ASSERT_EQ(parsed.up_size(), 2);
  EXPECT_GT(parsed.up(0).ByteSizeLong(), size_t{4} << 20);
  const Outcome remote = Remote(sweep);
  ASSERT_EQ(remote.exit_code, 0) << remote.err;
  ExpectSameText(WithoutTimes(remote.out), WithoutTimes(local.out));
}

// A server with TLS on its gRPC port, from a throwaway self-signed certificate for 127.0.0.1:
// --tls-ca (or DRILLBIF_TLS_CA) with that certificate reaches it; --tls alone (the system's roots
// do not sign it) exits 2 naming --tls-ca; plaintext exits 1 (the server closes the connection)
// saying a TLS server needs --tls; TLS to the plaintext server exits 2; an unreadable CA file
// exits 2 before any rpc.
TEST_F(DrillctlServer, TlsServerNeedsItsCertificate) {
  const std::string dir = dir_->path() + "/tls";
  std::filesystem::create_directories(dir);
  const std::string cert = dir + "/cert.pem";
  const std::string key = dir + "/key.pem";
  const std::string openssl =
      "openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:prime256v1 -nodes -days 2 "
      "-subj /CN=localhost -addext subjectAltName=IP:127.0.0.1,DNS:localhost -keyout " +
      key + " -out " + cert + " 2>/dev/null";
  ASSERT_EQ(std::system(openssl.c_str()), 0) << "openssl (Debian's openssl package) is needed";
  ServerProcess tls(dir, {"--tls-cert", cert, "--tls-key", key});
  ASSERT_GT(tls.port(), 0) << "the TLS server did not start:\n" << tls.log();
  const Args base = {"--server", tls.address(), "--token", kToken, "--timeout", "10"};
  const Args request = Concat(kSimulate, {"--format", "csv"});

  const Outcome verified = Drillctl(Concat(Concat(base, {"--tls-ca", cert}), request));
  EXPECT_EQ(verified.exit_code, 0) << verified.err;
  EXPECT_EQ(verified.out, Local(request).out);
  const Outcome from_env = Drillctl(Concat(base, {"jobs", "list"}), {"DRILLBIF_TLS_CA=" + cert});
  EXPECT_EQ(from_env.exit_code, 0) << from_env.err;
  EXPECT_THAT(from_env.out, HasSubstr("\"operations/"));

  const Outcome roots = Drillctl(Concat(Concat(base, {"--tls"}), request));
  EXPECT_EQ(roots.exit_code, 2);
  EXPECT_TRUE(roots.out.empty());
  EXPECT_THAT(roots.err, HasSubstr("the TLS handshake with the drillbif server at " +
                                   tls.address() + " failed"));
  EXPECT_THAT(roots.err, HasSubstr("give its CA certificate with --tls-ca FILE"));
  const Outcome plain = Drillctl(Concat(base, request));
  EXPECT_EQ(plain.exit_code, 1);
  EXPECT_THAT(plain.err, HasSubstr("a server with TLS needs --tls or --tls-ca FILE"));
  const Outcome to_plaintext = Drillctl(
      Concat({"--server", server_->address(), "--token", kToken, "--tls-ca", cert}, request));
  EXPECT_EQ(to_plaintext.exit_code, 2);
  EXPECT_THAT(to_plaintext.err, HasSubstr("the server does not use TLS"));
  const Outcome missing = Drillctl(Concat(Concat(base, {"--tls-ca", dir + "/none.pem"}), request));
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_THAT(missing.err, HasSubstr("--tls-ca: cannot read " + dir + "/none.pem"));
}

}  // namespace
}  // namespace drillbif::client
