// Structured logs: every line the JSON formatter writes is one JSON object that an independent
// parser (protobuf's JSON to google.protobuf.Struct) reads back, with the message intact however
// it is spelled (quotes, backslashes, newlines, control characters, UTF-8).
#include "server/json_log.h"

#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>
#include <spdlog/logger.h>
#include <spdlog/sinks/ostream_sink.h>

#include <sstream>
#include <string>
#include <vector>

namespace drillbif::server {
namespace {

TEST(JsonLog, EveryLineParsesBackWithItsMessage) {
  std::ostringstream out;
  auto sink = std::make_shared<spdlog::sinks::ostream_sink_mt>(out);
  spdlog::logger logger("test", sink);
  logger.set_formatter(JsonLogFormatter());
  const std::vector<std::string> messages = {
      "job 1f (sweep) started, attempt 1",
      "quote \" backslash \\ slash /",
      "two\nlines\tand a tab\r",
      std::string("control \x01\x1f bytes"),
      "UTF-8: \xce\xbe = 0.05, \xcf\x89 = 0.1",
  };
  for (const std::string& m : messages) logger.warn("{}", m);
  logger.flush();
  std::istringstream lines(out.str());
  std::string line;
  size_t k = 0;
  while (std::getline(lines, line)) {
    ASSERT_LT(k, messages.size());
    google::protobuf::Struct parsed;
    const auto status = google::protobuf::util::JsonStringToMessage(line, &parsed);
    ASSERT_TRUE(status.ok()) << status.ToString() << "\n" << line;
    EXPECT_EQ(parsed.fields().at("msg").string_value(), messages[k]);
    EXPECT_EQ(parsed.fields().at("level").string_value(), "warning");
    EXPECT_FALSE(parsed.fields().at("time").string_value().empty());
    EXPECT_GT(parsed.fields().at("thread").number_value(), 0.0);
    ++k;
  }
  EXPECT_EQ(k, messages.size());
}

}  // namespace
}  // namespace drillbif::server
