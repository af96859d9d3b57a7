// Job limits given in a --config file (TOML, the flag names as keys) are the limits the
// drillbif-server binary enforces at submit; a bad limit in the file stops it at start. The
// parsing is main()'s (CLI11 reads the file into the --job-limit flags), so the binary is run.
#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <chrono>
#include <fstream>
#include <optional>
#include <string>
#include <vector>

#include "drillbif/v1/continue.pb.h"
#include "support/server_process.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

using drillbif::testing::ServerExit;
using drillbif::testing::ServerProcess;
using drillbif::testing::Submit;
using drillbif::testing::TempDir;
using google::longrunning::Operation;
using ::testing::HasSubstr;

// A continuation of b with `steps` steps (~20 kB of memory a step, jobs/continue_job.cc).
v1::ContinueRequest Continuation(int steps) {
  v1::ContinueRequest r;
  r.set_param("b");
  r.set_min(0.0);
  r.set_max(0.2);
  r.set_direction(v1::ContinueRequest::INCREASING);
  r.set_max_steps(steps);
  return r;
}

// The flags of a one-worker server that reads `config`, then `more`.
std::vector<std::string> ConfigFlags(const std::string& config,
                                     const std::vector<std::string>& more = {}) {
  std::vector<std::string> flags = {"--workers", "1", "--config", config};
  flags.insert(flags.end(), more.begin(), more.end());
  return flags;
}

std::string WriteConfig(const TempDir& dir, const std::string& text) {
  const std::string path = dir.path() + "/drillbif.toml";
  std::ofstream(path) << text;
  return path;
}

TEST(ConfigLimits, AJobLimitFromTheConfigFileIsEnforcedAtSubmitNamingIt) {
  TempDir dir("drillbif_config_limits");
  // 1 MB of memory admits ~50 steps; the default (1 GB) would admit 50000.
  const std::string config = WriteConfig(dir,
                                         "# drillbif-server flags\n"
                                         "job-limit = [\"continue.memory-bytes=1000000\", "
                                         "\"sweep.seconds=2\"]\n");
  ServerProcess server(dir.path(), dir.path() + "/jobs.db", ConfigFlags(config));
  ASSERT_TRUE(server.serving()) << "see " << server.log_path();
  const jobs::JobKindSpec& cont = *jobs::FindKind("continue");

  Operation op;
  grpc::Status s = Submit(server, cont, Continuation(1000), &op);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_THAT(s.error_message(), HasSubstr("request.max_steps = 1000"));
  EXPECT_THAT(s.error_message(), HasSubstr("above the limit of 1.0 MB (max_memory_bytes of "
                                           "continue jobs)"));
  // Under the configured limit: accepted.
  s = Submit(server, cont, Continuation(20), &op);
  EXPECT_TRUE(s.ok()) << s.error_message();

  // The second limit of the list.
  v1::SweepRequest sweep;
  sweep.set_param("b");
  sweep.set_min(0.0);
  sweep.set_max(0.2);
  sweep.set_steps(1000);  // 1000 values of 600 periods at 1e-5 s and the chunk starts: ~16 s
  s = Submit(server, *jobs::FindKind("sweep"), sweep, &op);
  EXPECT_EQ(s.error_code(), grpc::StatusCode::RESOURCE_EXHAUSTED) << s.error_message();
  EXPECT_THAT(s.error_message(), HasSubstr("max_seconds of sweep jobs"));
}

TEST(ConfigLimits, AFlagOnTheCommandLineOverridesTheConfigFile) {
  TempDir dir("drillbif_config_override");
  const std::string config = WriteConfig(dir, "job-limit = [\"continue.memory-bytes=1000000\"]\n");
  // CLI11: a flag given on the command line replaces the file's value.
  ServerProcess server(dir.path(), dir.path() + "/jobs.db",
                       ConfigFlags(config, {"--job-limit", "continue.memory-bytes=100000000"}));
  ASSERT_TRUE(server.serving()) << "see " << server.log_path();
  Operation op;
  const grpc::Status s = Submit(server, *jobs::FindKind("continue"), Continuation(1000), &op);
  EXPECT_TRUE(s.ok()) << s.error_message();
}

TEST(ConfigLimits, AnUnknownLimitInTheConfigFileStopsTheServerNamingIt) {
  TempDir dir("drillbif_config_bad");
  const std::string config = WriteConfig(dir, "job-limit = [\"continue.bytes=1000\"]\n");
  ServerProcess server =
      ServerProcess::ExpectingEarlyExit(dir.path(), dir.path() + "/jobs.db", ConfigFlags(config));
  EXPECT_FALSE(server.serving());
  // The constructor returned on the exit, so it is reaped without waiting.
  const std::optional<ServerExit> exit = server.WaitExit(std::chrono::milliseconds(0));
  ASSERT_TRUE(exit.has_value()) << "the server still runs; see " << server.log_path();
  EXPECT_EQ(exit->code(), 2);
  std::ifstream log(server.log_path());
  const std::string text((std::istreambuf_iterator<char>(log)), std::istreambuf_iterator<char>());
  EXPECT_THAT(text, HasSubstr("unknown limit 'bytes'"));
}

}  // namespace
}  // namespace drillbif::server
