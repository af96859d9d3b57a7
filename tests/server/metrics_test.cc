// The Prometheus exposition (server/metrics.h, on prometheus-cpp) read back by a small parser of
// the text format written here from the format's specification, and the REST gateway's status
// and error mappings (server/rest_gateway.h), without a server.
#include "server/metrics.h"

#include <gmock/gmock.h>
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest-spi.h>
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <thread>
#include <utility>
#include <vector>

#include "drillbif/v1/service.pb.h"
#include "google/rpc/status.pb.h"
#include "server/rest_gateway.h"

namespace drillbif::server {
namespace {

using ::testing::HasSubstr;
using Labels = std::map<std::string, std::string>;

// ---------------------------------------------------------------------------------------------
// A parser of the text format 0.0.4 (https://prometheus.io/docs/instrumenting/exposition_formats/)
// strict enough to catch what a scraper would reject: every line is "# HELP name text",
// "# TYPE name type" or "name{label="value",...} value"; a family's HELP comes before its TYPE,
// its TYPE before its samples, each once, and its samples are contiguous.

struct Sample {
  std::string name;  // With the histogram suffix (_bucket, _sum, _count).
  Labels labels;
  double value = 0;
};

struct FamilyInfo {
  std::string help;
  std::string type;
};

struct Exposition {
  std::vector<std::string> family_order;  // In the text's order.
  std::map<std::string, FamilyInfo> families;
  std::vector<Sample> samples;  // In the text's order.
  std::vector<std::string> errors;
};

bool IsMetricName(std::string_view name) {
  if (name.empty()) return false;
  for (size_t i = 0; i < name.size(); ++i) {
    const char c = name[i];
    const bool letter = (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_' || c == ':';
    if (!letter && !(i > 0 && c >= '0' && c <= '9')) return false;
  }
  return true;
}

std::optional<double> ParseValue(const std::string& text) {
  if (text == "+Inf") return std::numeric_limits<double>::infinity();
  if (text == "-Inf") return -std::numeric_limits<double>::infinity();
  if (text == "NaN") return std::nan("");
  if (text.empty() || text.find_first_not_of("0123456789.eE+-") != std::string::npos) {
    return std::nullopt;
  }
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (end != text.c_str() + text.size()) return std::nullopt;
  return value;
}

// `text` from `pos` on: `{name="value",...}`; advances `pos` past the closing brace.
std::optional<Labels> ParseLabels(std::string_view text, size_t* pos) {
  Labels labels;
  size_t i = *pos + 1;  // After '{'.
  while (i < text.size() && text[i] != '}') {
    const size_t eq = text.find('=', i);
    if (eq == std::string_view::npos || eq + 1 >= text.size() || text[eq + 1] != '"') {
      return std::nullopt;
    }
    const std::string name(text.substr(i, eq - i));
    if (!IsMetricName(name) || name.find(':') != std::string::npos) return std::nullopt;
    std::string value;
    size_t j = eq + 2;
    for (; j < text.size() && text[j] != '"'; ++j) {
      if (text[j] != '\\') {
        value += text[j];
        continue;
      }
      if (++j == text.size()) return std::nullopt;
      if (text[j] == 'n') {
        value += '\n';
      } else if (text[j] == '\\' || text[j] == '"') {
        value += text[j];
      } else {
        return std::nullopt;  // No other escape exists.
      }
    }
    if (j == text.size() || !labels.emplace(name, value).second) return std::nullopt;
    i = j + 1;
    if (i < text.size() && text[i] == ',') ++i;
  }
  if (i == text.size()) return std::nullopt;
  *pos = i + 1;
  return labels;
}

// The family a sample belongs to: its name, or for a histogram's series the name without the
// suffix.
std::string FamilyOf(const Exposition& e, const std::string& name) {
  for (std::string_view suffix : {"_bucket", "_sum", "_count"}) {
    if (name.size() > suffix.size() && name.ends_with(suffix)) {
      const std::string base = name.substr(0, name.size() - suffix.size());
      auto it = e.families.find(base);
      if (it != e.families.end() && it->second.type == "histogram") return base;
    }
  }
  return name;
}

void ParseLine(const std::string& line, Exposition* e) {
  auto fail = [&](const char* why) { e->errors.push_back(std::string(why) + ": '" + line + "'"); };
  if (line.starts_with("# HELP ") || line.starts_with("# TYPE ")) {
    const bool help = line[2] == 'H';
    const size_t space = line.find(' ', 7);
    const std::string name = line.substr(7, space == std::string::npos ? space : space - 7);
    const std::string rest = space == std::string::npos ? "" : line.substr(space + 1);
    if (!IsMetricName(name) || rest.empty()) return fail("malformed HELP or TYPE");
    if (help) {
      if (e->families.count(name) != 0) return fail("HELP twice");
      e->families[name].help = rest;
      e->family_order.push_back(name);
      return;
    }
    if (e->families.count(name) == 0 || e->family_order.back() != name) {
      return fail("TYPE not right after its HELP");
    }
    if (!e->families[name].type.empty()) return fail("TYPE twice");
    for (const char* type : {"counter", "gauge", "histogram", "summary", "untyped"}) {
      if (rest == type) {
        e->families[name].type = rest;
        return;
      }
    }
    return fail("unknown TYPE");
  }
  if (line.empty() || line[0] == '#') return fail("empty line or other comment");
  Sample sample;
  size_t pos = line.find_first_of("{ ");
  if (pos == std::string::npos) return fail("no value");
  sample.name = line.substr(0, pos);
  if (!IsMetricName(sample.name)) return fail("bad metric name");
  if (line[pos] == '{') {
    std::optional<Labels> labels = ParseLabels(line, &pos);
    if (!labels) return fail("bad labels");
    sample.labels = std::move(*labels);
  }
  if (pos >= line.size() || line[pos] != ' ') return fail("no space before the value");
  std::optional<double> value = ParseValue(line.substr(pos + 1));
  if (!value) return fail("bad value");
  sample.value = *value;
  const std::string family = FamilyOf(*e, sample.name);
  if (e->family_order.empty() || e->family_order.back() != family ||
      e->families[family].type.empty()) {
    return fail("sample outside its family's block (or before its TYPE)");
  }
  e->samples.push_back(std::move(sample));
}

Exposition Parse(const std::string& text) {
  Exposition e;
  if (text.empty() || text.back() != '\n') e.errors.push_back("text does not end with a newline");
  size_t start = 0;
  while (start < text.size()) {
    size_t end = text.find('\n', start);
    if (end == std::string::npos) end = text.size();
    ParseLine(text.substr(start, end - start), &e);
    start = end + 1;
  }
  return e;
}

// The value of the one sample `name` with exactly `labels`; nullopt when there is none.
std::optional<double> Value(const Exposition& e, std::string_view name, const Labels& labels = {}) {
  std::optional<double> found;
  for (const Sample& s : e.samples) {
    if (s.name != name || s.labels != labels) continue;
    EXPECT_FALSE(found.has_value()) << "two samples " << name;
    found = s.value;
  }
  return found;
}

// Samples of family-level name `name` (any labels).
int SeriesCount(const Exposition& e, std::string_view name) {
  int n = 0;
  for (const Sample& s : e.samples) n += s.name == name ? 1 : 0;
  return n;
}

// Every histogram series: "le" increasing and ending at +Inf, counts cumulative (never
// decreasing), the +Inf bucket equal to _count, and a _sum.
void ExpectHistogramsWellFormed(const Exposition& e) {
  for (const auto& [name, info] : e.families) {
    if (info.type != "histogram") continue;
    std::map<Labels, std::vector<std::pair<double, double>>> buckets;  // series -> (le, count)
    for (const Sample& s : e.samples) {
      if (s.name != name + "_bucket") continue;
      Labels series = s.labels;
      auto le = series.find("le");
      ASSERT_NE(le, series.end()) << name << " bucket without le";
      std::optional<double> bound = ParseValue(le->second);
      ASSERT_TRUE(bound.has_value()) << le->second;
      series.erase(le);
      buckets[series].emplace_back(*bound, s.value);
    }
    for (const auto& [series, list] : buckets) {
      ASSERT_FALSE(list.empty());
      for (size_t i = 1; i < list.size(); ++i) {
        EXPECT_LT(list[i - 1].first, list[i].first) << name << ": le in increasing order";
        EXPECT_LE(list[i - 1].second, list[i].second) << name << ": cumulative";
      }
      EXPECT_EQ(list.back().first, std::numeric_limits<double>::infinity()) << name;
      EXPECT_EQ(Value(e, name + "_count", series), list.back().second) << name;
      EXPECT_TRUE(Value(e, name + "_sum", series).has_value()) << name;
    }
  }
}

// Parses `text` and expects no error and well-formed histograms.
Exposition ParseValid(const std::string& text) {
  Exposition e = Parse(text);
  EXPECT_THAT(e.errors, ::testing::IsEmpty()) << text;
  ExpectHistogramsWellFormed(e);
  return e;
}

// ---------------------------------------------------------------------------------------------

TEST(MetricsParser, RejectsMalformedText) {
  // The parser must be able to fail, or the tests below prove nothing.
  EXPECT_FALSE(Parse("x 1").errors.empty()) << "no final newline";
  EXPECT_FALSE(Parse("x 1\n").errors.empty()) << "sample without HELP and TYPE";
  EXPECT_FALSE(Parse("# TYPE x gauge\nx 1\n").errors.empty()) << "no HELP";
  EXPECT_FALSE(Parse("# HELP x h\n# TYPE x gauge\nx{a=\"b} 1\n").errors.empty());
  EXPECT_FALSE(Parse("# HELP x h\n# TYPE x gauge\nx{a=\"\\q\"} 1\n").errors.empty());
  EXPECT_FALSE(Parse("# HELP x h\n# TYPE x gauge\nx one\n").errors.empty());
  EXPECT_FALSE(Parse("# HELP x two\nlines\n# TYPE x gauge\nx 1\n").errors.empty());
  EXPECT_FALSE(
      Parse("# HELP x h\n# TYPE x gauge\n# HELP y h\n# TYPE y gauge\nx 1\n").errors.empty())
      << "sample outside its family's block";
  const Exposition ok = Parse("# HELP x h\n# TYPE x gauge\nx{a=\"q\\\"\\n\\\\\",b=\"\"} -1.5e3\n");
  EXPECT_THAT(ok.errors, ::testing::IsEmpty());
  EXPECT_EQ(Value(ok, "x", {{"a", "q\"\n\\"}, {"b", ""}}), -1500);
}

// Histograms the check must refuse, one fault each (EXPECT_NONFATAL_FAILURE wants exactly one).
const char kDecreasingBuckets[] =
    "# HELP h x\n# TYPE h histogram\nh_bucket{le=\"1\"} 2\nh_bucket{le=\"+Inf\"} 1\n"
    "h_count 1\nh_sum 1\n";
const char kNoInfBucket[] =
    "# HELP h x\n# TYPE h histogram\nh_bucket{le=\"1\"} 1\nh_bucket{le=\"2\"} 1\n"
    "h_count 1\nh_sum 1\n";
const char kInfBucketIsNotTheCount[] =
    "# HELP h x\n# TYPE h histogram\nh_bucket{le=\"1\"} 1\nh_bucket{le=\"+Inf\"} 2\n"
    "h_count 1\nh_sum 1\n";

TEST(MetricsParser, HistogramCheckRefusesBadBuckets) {
  EXPECT_NONFATAL_FAILURE(ExpectHistogramsWellFormed(Parse(kDecreasingBuckets)), "cumulative");
  EXPECT_NONFATAL_FAILURE(ExpectHistogramsWellFormed(Parse(kNoInfBucket)), "infinity");
  EXPECT_NONFATAL_FAILURE(ExpectHistogramsWellFormed(Parse(kInfBucketIsNotTheCount)), "_count");
}

TEST(Metrics, RendersTheSnapshotAsGaugesAndCounters) {
  Metrics metrics;
  MetricsSnapshot snapshot;
  snapshot.stats.jobs_by_state = {3, 1, 10, 2, 4};
  snapshot.stats.queue_depth = 9;
  snapshot.stats.queue_depth_by_lane = {6, 3};
  snapshot.stats.cache_hits_total = 7;
  snapshot.stats.used_bytes = 3'000'000'123;  // Above 2^31: no 32-bit truncation.
  snapshot.engine_runs = 12;
  snapshot.watchers = 5;
  snapshot.store_healthy = true;
  const std::string text = metrics.Render(snapshot);
  const Exposition e = ParseValid(text);

  const std::map<std::string, std::string> types = {{"drillbif_jobs", "gauge"},
                                                    {"drillbif_queue_depth", "gauge"},
                                                    {"drillbif_cache_hits_total", "counter"},
                                                    {"drillbif_engine_runs_total", "counter"},
                                                    {"drillbif_watchers", "gauge"},
                                                    {"drillbif_store_healthy", "gauge"},
                                                    {"drillbif_store_bytes", "gauge"}};
  for (const auto& [name, type] : types) {
    ASSERT_EQ(e.families.count(name), 1u) << name;
    EXPECT_EQ(e.families.at(name).type, type) << name;
    EXPECT_GT(e.families.at(name).help.size(), 10u) << name;
  }
  EXPECT_EQ(Value(e, "drillbif_jobs", {{"state", "QUEUED"}}), 3);
  EXPECT_EQ(Value(e, "drillbif_jobs", {{"state", "RUNNING"}}), 1);
  EXPECT_EQ(Value(e, "drillbif_jobs", {{"state", "SUCCEEDED"}}), 10);
  EXPECT_EQ(Value(e, "drillbif_jobs", {{"state", "FAILED"}}), 2);
  EXPECT_EQ(Value(e, "drillbif_jobs", {{"state", "CANCELLED"}}), 4);
  EXPECT_EQ(SeriesCount(e, "drillbif_jobs"), 5);
  EXPECT_EQ(Value(e, "drillbif_queue_depth", {{"lane", "short"}}), 6);
  EXPECT_EQ(Value(e, "drillbif_queue_depth", {{"lane", "long"}}), 3);
  EXPECT_EQ(SeriesCount(e, "drillbif_queue_depth"), 2) << "one series a lane, no total";
  EXPECT_EQ(Value(e, "drillbif_cache_hits_total"), 7);
  EXPECT_EQ(Value(e, "drillbif_engine_runs_total"), 12);
  EXPECT_EQ(Value(e, "drillbif_watchers"), 5);
  EXPECT_EQ(Value(e, "drillbif_store_healthy"), 1);
  EXPECT_EQ(Value(e, "drillbif_store_bytes"), 3'000'000'123.0);
  // The snapshot's families come first, in the header's order.
  ASSERT_GE(e.family_order.size(), 7u);
  EXPECT_EQ(e.family_order[0], "drillbif_jobs");
  EXPECT_EQ(e.family_order[6], "drillbif_store_bytes");

  snapshot.store_healthy = false;
  EXPECT_EQ(Value(ParseValid(metrics.Render(snapshot)), "drillbif_store_healthy"), 0);
  EXPECT_EQ(Value(ParseValid(metrics.Render(MetricsSnapshot())), "drillbif_store_healthy"), 0)
      << "unhealthy unless the snapshot says otherwise";
}

TEST(Metrics, JobDurationsAreACumulativeHistogramByKindAndOutcome) {
  MetricsOptions options;
  options.job_duration_buckets = {0.125, 1, 10};
  ASSERT_TRUE(options.Validate().ok());
  Metrics metrics(options);
  // Binary fractions, so that the sum is exact whatever the order of additions.
  metrics.ObserveJob("sweep", "succeeded", 0.0625);
  metrics.ObserveJob("sweep", "succeeded", 0.125);  // On a bound: in that bucket ("le").
  metrics.ObserveJob("sweep", "succeeded", 5);
  metrics.ObserveJob("sweep", "succeeded", 48);  // Above every bound: +Inf only.
  metrics.ObserveJob("sweep", "cancelled", 0.5);
  metrics.ObserveJob("simulate", "deadline_exceeded", 2);  // Any outcome string is a label.
  const Exposition e = ParseValid(metrics.Render({}));
  ASSERT_EQ(e.families.count("drillbif_job_duration_seconds"), 1u);
  EXPECT_EQ(e.families.at("drillbif_job_duration_seconds").type, "histogram");

  const std::string bucket = "drillbif_job_duration_seconds_bucket";
  auto at = [&](const char* kind, const char* outcome, const char* le) {
    return Value(e, bucket, {{"kind", kind}, {"outcome", outcome}, {"le", le}});
  };
  // Counted by hand: observations <= each bound.
  EXPECT_EQ(at("sweep", "succeeded", "0.125"), 2);
  EXPECT_EQ(at("sweep", "succeeded", "1"), 2);
  EXPECT_EQ(at("sweep", "succeeded", "10"), 3);
  EXPECT_EQ(at("sweep", "succeeded", "+Inf"), 4);
  const Labels succeeded = {{"kind", "sweep"}, {"outcome", "succeeded"}};
  EXPECT_EQ(Value(e, "drillbif_job_duration_seconds_sum", succeeded), 53.1875);
  EXPECT_EQ(Value(e, "drillbif_job_duration_seconds_count", succeeded), 4);
  EXPECT_EQ(at("sweep", "cancelled", "0.125"), 0);
  EXPECT_EQ(at("sweep", "cancelled", "1"), 1);
  EXPECT_EQ(at("simulate", "deadline_exceeded", "1"), 0);
  EXPECT_EQ(at("simulate", "deadline_exceeded", "10"), 1);
  EXPECT_EQ(Value(e, "drillbif_job_duration_seconds_count",
                  {{"kind", "simulate"}, {"outcome", "deadline_exceeded"}}),
            1);
  EXPECT_EQ(SeriesCount(e, bucket), 3 * 4) << "three series of three bounds and +Inf";
}

TEST(Metrics, NonFiniteOrNegativeDurationsCountAsZero) {
  MetricsOptions options;
  options.job_duration_buckets = {1};
  Metrics metrics(options);
  metrics.ObserveJob("sweep", "failed", std::nan(""));
  metrics.ObserveJob("sweep", "failed", std::numeric_limits<double>::infinity());
  metrics.ObserveJob("sweep", "failed", -3);
  const Exposition e = ParseValid(metrics.Render({}));
  const Labels failed = {{"kind", "sweep"}, {"outcome", "failed"}};
  EXPECT_EQ(Value(e, "drillbif_job_duration_seconds_count", failed), 3);
  EXPECT_EQ(Value(e, "drillbif_job_duration_seconds_sum", failed), 0);
  EXPECT_EQ(Value(e, "drillbif_job_duration_seconds_bucket",
                  {{"kind", "sweep"}, {"outcome", "failed"}, {"le", "1"}}),
            3);
}

TEST(Metrics, CountsRequestsByLabels) {
  Metrics metrics;
  metrics.CountHttpRequest("POST", "/v1/jobs:sweep", 200);
  metrics.CountHttpRequest("POST", "/v1/jobs:sweep", 200);
  metrics.CountHttpRequest("POST", "/v1/jobs:sweep", 400);
  metrics.CountGrpcRequest("/drillbif.v1.Jobs/SubmitSweep", 0);
  metrics.CountGrpcRequest("/drillbif.v1.Jobs/SubmitSweep", 3);
  metrics.CountGrpcRequest("/drillbif.v1.Jobs/SubmitSweep", 3);
  metrics.CountGrpcRequest("/drillbif.v1.Jobs/SubmitSweep", 99);
  const Exposition e = ParseValid(metrics.Render({}));
  EXPECT_EQ(e.families.at("drillbif_http_requests_total").type, "counter");
  EXPECT_EQ(e.families.at("drillbif_grpc_requests_total").type, "counter");
  EXPECT_EQ(Value(e, "drillbif_http_requests_total",
                  {{"method", "POST"}, {"route", "/v1/jobs:sweep"}, {"code", "200"}}),
            2);
  EXPECT_EQ(Value(e, "drillbif_http_requests_total",
                  {{"method", "POST"}, {"route", "/v1/jobs:sweep"}, {"code", "400"}}),
            1);
  const std::string submit = "/drillbif.v1.Jobs/SubmitSweep";
  EXPECT_EQ(Value(e, "drillbif_grpc_requests_total", {{"method", submit}, {"code", "OK"}}), 1);
  EXPECT_EQ(
      Value(e, "drillbif_grpc_requests_total", {{"method", submit}, {"code", "INVALID_ARGUMENT"}}),
      2);
  EXPECT_EQ(Value(e, "drillbif_grpc_requests_total", {{"method", submit}, {"code", "UNKNOWN"}}), 1)
      << "a code outside 0..16";
}

TEST(Metrics, LabelValuesFromOutsideStayBounded) {
  Metrics metrics;
  for (const char* method : {"BREW", "get", "", "GET\"x"}) {
    metrics.CountHttpRequest(method, "other", 405);
  }
  metrics.CountHttpRequest("GET", "other", 42);
  metrics.CountHttpRequest("GET", "other", 600);
  metrics.CountHttpRequest("OPTIONS", "other", 404);
  for (const char* method : {"/made.Up/Method", "/drillbif.v1.Jobs/NoSuchMethod",
                             "/drillbif.v1.Jobs", "/drillbif.v1.Jobs/", "", "/",
                             "drillbif.v1.Jobs/SubmitSweep", "/drillbif.v1.JobMetadata/name"}) {
    metrics.CountGrpcRequest(method, 12);
  }
  metrics.CountGrpcRequest("/grpc.health.v1.Health/Check", 0);
  metrics.CountGrpcRequest("/google.longrunning.Operations/GetOperation", 0);
  const Exposition e = ParseValid(metrics.Render({}));
  EXPECT_EQ(Value(e, "drillbif_http_requests_total",
                  {{"method", "other"}, {"route", "other"}, {"code", "405"}}),
            4);
  EXPECT_EQ(Value(e, "drillbif_http_requests_total",
                  {{"method", "GET"}, {"route", "other"}, {"code", "other"}}),
            2);
  EXPECT_EQ(Value(e, "drillbif_http_requests_total",
                  {{"method", "OPTIONS"}, {"route", "other"}, {"code", "404"}}),
            1);
  EXPECT_EQ(SeriesCount(e, "drillbif_http_requests_total"), 3);
  EXPECT_EQ(
      Value(e, "drillbif_grpc_requests_total", {{"method", "other"}, {"code", "UNIMPLEMENTED"}}),
      8);
  EXPECT_EQ(Value(e, "drillbif_grpc_requests_total",
                  {{"method", "/grpc.health.v1.Health/Check"}, {"code", "OK"}}),
            1);
  EXPECT_EQ(Value(e, "drillbif_grpc_requests_total",
                  {{"method", "/google.longrunning.Operations/GetOperation"}, {"code", "OK"}}),
            1);
  EXPECT_EQ(SeriesCount(e, "drillbif_grpc_requests_total"), 3);
}

TEST(Metrics, CountsRefusalsAndEvictions) {
  Metrics metrics;
  // Eviction counters exist from the start, at 0 (a first sample for rate()).
  Exposition e = ParseValid(metrics.Render({}));
  EXPECT_EQ(e.families.at("drillbif_store_evicted_jobs_total").type, "counter");
  EXPECT_EQ(e.families.at("drillbif_store_evicted_bytes_total").type, "counter");
  EXPECT_EQ(Value(e, "drillbif_store_evicted_jobs_total"), 0);
  EXPECT_EQ(Value(e, "drillbif_store_evicted_bytes_total"), 0);

  metrics.CountAdmissionRefusal("sweep", "queue_full");
  metrics.CountAdmissionRefusal("sweep", "queue_full");
  metrics.CountAdmissionRefusal("simulate", "invalid_argument");
  metrics.CountAdmissionRefusal("trace", "resource_exhausted");
  metrics.CountEvictions(3, 4096);
  metrics.CountEvictions(2, 5'000'000'000);  // Above 2^32 bytes.
  metrics.CountEvictions(-1, -5);            // Ignored: a counter never decreases.
  metrics.CountEvictions(0, 0);
  e = ParseValid(metrics.Render({}));
  EXPECT_EQ(e.families.at("drillbif_jobs_refused_total").type, "counter");
  EXPECT_EQ(Value(e, "drillbif_jobs_refused_total", {{"kind", "sweep"}, {"reason", "queue_full"}}),
            2);
  EXPECT_EQ(Value(e, "drillbif_jobs_refused_total",
                  {{"kind", "simulate"}, {"reason", "invalid_argument"}}),
            1);
  EXPECT_EQ(Value(e, "drillbif_jobs_refused_total",
                  {{"kind", "trace"}, {"reason", "resource_exhausted"}}),
            1);
  EXPECT_EQ(SeriesCount(e, "drillbif_jobs_refused_total"), 3);
  EXPECT_EQ(Value(e, "drillbif_store_evicted_jobs_total"), 5);
  EXPECT_EQ(Value(e, "drillbif_store_evicted_bytes_total"), 5'000'004'096.0);
}

// Every sample of a counter (and every histogram series, whose buckets, count and sum are
// counters) in `before` is in `after` with a value at least as large.
void ExpectMonotonic(const Exposition& before, const Exposition& after) {
  for (const Sample& s : before.samples) {
    const std::string family = FamilyOf(before, s.name);
    const std::string& type = before.families.at(family).type;
    if (type != "counter" && type != "histogram") continue;
    const std::optional<double> later = Value(after, s.name, s.labels);
    ASSERT_TRUE(later.has_value()) << s.name << " disappeared";
    EXPECT_GE(*later, s.value) << s.name;
  }
}

TEST(Metrics, CountersAreMonotonicAcrossRenders) {
  Metrics metrics;
  MetricsSnapshot snapshot;
  snapshot.stats.cache_hits_total = 4;
  snapshot.engine_runs = 2;
  metrics.ObserveJob("sweep", "succeeded", 0.3);
  metrics.CountHttpRequest("GET", "/v1/operations", 200);
  metrics.CountGrpcRequest("/drillbif.v1.Jobs/SubmitSweep", 0);
  metrics.CountAdmissionRefusal("sweep", "queue_full");
  metrics.CountEvictions(1, 10);
  const Exposition first = ParseValid(metrics.Render(snapshot));
  const Exposition again = ParseValid(metrics.Render(snapshot));
  ExpectMonotonic(first, again);
  EXPECT_EQ(first.samples.size(), again.samples.size());

  metrics.ObserveJob("sweep", "succeeded", 20);
  metrics.CountHttpRequest("GET", "/v1/operations", 200);
  metrics.CountEvictions(1, 10);
  const Exposition later = ParseValid(metrics.Render(snapshot));
  ExpectMonotonic(first, later);
  EXPECT_EQ(Value(later, "drillbif_http_requests_total",
                  {{"method", "GET"}, {"route", "/v1/operations"}, {"code", "200"}}),
            2);
  EXPECT_EQ(Value(later, "drillbif_store_evicted_bytes_total"), 20);
  EXPECT_EQ(Value(later, "drillbif_job_duration_seconds_count",
                  {{"kind", "sweep"}, {"outcome", "succeeded"}}),
            2);
}

TEST(Metrics, EscapesLabelValues) {
  Metrics metrics;
  const std::string route = "odd\"ro\\ute\nend";
  metrics.CountHttpRequest("GET", route, 200);
  const std::string text = metrics.Render({});
  EXPECT_THAT(text, HasSubstr(R"(route="odd\"ro\\ute\nend")"));
  const Exposition e = ParseValid(text);
  EXPECT_EQ(Value(e, "drillbif_http_requests_total",
                  {{"method", "GET"}, {"route", route}, {"code", "200"}}),
            1)
      << "reads back as the original value";
}

// Four threads count events while a fifth renders: every render parses, with well-formed
// histograms and counters that never go back; the totals at the end are exact. Run under
// -fsanitize=thread to check for data races.
TEST(Metrics, ConcurrentEventsAndRenders) {
  constexpr int kThreads = 4;
  constexpr int kEvents = 2000;
  MetricsOptions options;
  options.job_duration_buckets = {0.25, 0.5, 1};
  Metrics metrics(options);
  std::atomic<bool> rendering{false};
  std::atomic<bool> done{false};
  int renders = 0;
  std::thread renderer([&] {
    std::optional<Exposition> previous;
    while (true) {
      const bool last = done.load();
      Exposition e = ParseValid(metrics.Render({}));
      if (previous) ExpectMonotonic(*previous, e);
      previous = std::move(e);
      ++renders;
      rendering = true;
      if (last) break;
    }
  });
  std::vector<std::thread> workers;
  for (int t = 0; t < kThreads; ++t) {
    workers.emplace_back([&metrics, &rendering] {
      while (!rendering.load()) std::this_thread::yield();
      for (int i = 0; i < kEvents; ++i) {
        // Multiples of 0.25: the sum is exact in any order of additions.
        metrics.ObserveJob("sweep", i % 2 == 0 ? "succeeded" : "failed", 0.25 * (i % 4));
        metrics.CountHttpRequest("GET", "/v1/operations", 200);
        metrics.CountGrpcRequest("/drillbif.v1.Jobs/SubmitSweep", 0);
        metrics.CountAdmissionRefusal("sweep", "queue_full");
        metrics.CountEvictions(1, 10);
      }
    });
  }
  for (std::thread& w : workers) w.join();
  done = true;
  renderer.join();
  EXPECT_GE(renders, 2);

  // Expected totals, computed from the loop above.
  double succeeded_sum = 0;
  double failed_sum = 0;
  for (int i = 0; i < kEvents; ++i) (i % 2 == 0 ? succeeded_sum : failed_sum) += 0.25 * (i % 4);
  const Exposition e = ParseValid(metrics.Render({}));
  const double n = kThreads * kEvents;
  EXPECT_EQ(Value(e, "drillbif_http_requests_total",
                  {{"method", "GET"}, {"route", "/v1/operations"}, {"code", "200"}}),
            n);
  EXPECT_EQ(Value(e, "drillbif_grpc_requests_total",
                  {{"method", "/drillbif.v1.Jobs/SubmitSweep"}, {"code", "OK"}}),
            n);
  EXPECT_EQ(Value(e, "drillbif_jobs_refused_total", {{"kind", "sweep"}, {"reason", "queue_full"}}),
            n);
  EXPECT_EQ(Value(e, "drillbif_store_evicted_jobs_total"), n);
  EXPECT_EQ(Value(e, "drillbif_store_evicted_bytes_total"), 10 * n);
  const Labels succeeded = {{"kind", "sweep"}, {"outcome", "succeeded"}};
  const Labels failed = {{"kind", "sweep"}, {"outcome", "failed"}};
  EXPECT_EQ(Value(e, "drillbif_job_duration_seconds_count", succeeded), n / 2);
  EXPECT_EQ(Value(e, "drillbif_job_duration_seconds_count", failed), n / 2);
  EXPECT_EQ(Value(e, "drillbif_job_duration_seconds_sum", succeeded), kThreads * succeeded_sum);
  EXPECT_EQ(Value(e, "drillbif_job_duration_seconds_sum", failed), kThreads * failed_sum);
}

TEST(MetricsOptions, ValidateRefusesBadBuckets) {
  EXPECT_TRUE(MetricsOptions().Validate().ok());
  MetricsOptions options;
  options.job_duration_buckets = {};
  EXPECT_THAT(options.Validate().message(), HasSubstr("job_duration_buckets"));
  options.job_duration_buckets = {1, 1};
  EXPECT_THAT(options.Validate().message(), HasSubstr("job_duration_buckets[1]"));
  options.job_duration_buckets = {0};
  EXPECT_FALSE(options.Validate().ok());
  options.job_duration_buckets = {1, std::numeric_limits<double>::infinity()};
  EXPECT_FALSE(options.Validate().ok());
}

TEST(RestMapping, HttpStatusOfEachGrpcCode) {
  using grpc::StatusCode;
  EXPECT_EQ(HttpStatusOf(StatusCode::OK), 200);
  EXPECT_EQ(HttpStatusOf(StatusCode::INVALID_ARGUMENT), 400);
  EXPECT_EQ(HttpStatusOf(StatusCode::FAILED_PRECONDITION), 400);
  EXPECT_EQ(HttpStatusOf(StatusCode::UNAUTHENTICATED), 401);
  EXPECT_EQ(HttpStatusOf(StatusCode::PERMISSION_DENIED), 403);
  EXPECT_EQ(HttpStatusOf(StatusCode::NOT_FOUND), 404);
  EXPECT_EQ(HttpStatusOf(StatusCode::ALREADY_EXISTS), 409);
  EXPECT_EQ(HttpStatusOf(StatusCode::ABORTED), 409);
  EXPECT_EQ(HttpStatusOf(StatusCode::RESOURCE_EXHAUSTED), 429);
  EXPECT_EQ(HttpStatusOf(StatusCode::UNAVAILABLE), 503);
  EXPECT_EQ(HttpStatusOf(StatusCode::DEADLINE_EXCEEDED), 504);
  EXPECT_EQ(HttpStatusOf(StatusCode::INTERNAL), 500);
  EXPECT_EQ(HttpStatusOf(StatusCode::UNKNOWN), 500);
  EXPECT_EQ(HttpStatusOf(StatusCode::DATA_LOSS), 500);
  EXPECT_STREQ(GrpcCodeName(16), "UNAUTHENTICATED");
  EXPECT_STREQ(GrpcCodeName(17), "UNKNOWN");
}

TEST(RestMapping, ErrorJsonHasCodeNameMessageAndDetails) {
  EXPECT_EQ(ErrorJson(grpc::Status(grpc::StatusCode::NOT_FOUND, "no \"such\" job\n")),
            R"({"code":"NOT_FOUND","message":"no \"such\" job\n","details":[]})");
  // Details of a google.rpc.Status carried by the status, in the Any JSON mapping.
  google::rpc::Status rich;
  rich.set_code(3);
  v1::JobMetadata detail;
  detail.set_name("operations/x");
  rich.add_details()->PackFrom(detail);
  const std::string json =
      ErrorJson(grpc::Status(grpc::StatusCode::INVALID_ARGUMENT, "bad", rich.SerializeAsString()));
  EXPECT_EQ(
      json,
      R"({"code":"INVALID_ARGUMENT","message":"bad","details":[{"@type":"type.googleapis.com/drillbif.v1.JobMetadata","name":"operations/x"}]})");
  google::protobuf::Struct parsed;
  EXPECT_TRUE(google::protobuf::util::JsonStringToMessage(json, &parsed).ok());
}

}  // namespace
}  // namespace drillbif::server
