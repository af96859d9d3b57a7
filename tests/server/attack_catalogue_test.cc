// The attack catalogue: a real server (Server::Start, 127.0.0.1, ports 0, a tokens file of three
// clients) given bad and hostile inputs over REST and gRPC, each with the answer it must get:
// malformed and mistyped JSON, NaN / Infinity / 1e309 / -0 / huge integers in every numeric field
// of every kind's request, model parameters outside their domain, overflowing counts, work too
// large to admit, invalid UTF-8 everywhere, header floods, long request lines, oversize, lying,
// doubled and chunked bodies, bad page tokens and sizes, unknown names, paths and methods, missing
// and wrong tokens, garbage bytes to every gRPC method, a slowloris and a lying Content-Length cut
// at the request deadline while the catalogue is served, 32 event streams of a queued job while
// /metrics and a small simulate answer, and one client at its queue cap while another submits.
//
// Every REST answer is checked for its status, and, except where libmicrohttpd answers by itself
// before the gateway runs (kServerOwn below), for the {code, message, details} JSON body with a
// message naming the field; no answer is a 500 or mentions SQL. Afterwards the server must still
// be healthy: gRPC health SERVING, /metrics with a healthy store, a 3 + 3-period simulate
// SUCCEEDED, and the process's peak memory grown by less than a bound derived below.
//
// `--gtest_also_run_disabled_tests --gtest_filter='*PrintTable*'` prints the catalogue as the
// markdown table of docs/service.md ("Attack catalogue").
#include <gmock/gmock.h>
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <grpcpp/grpcpp.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <cctype>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "drillbif/v1/service.grpc.pb.h"
#include "google/longrunning/operations.grpc.pb.h"
#include "server/grpc_calls.h"
#include "server/server.h"
#include "support/generic_call.h"
#include "support/metrics_samples.h"
#include "support/raw_http.h"
#include "support/small_requests.h"
#include "support/temp_dir.h"

namespace drillbif::server {
namespace {

using Clock = std::chrono::steady_clock;
using drillbif::testing::BodyOf;
using drillbif::testing::ExpectJsonError;
using drillbif::testing::RawConnection;
using drillbif::testing::StatusOf;
using drillbif::testing::TempDir;
using google::longrunning::Operation;
using std::chrono::milliseconds;
using ::testing::HasSubstr;

// The clients of the tokens file: the catalogue's own, and two that share the queue.
constexpr char kToken[] = "catalogue-0123456789abcdef";
constexpr char kAliceToken[] = "alice-0123456789abcdef";
constexpr char kBobToken[] = "bob-0123456789abcdef";
// Each client's queue cap (ServerOptions::max_queued_per_client).
constexpr int kPerClientCap = 2;
// The request deadline (RestOptions::request_timeout_ms): short, so that the slowloris is cut
// within the test; every other request is sent whole at once and needs milliseconds.
constexpr int kRequestDeadlineMs = 2000;

// The longest error message: the server cuts messages after kMaxStatusMessageBytes and marks
// the cut with "...".
constexpr size_t kMaxMessageBytes = kMaxStatusMessageBytes + 3;
// Strings a message would echo whole: beyond what a gRPC client takes in its trailers (8 KiB).
constexpr size_t kLongEcho = 100000;

double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

// A field of /proc/self/status in KiB (VmRSS, VmHWM).
long ProcStatusKib(const char* field) {
  std::ifstream in("/proc/self/status");
  std::string line;
  const std::string prefix = std::string(field) + ":";
  while (std::getline(in, line)) {
    if (line.rfind(prefix, 0) == 0) return std::atol(line.c_str() + prefix.size());
  }
  return -1;
}

// ---------------------------------------------------------------------------------------------
// REST requests as raw bytes.

std::string Auth(const std::string& token = kToken) {
  return "Authorization: Bearer " + token + "\r\n";
}

std::string Get(const std::string& target, const std::string& headers = Auth()) {
  return "GET " + target + " HTTP/1.1\r\nHost: x\r\n" + headers + "\r\n";
}

std::string Post(const std::string& path, const std::string& body,
                 const std::string& headers = Auth()) {
  return "POST " + path + " HTTP/1.1\r\nHost: x\r\n" + headers +
         "Content-Type: application/json\r\nContent-Length: " + std::to_string(body.size()) +
         "\r\n\r\n" + body;
}

// How a REST case must be answered.
enum class Answer {
  kJson,       // the gateway's or the services' JSON error body: {code, message, details}
  kServerOwn,  // libmicrohttpd's own answer (its HTML body), before the gateway is called
  kClosed,     // no answer: libmicrohttpd closes a connection that does not speak HTTP/1.x
};

struct RestCase {
  std::string group;    // the docs table's row
  std::string name;     // what is sent, in words
  std::string request;  // the bytes sent
  int status;           // expected HTTP status
  std::string code;     // expected gRPC code name in the body (kJson)
  std::string names;    // a substring the message must contain (the field, value or limit)
  Answer answer = Answer::kJson;
};

// A case of the numeric-field matrix: `value` (a JSON token) at `path` of the kind's base request.
struct Base {
  std::string kind;  // simulate, sweep, ...
  std::string json;  // a valid request body with the placeholder string "@" somewhere
};

// Replaces the JSON path `path` (dotted, "[0]" for list items) of `json` by the raw token
// `value`: the path is set to a marker string in a google.protobuf.Struct, printed, and the
// marker's quotes and all replaced.
std::string WithValue(const std::string& json, const std::string& path, const std::string& value) {
  google::protobuf::Value root;
  EXPECT_TRUE(google::protobuf::util::JsonStringToMessage(json, &root).ok()) << json;
  google::protobuf::Value* at = &root;
  std::stringstream parts(path);
  std::string part;
  while (std::getline(parts, part, '.')) {
    int index = -1;
    if (const size_t bracket = part.find('['); bracket != std::string::npos) {
      index = std::atoi(part.c_str() + bracket + 1);
      part = part.substr(0, bracket);
    }
    at = &(*at->mutable_struct_value()->mutable_fields())[part];
    if (index >= 0) {
      auto* list = at->mutable_list_value();
      while (list->values_size() <= index) list->add_values()->set_number_value(0.5);
      at = list->mutable_values(index);
    }
  }
  at->set_string_value("@@value@@");
  std::string out;
  EXPECT_TRUE(google::protobuf::util::MessageToJsonString(root, &out).ok());
  out.replace(out.find("\"@@value@@\""), 11, value);
  return out;
}

// The last component of a dotted path, in snake_case ("request.params.trajectoryDt" ->
// "trajectory_dt"), without a list index.
std::string FieldName(const std::string& path) {
  std::string last = path.substr(path.rfind('.') + 1);
  last = last.substr(0, last.find('['));
  std::string out;
  for (char c : last) {
    if (std::isupper(static_cast<unsigned char>(c))) {
      out += '_';
      out += static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    } else {
      out += c;
    }
  }
  return out;
}

// The last component of a dotted path as JSON spells it, without a list index.
std::string JsonName(const std::string& path) {
  const std::string last = path.substr(path.rfind('.') + 1);
  return last.substr(0, last.find('['));
}

const std::string kTraceJson =
    R"({"traceParams": ["omega", "a"], "min": [0.05, 0.25], "max": [0.15, 0.6]})";

// Valid requests of each kind, small enough that an accepted one (a catalogue failure) would not
// hold the workers for long.
std::map<std::string, std::string> BaseRequests() {
  return {
      {"simulate", R"({"request": {"transientPeriods": 3, "samplePeriods": 3}})"},
      {"sweep", R"({"request": {"param": "b", "min": 0.1, "max": 0.2, "steps": 5}})"},
      {"continue", R"({"request": {"param": "b", "min": 0.14, "max": 0.16}})"},
      {"trace", R"({"request": )" + kTraceJson + "}"},
      {"optimum", R"({"request": {"trace": )" + kTraceJson + R"(, "margin": [0.01, 0.02]}})"},
  };
}

// The floating-point fields of each kind's request (JSON paths below the body).
std::map<std::string, std::vector<std::string>> DoubleFields() {
  const std::vector<std::string> params = {"params.a",  "params.b", "params.omega",
                                           "params.xi", "params.g", "params.phi0"};
  const std::vector<std::string> state = {"initialState.p", "initialState.y", "initialState.q",
                                          "initialState.s"};
  std::map<std::string, std::vector<std::string>> fields;
  const auto with = [&](std::vector<std::string> own, bool model) {
    std::vector<std::string> all;
    if (model) {
      for (const auto& p : params) all.push_back("request." + p);
      for (const auto& s : state) all.push_back("request." + s);
    }
    for (const auto& o : own) all.push_back("request." + o);
    return all;
  };
  fields["simulate"] = with({"outputs.trajectoryDt", "cvodeRtol"}, true);
  fields["sweep"] = with({"min", "max"}, true);
  fields["continue"] =
      with({"min", "max", "initialStep", "minStep", "maxStep", "locateTolerance"}, true);
  fields["trace"] = with({"min[0]", "max[1]", "seeds[0]"}, true);
  fields["optimum"] = with({"margin[0]", "trace.min[1]", "trace.params.xi"}, false);
  return fields;
}

// The integer fields of each kind's request.
std::map<std::string, std::vector<std::string>> IntFields() {
  return {
      {"simulate", {"request.transientPeriods", "request.samplePeriods"}},
      {"sweep",
       {"request.steps", "request.transientPeriods", "request.samplePeriods", "request.threads"}},
      {"continue", {"request.maxSteps", "request.targetIterations", "request.transientPeriods"}},
      {"trace", {"request.transientPeriods", "request.maxPeriod"}},
      {"optimum", {"request.grid[0]"}},
  };
}

// `queued_op` names a job that stays queued, `done_op` one that succeeded.
std::vector<RestCase> RestCatalogue(const std::string& queued_op, const std::string& done_op) {
  std::vector<RestCase> cases;
  const auto add = [&](std::string group, std::string name, std::string request, int status,
                       std::string code, std::string names, Answer answer = Answer::kJson) {
    cases.push_back({std::move(group), std::move(name), std::move(request), status, std::move(code),
                     std::move(names), answer});
  };
  const std::string kIA = "INVALID_ARGUMENT";
  const std::string kRE = "RESOURCE_EXHAUSTED";
  const std::map<std::string, std::string> base = BaseRequests();
  const auto submit = [&](const std::string& kind, const std::string& body) {
    return Post("/v1/jobs:" + kind, body);
  };

  // Malformed JSON, wrong types, unknown fields.
  const std::string g1 = "malformed or mistyped JSON";
  add(g1, "truncated object", submit("simulate", R"({"request": {)"), 400, kIA, "body");
  add(g1, "not JSON at all", submit("simulate", "hello"), 400, kIA, "body");
  add(g1, "a JSON array", submit("sweep", "[1, 2]"), 400, kIA, "body");
  add(g1, "trailing garbage", submit("simulate", "{} x"), 400, kIA, "body");
  add(g1, "bare NaN token", submit("simulate", R"({"request": {"params": {"xi": NaN}}})"), 400, kIA,
      "body");
  add(g1, "string for a number", submit("simulate", R"({"request": {"params": {"xi": "lots"}}})"),
      400, kIA, "xi");
  add(g1, "object for a number", submit("sweep", R"({"request": {"param": "b", "min": {"x": 1}}})"),
      400, kIA, "min");
  add(g1, "number for a string", submit("sweep", R"({"request": {"param": 7}})"), 400, kIA,
      "param");
  add(g1, "list for a message", submit("simulate", R"({"request": [1]})"), 400, kIA, "request");
  add(g1, "unknown field", submit("simulate", R"({"request": {"samplePeriodz": 3}})"), 400, kIA,
      "samplePeriodz");
  add(g1, "unknown top-level field", submit("trace", R"({"reqest": {}})"), 400, kIA, "reqest");
  add(g1, "unknown enum name", submit("simulate", R"({"request": {"propagator": "WARP"}})"), 400,
      kIA, "propagator");
  add(g1, "unknown enum number", submit("simulate", R"({"request": {"propagator": 99}})"), 400, kIA,
      "propagator");
  add(g1, "deeply nested JSON",
      submit("simulate", std::string(20000, '[') + std::string(20000, ']')), 400, kIA, "body");
  add(g1, "3 MB request_id (read, parsed, refused)",
      submit("simulate", R"({"requestId": ")" + std::string(3 << 20, 'r') + "\"}"), 400, kIA,
      "request_id");

  // NaN, infinities and 1e309 in every floating-point field of every kind.
  for (const auto& [kind, paths] : DoubleFields()) {
    for (const std::string& path : paths) {
      for (const char* value : {"\"NaN\"", "\"Infinity\"", "\"-Infinity\""}) {
        add("NaN, Infinity, 1e309 in every double field", kind + " " + path + " = " + value,
            submit(kind, WithValue(base.at(kind), path, value)), 400, kIA, FieldName(path));
      }
      // Out of double's range, the JSON parser refuses the number itself: its message quotes
      // the body around the number, so it names the field as the client spelt it.
      add("NaN, Infinity, 1e309 in every double field", kind + " " + path + " = 1e309",
          submit(kind, WithValue(base.at(kind), path, "1e309")), 400, kIA,
          JsonName(path) + (path.back() == ']' ? "\":[" : "\":1e309"));
    }
  }
  // -0 and negative values where the model's domain is > 0 (and a, b >= 0).
  const std::string g3 = "model parameters outside their domain";
  for (const std::string kind : {"simulate", "sweep", "continue", "trace"}) {
    for (const char* field : {"xi", "g", "omega"}) {
      for (const char* value : {"-0", "0", "-1e-300"}) {
        add(g3, kind + " params." + field + " = " + value,
            submit(kind, WithValue(base.at(kind), std::string("request.params.") + field, value)),
            400, kIA, field);
      }
    }
    for (const char* field : {"a", "b"}) {
      // The swept or continued parameter's own value is replaced by the range's.
      if (field == std::string("b") && (kind == "sweep" || kind == "continue")) continue;
      add(g3, kind + " params." + field + " = -1",
          submit(kind, WithValue(base.at(kind), std::string("request.params.") + field, "-1")), 400,
          kIA, field);
    }
  }
  add(g3, "initial state q outside [0, 1]",
      submit("simulate", R"({"request": {"initialState": {"q": 7}}})"), 400, kIA, "q");
  add(g3, "sweep of an unknown parameter",
      submit("sweep", R"({"request": {"param": "zeta", "min": 0, "max": 1}})"), 400, kIA, "param");
  add(g3, "sweep range through xi <= 0",
      submit("sweep", R"({"request": {"param": "xi", "min": -1, "max": 1}})"), 400, kIA, "min");
  add(g3, "optimum margin negative",
      submit("optimum", WithValue(base.at("optimum"), "request.margin[0]", "-0.5")), 400, kIA,
      "margin");

  // Integers: beyond int32, fractional, as exponents, negative, and the int32 maximum.
  const std::string g4 = "huge, fractional or negative integers";
  for (const auto& [kind, paths] : IntFields()) {
    for (const std::string& path : paths) {
      for (const char* value :
           {"2147483648", "-2147483649", "1.5", "1e10", "\"99999999999999999999\""}) {
        add(g4, kind + " " + path + " = " + value,
            submit(kind, WithValue(base.at(kind), path, value)), 400, kIA, FieldName(path));
      }
    }
  }

  // Counts that overflow the work they multiply, and work too large to admit.
  const std::string g5 = "overflowing counts and huge work";
  add(g5, "simulate transientPeriods 2147483647",
      submit("simulate", R"({"request": {"transientPeriods": 2147483647, "samplePeriods": 3}})"),
      429, kRE, "transient_periods");
  add(g5, "simulate samplePeriods 2147483647",
      submit("simulate", R"({"request": {"samplePeriods": 2147483647}})"), 400, kIA,
      "sample_periods");
  add(g5, "simulate 1e6 samples with every output",
      submit("simulate",
             R"({"request": {"samplePeriods": 1000000, "outputs": {"measures": true,
                 "poincare": true, "events": true, "modes": true, "trajectoryDt": 0.01}}})"),
      400, kIA, "trajectory_dt");
  add(g5, "simulate 1e6 samples with events and modes",
      submit("simulate",
             R"({"request": {"samplePeriods": 1000000, "outputs": {"poincare": true,
                 "events": true, "modes": true}}})"),
      429, kRE, "sample_periods = 1000000");
  add(g5, "simulate negative samplePeriods",
      submit("simulate", R"({"request": {"samplePeriods": -5}})"), 400, kIA, "sample_periods");
  add(g5, "sweep of 1e7 values",
      submit("sweep", R"({"request": {"param": "b", "min": 0, "max": 0.2, "steps": 10000000}})"),
      400, kIA, "steps");
  add(g5, "sweep steps * samplePeriods overflowing",
      submit("sweep", R"({"request": {"param": "b", "min": 0, "max": 0.2, "steps": 2147483647,
                 "samplePeriods": 2147483647, "direction": "BOTH"}})"),
      400, kIA, "exceed 2^63 - 1");
  add(g5, "sweep of 2147483647 transient periods",
      submit("sweep", R"({"request": {"param": "b", "min": 0, "max": 0.2, "steps": 2,
                 "transientPeriods": 2147483647}})"),
      429, kRE, "transient_periods");
  add(g5, "sweep with 1e6 threads",
      submit("sweep", R"({"request": {"param": "b", "min": 0, "max": 0.2, "threads": 1000000}})"),
      400, kIA, "threads");
  add(g5, "continue maxSteps 2147483647",
      submit("continue", R"({"request": {"param": "b", "min": 0.14, "max": 0.16,
                 "maxSteps": 2147483647}})"),
      400, kIA, "max_steps");
  add(g5, "trace region grid 1e6 x 1e6",
      submit("trace", R"({"request": {"traceParams": ["omega", "a"], "min": [0.05, 0.25],
                 "max": [0.15, 0.6], "region": {"grid": [1000000, 1000000]}}})"),
      400, kIA, "region.grid");
  add(g5, "optimum grid 1e6 x 1e6",
      submit("optimum",
             R"({"request": {"trace": )" + kTraceJson + R"(, "grid": [1000000, 1000000]}})"),
      400, kIA, "grid");
  {
    // 100000 seeds inside the box: each is a simulation, an orbit solve and two branches.
    std::string seeds;
    for (int i = 0; i < 100000; ++i) seeds += (i == 0 ? "" : ",") + std::string("0.1");
    add(g5, "trace with 100000 seeds",
        submit("trace", R"({"request": {"traceParams": ["omega", "a"], "min": [0.05, 0.25],
                   "max": [0.15, 0.6], "seeds": [)" +
                            seeds + "]}}"),
        400, kIA, "seeds: at most");
  }
  add(g5, "simulate CVODE with rtol 1e-300",
      submit("simulate", R"({"request": {"propagator": "CVODE", "cvodeRtol": 1e-300}})"), 429, kRE,
      "request.cvode_rtol = 1e-300");
  add(g5, "trace maxPeriod 2147483647",
      submit("trace", WithValue(base.at("trace"), "request.maxPeriod", "2147483647")), 400, kIA,
      "max_period");

  // Invalid UTF-8 in each part of a request.
  const std::string g6 = "invalid UTF-8";
  add(g6, "in the path (percent-encoded)", Get("/v1/operations/%FF%FE"), 400, kIA,
      "path: not valid UTF-8");
  add(g6, "in the path (raw)", Get("/v1/operations/\xC3\x28"), 400, kIA, "path: not valid UTF-8");
  add(g6, "a NUL byte in the path", Get("/v1/operations/a%00b"), 400, kIA, "path: a NUL byte");
  add(g6, "a bad percent escape", Get("/v1/operations/%G1"), 400, kIA, "path");
  add(g6, "in a query value", Get("/v1/operations?filter=%C3%28"), 400, kIA,
      "query parameter 'filter': not valid UTF-8");
  add(g6, "in a query name", Get("/v1/operations?%ED%A0%80=1"), 400, kIA,
      "query parameter name: not valid UTF-8");
  add(g6, "in a header", Get("/v1/operations", Auth() + "X-Server-Timeout: \xFF\r\n"), 400, kIA,
      "header X-Server-Timeout");
  add(g6, "in the token", Get("/v1/operations", "Authorization: Bearer \xC0\xAF\r\n"), 400, kIA,
      "header Authorization: not valid UTF-8");
  add(g6, "in the body (raw byte)", submit("simulate", "{\"requestId\": \"\xFF\"}"), 400, kIA,
      "body: not valid UTF-8");
  add(g6, "in the body (lone surrogate escape)", submit("simulate", R"({"requestId": "\ud800"})"),
      400, kIA, "surrogate");
  add(g6, "overlong encoding in a string field",
      submit("sweep", "{\"request\": {\"param\": \"\xC0\x80\"}}"), 400, kIA, "body");

  // Headers and request lines beyond the limits.
  const std::string g7 = "header floods and long request lines";
  {
    std::string many;
    for (int i = 0; i < 150; ++i) many += "X-H" + std::to_string(i) + ": v\r\n";
    add(g7, "150 headers", Get("/v1/operations", Auth() + many), 431, kRE,
        "more than the limit of 100");
    std::string thousand;
    for (int i = 0; i < 1000; ++i) thousand += "X-H" + std::to_string(i) + ": v\r\n";
    add(g7, "1000 headers (beyond the connection's memory)", Get("/v1/operations", thousand), 431,
        "", "", Answer::kServerOwn);
  }
  add(g7, "one 20 KB header",
      Get("/v1/operations", Auth() + "X-Big: " + std::string(20000, 'b') + "\r\n"), 431, kRE,
      "more than the limit of 16384");
  add(g7, "1 MB of headers",
      Get("/v1/operations", Auth() + "X-Flood: " + std::string(1 << 20, 'f') + "\r\n"), 431, "", "",
      Answer::kServerOwn);
  add(g7, "10 KB request target", Get("/v1/operations?filter=" + std::string(10000, 'k')), 414, kRE,
      "longer than the limit of 8192");
  add(g7, "100 KB request target", Get("/v1/operations?filter=" + std::string(100000, 'k')), 414,
      "", "", Answer::kServerOwn);

  // Bodies: oversize, lying or doubled lengths, chunked.
  const std::string g8 = "oversize, lying, doubled and chunked bodies";
  add(g8, "Content-Length 100 MB (no body sent)",
      "POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\n" + Auth() +
          "Content-Length: 100000000\r\n\r\n",
      413, kRE, "Content-Length 100000000 is larger than the limit of 4194304");
  add(g8, "Content-Length beyond 64 bits",
      "POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\n" + Auth() +
          "Content-Length: 99999999999999999999999\r\n\r\n{}",
      413, "", "", Answer::kServerOwn);
  add(g8, "negative Content-Length",
      "POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\n" + Auth() + "Content-Length: -1\r\n\r\n{}",
      400, "", "", Answer::kServerOwn);
  add(g8, "two different Content-Lengths",
      "POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\n" + Auth() +
          "Content-Length: 2\r\nContent-Length: 3\r\n\r\n{}",
      400, kIA, "Content-Length");
  add(g8, "Content-Length shorter than the body",
      "POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\n" + Auth() +
          "Content-Length: 5\r\n\r\n{\"request\": {}}",
      400, kIA, "body");
  add(g8, "chunked body",
      "POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\n" + Auth() +
          "Transfer-Encoding: chunked\r\n\r\n2\r\n{}\r\n0\r\n\r\n",
      411, kIA, "Content-Length");
  add(g8, "chunked and Content-Length",
      "POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\n" + Auth() +
          "Transfer-Encoding: chunked\r\nContent-Length: 2\r\n\r\n2\r\n{}\r\n0\r\n\r\n",
      411, kIA, "Content-Length");
  add(g8, "unauthenticated 1 MB body (not read)",
      "POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\nContent-Length: 1000000\r\n\r\n", 401,
      "UNAUTHENTICATED", "missing");

  // Result pages and names.
  const std::string g9 = "page tokens, page sizes, operation names";
  const std::string result = "/v1/" + done_op + ":result";
  add(g9, "GetResult of a queued job", Get("/v1/" + queued_op + ":result"), 400,
      "FAILED_PRECONDITION", "QUEUED, not SUCCEEDED");
  add(g9, "page token beyond the result", Get(result + "?pageSize=1&pageToken=o999999"), 400, kIA,
      "page_token");
  add(g9, "page token overflowing int64", Get(result + "?pageToken=o99999999999999999999999"), 400,
      kIA, "page_token");
  add(g9, "page token negative", Get(result + "?pageToken=o-1"), 400, kIA, "page_token");
  add(g9, "pageSize above the largest page", Get(result + "?pageSize=2147483647"), 400, kIA,
      "page_size");
  add(g9, "negative pageSize", Get(result + "?pageSize=-1"), 400, kIA, "page_size");
  add(g9, "pageSize beyond int32", Get(result + "?pageSize=99999999999"), 400, kIA, "page_size");
  add(g9, "pageSize not a number", Get(result + "?pageSize=ten"), 400, kIA, "page_size");
  add(g9, "page token garbage", Get(result + "?pageToken=%FF%FF"), 400, kIA,
      "query parameter 'pageToken': not valid UTF-8");
  add(g9, "list with a negative pageSize", Get("/v1/operations?pageSize=-5"), 400, kIA,
      "page_size");
  add(g9, "list with a malformed page token", Get("/v1/operations?pageToken=zzz"), 400, kIA,
      "page_token");
  add(g9, "list with an overflowing page token",
      Get("/v1/operations?pageToken=99999999999999999999999"), 400, kIA, "page_token");
  add(g9, "list with a negative page token", Get("/v1/operations?pageToken=-1"), 400, kIA,
      "page_token");
  add(g9, "list with an unknown filter", Get("/v1/operations?filter=state%3DSLEEPING"), 400, kIA,
      "filter");
  add(g9, "list with an SQL filter", Get("/v1/operations?filter=state%3DQUEUED%27%20OR%201%3D1--"),
      400, kIA, "filter");
  add(g9, "unknown query parameter", Get("/v1/operations?color=red"), 400, kIA, "color");
  add(g9, "repeated query parameter", Get("/v1/operations?filter=a&filter=b"), 400, kIA, "filter");
  add(g9, "unknown operation", Get("/v1/operations/0123456789abcdef0123456789abcdef"), 404,
      "NOT_FOUND", "no job '0123456789abcdef0123456789abcdef'");
  add(g9, "operation name of SQL", Get("/v1/operations/x%27%20OR%20%271%27%3D%271"), 400, kIA,
      "name");
  add(g9, "operation name of 5000 bytes", Get("/v1/operations/" + std::string(5000, 'n')), 400, kIA,
      "name");
  add(g9, "result of an unknown operation",
      Get("/v1/operations/0123456789abcdef0123456789abcdef:result"), 404, "NOT_FOUND",
      "no job '0123456789abcdef0123456789abcdef'");
  add(g9, "watch of an unknown operation",
      Get("/v1/operations/0123456789abcdef0123456789abcdef:watch"), 404, "NOT_FOUND",
      "no job '0123456789abcdef0123456789abcdef'");
  add(g9, "delete of a queued operation",
      "DELETE /v1/" + queued_op + " HTTP/1.1\r\nHost: x\r\n" + Auth() + "\r\n", 400,
      "FAILED_PRECONDITION", "is QUEUED: cancel it");
  add(g9, "cancel with a differing body name",
      Post("/v1/" + queued_op + ":cancel", R"({"name": "operations/other"})"), 400, kIA, "name");
  add(g9, "X-Server-Timeout NaN", Get("/v1/operations", Auth() + "X-Server-Timeout: nan\r\n"), 400,
      kIA, "X-Server-Timeout");
  add(g9, "X-Server-Timeout 1e999", Get("/v1/operations", Auth() + "X-Server-Timeout: 1e999\r\n"),
      400, kIA, "X-Server-Timeout");
  add(g9, "query parameter on a watch", Get("/v1/" + queued_op + ":watch?color=red"), 400, kIA,
      "color");
  add(g9, "QueryOptimum with NaN margin",
      Post("/v1/optimum:query",
           R"({"request": {"trace": )" + kTraceJson + R"(, "margin": ["NaN", 0.02]}})"),
      400, kIA, "request.margin[0]");
  add(g9, "QueryOptimum with a malformed timeout",
      Post("/v1/optimum:query",
           R"({"request": {"trace": )" + kTraceJson + R"(}, "timeout": "soon"})"),
      400, kIA, "timeout");
  add(g9, "X-Server-Timeout negative", Get("/v1/operations", Auth() + "X-Server-Timeout: -3\r\n"),
      400, kIA, "X-Server-Timeout");

  // Tokens.
  const std::string g10 = "missing or wrong token";
  add(g10, "no token", Get("/v1/operations", ""), 401, "UNAUTHENTICATED", "missing");
  add(g10, "wrong token", Get("/v1/operations", Auth("not-the-token")), 401, "UNAUTHENTICATED",
      "wrong bearer token");
  add(g10, "token without Bearer",
      Get("/v1/operations", std::string("Authorization: ") + kToken + "\r\n"), 401,
      "UNAUTHENTICATED", "wrong bearer token");
  add(g10, "Basic scheme", Get("/v1/operations", "Authorization: Basic YWxpY2U6cHc=\r\n"), 401,
      "UNAUTHENTICATED", "wrong bearer token");
  add(g10, "10 KB token", Get("/v1/operations", Auth(std::string(10000, 't'))), 401,
      "UNAUTHENTICATED", "wrong bearer token");
  add(g10, "no token on a submit", Post("/v1/jobs:simulate", "{}", ""), 401, "UNAUTHENTICATED",
      "missing");

  // Paths and methods.
  const std::string g11 = "unknown paths and methods";
  add(g11, "unknown path", Get("/v1/nothing"), 404, "NOT_FOUND", "no route");
  add(g11, "unknown kind", submit("teleport", "{}"), 404, "NOT_FOUND", "no route");
  add(g11, "path traversal", Get("/v1/../../etc/passwd"), 404, "NOT_FOUND",
      "no route for GET /v1/../../etc/passwd");
  add(g11, "PUT on a submit route",
      "PUT /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\n" + Auth() + "Content-Length: 2\r\n\r\n{}", 405,
      "UNIMPLEMENTED", "PUT");
  add(g11, "POST on the health route", Post("/healthz", "{}"), 405, "UNIMPLEMENTED", "POST");
  add(g11, "GET on a submit route", Get("/v1/jobs:sweep"), 405, "UNIMPLEMENTED", "GET");
  add(g11, "unknown method", "BREW /v1/operations HTTP/1.1\r\nHost: x\r\n" + Auth() + "\r\n", 405,
      "UNIMPLEMENTED", "BREW");
  add(g11, "not HTTP at all", "\x16\x03\x01\x02\x00\x01\x00\x01\xfc\x03\x03\r\n\r\n", 0, "", "",
      Answer::kClosed);
  add(g11, "HTTP/2 preface", "PRI * HTTP/2.0\r\n\r\nSM\r\n\r\n", 505, "", "", Answer::kServerOwn);
  add(g11, "OPTIONS", "OPTIONS /v1/operations HTTP/1.1\r\nHost: x\r\n" + Auth() + "\r\n", 405,
      "UNIMPLEMENTED", "OPTIONS");
  add(g11, "NUL escape in a string field",
      submit("sweep", R"({"request": {"param": "b\u0000", "min": 0.1, "max": 0.2}})"), 400, kIA,
      "param");
  add(g11, "absolute-form target", Get("http://evil.example/v1/operations"), 400, kIA,
      "request target: must start with '/'");
  return cases;
}

// Whether `text` mentions SQL: the store's words must never reach a client.
bool MentionsSql(const std::string& text) {
  std::string lower = text;
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return std::tolower(c); });
  for (const char* word :
       {"sqlite", "select ", "constraint failed", "insert into", "syntax error"}) {
    if (lower.find(word) != std::string::npos) return true;
  }
  return false;
}

// ---------------------------------------------------------------------------------------------
// gRPC cases: raw bytes to a method.

struct GrpcCase {
  std::string group;
  std::string name;
  std::string method;  // "/drillbif.v1.Jobs/SubmitSimulate"
  std::string bytes;   // the request's serialized bytes (or garbage)
  grpc::StatusCode code;
  std::string names;  // a substring of the message
  std::string token = kToken;
  bool stream = false;  // a server-streaming method
};

const std::vector<std::pair<std::string, bool>>& AllMethods() {
  static const std::vector<std::pair<std::string, bool>> methods = {
      {"/drillbif.v1.Jobs/SubmitSimulate", false},
      {"/drillbif.v1.Jobs/SubmitSweep", false},
      {"/drillbif.v1.Jobs/SubmitContinue", false},
      {"/drillbif.v1.Jobs/SubmitTrace", false},
      {"/drillbif.v1.Jobs/SubmitOptimum", false},
      {"/drillbif.v1.Jobs/GetResult", false},
      {"/drillbif.v1.Jobs/QueryOptimum", false},
      {"/drillbif.v1.Jobs/Watch", true},
      {"/google.longrunning.Operations/ListOperations", false},
      {"/google.longrunning.Operations/GetOperation", false},
      {"/google.longrunning.Operations/DeleteOperation", false},
      {"/google.longrunning.Operations/CancelOperation", false},
      {"/google.longrunning.Operations/WaitOperation", false},
  };
  return methods;
}

// `done_op` names a job that succeeded.
std::vector<GrpcCase> GrpcCatalogue(const std::string& done_op) {
  std::vector<GrpcCase> cases;
  const auto add = [&](std::string group, std::string name, std::string method, std::string bytes,
                       grpc::StatusCode code, std::string names) {
    cases.push_back({std::move(group), std::move(name), std::move(method), std::move(bytes), code,
                     std::move(names)});
    for (const auto& [m, stream] : AllMethods()) {
      if (m == cases.back().method) cases.back().stream = stream;
    }
  };
  const std::string g1 = "gRPC: garbage bytes to every method";
  for (const auto& [method, stream] : AllMethods()) {
    // A field 1 of wire type 7 (there is none), then a truncated varint.
    add(g1, "garbage to " + method, method, std::string("\x0f\xff\xff\xff\xff", 5),
        grpc::StatusCode::INVALID_ARGUMENT, "not a valid");
    // Field 1 (a message or string in every request) with a length beyond the bytes.
    add(g1, "truncated length to " + method, method, std::string("\x0a\x7f\x01", 3),
        grpc::StatusCode::INVALID_ARGUMENT, "not a valid");
  }
  const std::string g2 = "gRPC: bad requests";
  // request_id (field 2, a string) of invalid UTF-8: protobuf refuses to parse it.
  add(g2, "request_id of invalid UTF-8", "/drillbif.v1.Jobs/SubmitSimulate",
      std::string("\x12\x02\xC3\x28", 4), grpc::StatusCode::INVALID_ARGUMENT, "request_id");
  add(g2, "operation name of invalid UTF-8", "/google.longrunning.Operations/GetOperation",
      std::string("\x0a\x02\xFF\xFE", 4), grpc::StatusCode::INVALID_ARGUMENT, "name");
  {
    v1::SubmitSimulateRequest r;
    r.mutable_request()->mutable_params()->set_xi(std::nan(""));
    add(g2, "simulate xi = NaN", "/drillbif.v1.Jobs/SubmitSimulate", r.SerializeAsString(),
        grpc::StatusCode::INVALID_ARGUMENT, "request.params.xi");
    r.mutable_request()->mutable_params()->set_xi(-0.0);
    add(g2, "simulate xi = -0", "/drillbif.v1.Jobs/SubmitSimulate", r.SerializeAsString(),
        grpc::StatusCode::INVALID_ARGUMENT, "xi");
  }
  {
    v1::SubmitSimulateRequest r;
    r.mutable_request()->set_sample_periods(1000000);
    auto* o = r.mutable_request()->mutable_outputs();
    o->set_poincare(true);
    o->set_events(true);
    o->set_modes(true);
    add(g2, "simulate 1e6 samples with events and modes", "/drillbif.v1.Jobs/SubmitSimulate",
        r.SerializeAsString(), grpc::StatusCode::RESOURCE_EXHAUSTED, "above the limit of");
    r.mutable_request()->set_sample_periods(3);
    r.mutable_request()->set_transient_periods(2147483647);
    add(g2, "simulate transient_periods 2147483647", "/drillbif.v1.Jobs/SubmitSimulate",
        r.SerializeAsString(), grpc::StatusCode::RESOURCE_EXHAUSTED, "transient_periods");
  }
  {
    v1::SubmitSweepRequest r;
    *r.mutable_request() = drillbif::testing::SmallSweep(0.0, 10000000);
    add(g2, "sweep of 1e7 values", "/drillbif.v1.Jobs/SubmitSweep", r.SerializeAsString(),
        grpc::StatusCode::INVALID_ARGUMENT, "steps");
  }
  {
    v1::SubmitSimulateRequest r;
    r.set_request_id(std::string(5 << 20, 'x'));
    add(g2, "5 MB request", "/drillbif.v1.Jobs/SubmitSimulate", r.SerializeAsString(),
        grpc::StatusCode::RESOURCE_EXHAUSTED, "larger than max (5242885 vs. 4194304)");
  }
  {
    v1::GetResultRequest r;
    r.set_name(done_op);
    r.set_page_size(-1);
    add(g2, "GetResult page_size -1", "/drillbif.v1.Jobs/GetResult", r.SerializeAsString(),
        grpc::StatusCode::INVALID_ARGUMENT, "page_size");
  }
  {
    google::longrunning::ListOperationsRequest r;
    r.set_name("operations");
    r.set_page_token("o-1");
    add(g2, "ListOperations page_token o-1", "/google.longrunning.Operations/ListOperations",
        r.SerializeAsString(), grpc::StatusCode::INVALID_ARGUMENT, "page_token");
  }
  {
    google::longrunning::GetOperationRequest r;
    r.set_name("operations/nope");
    add(g2, "GetOperation of a malformed name", "/google.longrunning.Operations/GetOperation",
        r.SerializeAsString(), grpc::StatusCode::INVALID_ARGUMENT, "name: not an operation name");
    r.set_name("operations/0123456789abcdef0123456789abcdef");
    add(g2, "GetOperation of an unknown name", "/google.longrunning.Operations/GetOperation",
        r.SerializeAsString(), grpc::StatusCode::NOT_FOUND, "no job");
  }
  // Long strings the messages would echo: they are cut (kMaxMessageBytes below).
  {
    google::longrunning::ListOperationsRequest r;
    r.set_name("operations");
    r.set_filter("kind=" + std::string(kLongEcho, 'k'));
    add(g2, "ListOperations filter of 100 KB", "/google.longrunning.Operations/ListOperations",
        r.SerializeAsString(), grpc::StatusCode::INVALID_ARGUMENT, "filter: unknown kind");
    r.set_filter(std::string(kLongEcho, 'f'));
    add(g2, "ListOperations filter of 100 KB without a term",
        "/google.longrunning.Operations/ListOperations", r.SerializeAsString(),
        grpc::StatusCode::INVALID_ARGUMENT, "filter: expected terms");
    r.set_filter("");
    r.set_page_size(std::numeric_limits<int32_t>::min());
    add(g2, "ListOperations page_size INT32_MIN", "/google.longrunning.Operations/ListOperations",
        r.SerializeAsString(), grpc::StatusCode::INVALID_ARGUMENT, "page_size");
  }
  {
    google::longrunning::GetOperationRequest r;
    r.set_name("operations/" + std::string(kLongEcho, 'n'));
    add(g2, "GetOperation name of 100 KB", "/google.longrunning.Operations/GetOperation",
        r.SerializeAsString(), grpc::StatusCode::INVALID_ARGUMENT, "name: not an operation name");
    v1::WatchRequest w;
    w.set_name(std::string(kLongEcho, 'w'));
    add(g2, "Watch name of 100 KB", "/drillbif.v1.Jobs/Watch", w.SerializeAsString(),
        grpc::StatusCode::INVALID_ARGUMENT, "name");
    google::longrunning::CancelOperationRequest c;
    c.set_name(std::string(kLongEcho, 'c'));
    add(g2, "CancelOperation name of 100 KB", "/google.longrunning.Operations/CancelOperation",
        c.SerializeAsString(), grpc::StatusCode::INVALID_ARGUMENT, "name");
  }
  {
    v1::SubmitSweepRequest r;
    *r.mutable_request() = drillbif::testing::SmallSweep(0.1, 5);
    r.mutable_request()->set_param(std::string(kLongEcho, 'p'));
    add(g2, "sweep param of 100 KB", "/drillbif.v1.Jobs/SubmitSweep", r.SerializeAsString(),
        grpc::StatusCode::INVALID_ARGUMENT, "param");
    v1::SubmitTraceRequest t;
    t.mutable_request()->add_trace_params(std::string(kLongEcho, 't'));
    t.mutable_request()->add_trace_params(std::string("a"));
    for (double bound : {0.1, 0.2}) t.mutable_request()->add_min(bound);
    for (double bound : {0.3, 0.4}) t.mutable_request()->add_max(bound);
    add(g2, "trace param of 100 KB", "/drillbif.v1.Jobs/SubmitTrace", t.SerializeAsString(),
        grpc::StatusCode::INVALID_ARGUMENT, "trace_params");
    v1::SubmitContinueRequest c;
    c.mutable_request()->set_param(std::string(kLongEcho, 'c'));
    c.mutable_request()->set_min(0.1);
    c.mutable_request()->set_max(0.2);
    add(g2, "continue param of 100 KB", "/drillbif.v1.Jobs/SubmitContinue", c.SerializeAsString(),
        grpc::StatusCode::INVALID_ARGUMENT, "param");
  }
  add(g2, "unknown method", "/drillbif.v1.Jobs/Teleport", "", grpc::StatusCode::UNIMPLEMENTED, "");
  add(g2, "no token", "/google.longrunning.Operations/ListOperations", "",
      grpc::StatusCode::UNAUTHENTICATED, "missing");
  cases.back().token = "";
  add(g2, "wrong token", "/drillbif.v1.Jobs/SubmitSimulate", "", grpc::StatusCode::UNAUTHENTICATED,
      "wrong bearer token");
  cases.back().token = "wrong-token-0123456789";
  return cases;
}

ServerOptions CatalogueOptions(const TempDir& dir) {
  const std::string tokens = dir.path() + "/tokens";
  std::ofstream(tokens) << "catalogue " << kToken << "\nalice " << kAliceToken << "\nbob "
                        << kBobToken << "\n";
  ServerOptions options;
  options.grpc_port = 0;
  options.http_port = 0;
  options.db_path = dir.path() + "/jobs.db";
  options.workers = 1;        // busy with a sweep of minutes: long jobs stay queued
  options.short_workers = 1;  // runs the small simulate
  options.tokens_file = tokens;
  options.max_queued_per_client = kPerClientCap;
  options.http.request_timeout_ms = kRequestDeadlineMs;
  options.full_sync = false;  // durability is not what is tested; the disk is shared
  return options;
}

// The answer to `request` on a fresh connection.
std::string Exchange(int port, const std::string& request, bool* closed = nullptr) {
  RawConnection c(port);
  c.Send(request);  // The server may stop reading early (a flood): the send may fail.
  return c.ReadResponse(milliseconds(15000), closed);
}

// The operation of a 200 answer (empty name otherwise).
Operation OperationOf(const std::string& response) {
  Operation op;
  if (StatusOf(response) == 200) {
    EXPECT_TRUE(google::protobuf::util::JsonStringToMessage(BodyOf(response), &op).ok());
  }
  return op;
}

std::string SweepBody(double min) {
  v1::SubmitSweepRequest r;
  *r.mutable_request() = drillbif::testing::LongSweep();
  r.mutable_request()->set_min(min);  // distinct requests: none follows another
  std::string json;
  EXPECT_TRUE(google::protobuf::util::MessageToJsonString(r, &json).ok());
  return json;
}

// Checks one REST case's answer; returns a one-line summary for the log.
void CheckRestAnswer(const RestCase& c, const std::string& response, bool closed) {
  SCOPED_TRACE(c.group + " / " + c.name);
  const int status = StatusOf(response);
  EXPECT_EQ(status, c.status) << response.substr(0, 400);
  EXPECT_NE(status, 500);
  EXPECT_FALSE(MentionsSql(response)) << response.substr(0, 400);
  if (c.answer == Answer::kClosed) {
    EXPECT_TRUE(closed) << response.substr(0, 400);
    return;
  }
  if (c.answer == Answer::kServerOwn) {
    // libmicrohttpd's own answer: then it closes the connection.
    EXPECT_TRUE(closed || response.find("Connection: close") != std::string::npos)
        << response.substr(0, 400);
    return;
  }
  const std::string message = ExpectJsonError(BodyOf(response), c.code.c_str());
  EXPECT_LE(message.size(), kMaxMessageBytes);
  EXPECT_FALSE(message.empty()) << response.substr(0, 400);
  EXPECT_FALSE(c.names.empty()) << "every JSON case names what its message must say";
  EXPECT_THAT(message, HasSubstr(c.names));
}

class AttackCatalogueTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::make_unique<TempDir>("drillbif_attack");
    StatusOr<std::unique_ptr<Server>> server = Server::Start(CatalogueOptions(*dir_));
    ASSERT_TRUE(server.ok()) << server.status().ToString();
    server_ = std::move(server).value();
    channel_ = grpc::CreateChannel(server_->grpc_address(), grpc::InsecureChannelCredentials());
  }

  int port() const { return server_->http_port(); }

  // The operation `name` as GET returns it.
  Operation Fetch(const std::string& name) {
    return OperationOf(Exchange(port(), Get("/v1/" + name)));
  }

  // Polls `name` until its state is `state` (a JobMetadata enum name) or `wait` passes.
  bool ReachesState(const std::string& name, const std::string& state, milliseconds wait) {
    const auto end = Clock::now() + wait;
    while (Clock::now() < end) {
      const std::string body = BodyOf(Exchange(port(), Get("/v1/" + name)));
      if (body.find("\"state\":\"" + state + "\"") != std::string::npos) return true;
      std::this_thread::sleep_for(milliseconds(20));
    }
    return false;
  }

  std::map<std::string, double> Metrics() {
    return drillbif::testing::MetricsSamples(BodyOf(Exchange(port(), Get("/metrics", ""))));
  }

  std::unique_ptr<TempDir> dir_;
  std::unique_ptr<Server> server_;
  std::shared_ptr<grpc::Channel> channel_;
};

TEST_F(AttackCatalogueTest, EveryHostileInputGetsItsCodeAndTheServerStaysHealthy) {
  const auto test_start = Clock::now();
  // Peak memory from here on: the server is up and has answered once.
  ASSERT_EQ(StatusOf(Exchange(port(), Get("/metrics", ""))), 200);
  const long hwm_before = ProcStatusKib("VmHWM");

  // --- The per-client queue cap. Alice's first sweep runs on the one worker; her next ones
  // wait, up to her cap; one more is refused, while Bob still submits.
  const Operation running =
      OperationOf(Exchange(port(), Post("/v1/jobs:sweep", SweepBody(0.0), Auth(kAliceToken))));
  ASSERT_FALSE(running.name().empty());
  ASSERT_TRUE(ReachesState(running.name(), "RUNNING", milliseconds(15000)));
  std::vector<std::string> alice_queued;
  for (int i = 1; i <= kPerClientCap; ++i) {
    const Operation op = OperationOf(
        Exchange(port(), Post("/v1/jobs:sweep", SweepBody(0.001 * i), Auth(kAliceToken))));
    ASSERT_FALSE(op.name().empty());
    alice_queued.push_back(op.name());
  }
  const std::string over =
      Exchange(port(), Post("/v1/jobs:sweep", SweepBody(0.01), Auth(kAliceToken)));
  EXPECT_EQ(StatusOf(over), 429) << over.substr(0, 400);
  EXPECT_THAT(ExpectJsonError(BodyOf(over), "RESOURCE_EXHAUSTED"),
              HasSubstr("client 'alice' has 2 jobs waiting (limit 2)"));
  const std::string bob =
      Exchange(port(), Post("/v1/jobs:sweep", SweepBody(0.02), Auth(kBobToken)));
  EXPECT_EQ(StatusOf(bob), 200) << bob.substr(0, 400);
  const std::string queued = alice_queued.front();

  // --- 32 event streams of a queued job; /metrics and a small simulate still answer.
  const double watchers_before = Metrics()["drillbif_watchers"];
  std::vector<std::unique_ptr<RawConnection>> streams;
  for (int i = 0; i < 32; ++i) {
    streams.push_back(std::make_unique<RawConnection>(port()));
    ASSERT_TRUE(streams.back()->Send(Get("/v1/" + queued + ":watch", Auth(kAliceToken))));
  }
  for (auto& s : streams) {
    EXPECT_THAT(s->ReadUntil(
                    [](const std::string& r) {
                      return r.find("\"state\":\"QUEUED\"") != std::string::npos;
                    },
                    milliseconds(10000)),
                HasSubstr("text/event-stream"));
  }
  auto start = Clock::now();
  const std::map<std::string, double> with_streams = Metrics();
  const double metrics_ms = MsSince(start);
  EXPECT_EQ(with_streams.at("drillbif_watchers"), watchers_before + 32);
  start = Clock::now();
  const Operation small = OperationOf(Exchange(
      port(),
      Post("/v1/jobs:simulate",
           R"({"request": {"transientPeriods": 3, "samplePeriods": 3, "params": {"b": 0.11}}})")));
  ASSERT_FALSE(small.name().empty());
  EXPECT_TRUE(ReachesState(small.name(), "SUCCEEDED", milliseconds(15000)));
  const double simulate_ms = MsSince(start);
  std::printf(
      "with 32 event streams open: GET /metrics %.1f ms, a 3 + 3-period simulate "
      "submitted and SUCCEEDED in %.1f ms\n",
      metrics_ms, simulate_ms);
  // The bounds leave a loaded 2-core machine seconds; the failure they guard against (a thread
  // held per stream) never answers.
  EXPECT_LT(metrics_ms, 2000.0);
  EXPECT_LT(simulate_ms, 10000.0);

  // --- A slowloris and a Content-Length the body never reaches, while the catalogue runs: both
  // are cut at the request deadline without an answer.
  std::atomic<double> slowloris_ms{0}, lying_ms{0};
  std::atomic<bool> slowloris_answered{false}, lying_answered{false};
  std::thread slowloris([&] {
    RawConnection slow(port());
    const std::string request =
        Get("/v1/operations", Auth() + "X-Slow: " + std::string(400, 's') + "\r\n");
    const auto begin = Clock::now();
    for (size_t sent = 0; sent < request.size(); ++sent) {
      if (!slow.Send(request.substr(sent, 1)) || !slow.NothingYet()) break;
      std::this_thread::sleep_for(milliseconds(20));
    }
    bool closed = false;
    const std::string answer = slow.ReadResponse(milliseconds(10000), &closed);
    slowloris_answered = StatusOf(answer) != 0;
    slowloris_ms = MsSince(begin);
  });
  std::thread lying([&] {
    RawConnection liar(port());
    const auto begin = Clock::now();
    liar.Send("POST /v1/jobs:simulate HTTP/1.1\r\nHost: x\r\n" + Auth() +
              "Content-Length: 1000\r\n\r\n{}");
    bool closed = false;
    const std::string answer = liar.ReadResponse(milliseconds(10000), &closed);
    lying_answered = StatusOf(answer) != 0;
    lying_ms = MsSince(begin);
  });

  // --- The REST catalogue.
  const std::vector<RestCase> rest = RestCatalogue(queued, small.name());
  std::map<std::string, int> per_group;
  start = Clock::now();
  for (const RestCase& c : rest) {
    bool closed = false;
    const auto sent = Clock::now();
    const std::string response = Exchange(port(), c.request, &closed);
    if (const double ms = MsSince(sent); ms > 500) {
      std::printf("  slow case: %s / %s: %.0f ms\n", c.group.c_str(), c.name.c_str(), ms);
    }
    CheckRestAnswer(c, response, closed);
    ++per_group[c.group];
  }
  std::printf("REST catalogue: %zu cases in %.0f ms\n", rest.size(), MsSince(start));

  // --- The gRPC catalogue.
  const std::vector<GrpcCase> grpc_cases = GrpcCatalogue(small.name());
  start = Clock::now();
  for (const GrpcCase& c : grpc_cases) {
    SCOPED_TRACE(c.group + " / " + c.name);
    std::string response;
    const std::string auth = c.token.empty() ? "" : "Bearer " + c.token;
    const grpc::Status s =
        c.stream ? drillbif::testing::GenericServerStreamFirst(channel_, c.method, c.bytes,
                                                               &response, auth)
                 : drillbif::testing::GenericUnary(channel_, c.method, c.bytes, &response, auth);
    EXPECT_EQ(s.error_code(), c.code) << s.error_message();
    // gRPC itself answers an unknown method, with no message.
    if (c.code != grpc::StatusCode::UNIMPLEMENTED) {
      EXPECT_FALSE(s.error_message().empty());
      EXPECT_FALSE(c.names.empty()) << "every case names what its message must say";
    }
    EXPECT_THAT(s.error_message(), HasSubstr(c.names));
    EXPECT_FALSE(MentionsSql(s.error_message())) << s.error_message();
    EXPECT_LE(s.error_message().size(), kMaxMessageBytes);
    ++per_group[c.group];
  }
  std::printf("gRPC catalogue: %zu cases in %.0f ms\n", grpc_cases.size(), MsSince(start));

  // WaitOperation of a queued job with the longest timeouts a Duration can hold, and beyond: each
  // waits until 50 ms before the client's 1.5 s deadline (the server's cap is 10 minutes), then
  // answers the job as it is. A timeout whose nanoseconds overflow the clock must not end the
  // wait at once.
  {
    auto operations = google::longrunning::Operations::NewStub(channel_);
    for (const int64_t seconds : {int64_t{315576000000}, std::numeric_limits<int64_t>::max()}) {
      SCOPED_TRACE("WaitOperation timeout of " + std::to_string(seconds) + " s");
      grpc::ClientContext context;
      context.set_deadline(std::chrono::system_clock::now() + milliseconds(1500));
      context.AddMetadata("authorization", std::string("Bearer ") + kToken);
      google::longrunning::WaitOperationRequest request;
      request.set_name(queued);
      request.mutable_timeout()->set_seconds(seconds);
      Operation op;
      const auto begin = Clock::now();
      const grpc::Status s = operations->WaitOperation(&context, request, &op);
      const double ms = MsSince(begin);
      std::printf("WaitOperation with a timeout of %lld s answered after %.0f ms\n",
                  static_cast<long long>(seconds), ms);
      // The server answers 50 ms before the client's deadline; on a loaded machine that answer
      // can arrive after it. Either way the wait lasted, which is what an overflow broke.
      EXPECT_TRUE(s.ok() || s.error_code() == grpc::StatusCode::DEADLINE_EXCEEDED)
          << s.error_message();
      EXPECT_FALSE(op.done());
      EXPECT_GE(ms, 1000.0);
    }
  }

  slowloris.join();
  lying.join();
  std::printf("slowloris cut after %.0f ms, lying Content-Length after %.0f ms (deadline %d ms)\n",
              slowloris_ms.load(), lying_ms.load(), kRequestDeadlineMs);
  EXPECT_FALSE(slowloris_answered.load());
  EXPECT_FALSE(lying_answered.load());
  // Not before the deadline (5% for the guard's timer); the upper bound leaves a loaded machine
  // 5 s.
  for (double ms : {slowloris_ms.load(), lying_ms.load()}) {
    EXPECT_GE(ms, 0.95 * kRequestDeadlineMs);
    EXPECT_LT(ms, kRequestDeadlineMs + 5000.0);
  }
  streams.clear();

  for (const auto& [group, n] : per_group) std::printf("  %3d  %s\n", n, group.c_str());
  EXPECT_GE(rest.size() + grpc_cases.size(), 100u);

  // --- Afterwards: healthy.
  EXPECT_EQ(drillbif::testing::HealthStatus(channel_), 1) << "gRPC health is not SERVING";
  const std::string health = Exchange(port(), Get("/healthz", ""));
  EXPECT_EQ(StatusOf(health), 200) << health;
  EXPECT_EQ(BodyOf(health), R"({"status":"SERVING"})");
  const std::map<std::string, double> after = Metrics();
  EXPECT_EQ(after.at("drillbif_store_healthy"), 1.0);
  const std::string final_body =
      R"({"request": {"transientPeriods": 3, "samplePeriods": 3, "params": {"b": 0.12}}})";
  const Operation last = OperationOf(Exchange(port(), Post("/v1/jobs:simulate", final_body)));
  ASSERT_FALSE(last.name().empty());
  EXPECT_TRUE(ReachesState(last.name(), "SUCCEEDED", milliseconds(15000)));
  // No 500 was ever answered (the gateway counts every answer it makes).
  for (const auto& [sample, value] : after) {
    if (sample.rfind("drillbif_http_requests_total{", 0) == 0) {
      EXPECT_THAT(sample, ::testing::Not(HasSubstr("code=\"500\""))) << value;
    }
  }

  // Peak memory. The bound, 96 MiB: the largest inputs read are the 3 MB REST body and the 5 MB
  // gRPC request (refused by its size once received), each held up to ~8 times while in flight
  // (the test's own copies, socket and transport buffers, the body string, the parsed message,
  // the in-process channel's copy): 64 MB; plus 32 MiB for what glibc keeps of freed blocks in
  // its per-thread arenas (up to 16 on 2 cores), the connection pools (< 40 x 64 KiB at once)
  // and thread stacks. What it guards against is far above: an admitted 1e6-sample simulate
  // with every output (its result alone estimated over the 256 MB limit), a 1 MB header flood
  // that costs ~400 MB per connection.
  const long hwm_after = ProcStatusKib("VmHWM");
  std::printf("peak RSS %ld KiB before the catalogue, %ld KiB after (+%ld KiB); %.1f s in all\n",
              hwm_before, hwm_after, hwm_after - hwm_before, MsSince(test_start) / 1000);
  EXPECT_LT(hwm_after - hwm_before, 96 * 1024);
}

// Prints the catalogue's groups as the markdown table of docs/service.md.
TEST(AttackCatalogueTable, DISABLED_PrintTable) {
  std::map<std::string, std::vector<std::string>> rows;
  std::map<std::string, int> counts;
  for (const RestCase& c : RestCatalogue("operations/QUEUED", "operations/DONE")) {
    const std::string outcome =
        c.answer == Answer::kClosed
            ? std::string("closed, no answer")
            : std::to_string(c.status) + " " +
                  (c.answer == Answer::kServerOwn ? std::string("(libmicrohttpd's HTML)") : c.code);
    auto& list = rows[c.group];
    if (std::find(list.begin(), list.end(), outcome) == list.end()) list.push_back(outcome);
    ++counts[c.group];
  }
  for (const GrpcCase& c : GrpcCatalogue("operations/DONE")) {
    const std::map<grpc::StatusCode, std::string> names = {
        {grpc::StatusCode::INVALID_ARGUMENT, "INVALID_ARGUMENT"},
        {grpc::StatusCode::RESOURCE_EXHAUSTED, "RESOURCE_EXHAUSTED"},
        {grpc::StatusCode::NOT_FOUND, "NOT_FOUND"},
        {grpc::StatusCode::UNIMPLEMENTED, "UNIMPLEMENTED"},
        {grpc::StatusCode::UNAUTHENTICATED, "UNAUTHENTICATED"}};
    const std::string code = names.count(c.code) ? names.at(c.code) : "?";
    auto& list = rows[c.group];
    if (std::find(list.begin(), list.end(), code) == list.end()) list.push_back(code);
    ++counts[c.group];
  }
  std::printf("| Group | Cases | Expected |\n| --- | --- | --- |\n");
  for (const auto& [group, outcomes] : rows) {
    std::string joined;
    for (const auto& o : outcomes) joined += (joined.empty() ? "" : ", ") + o;
    std::printf("| %s | %d | %s |\n", group.c_str(), counts[group], joined.c_str());
  }
  EXPECT_FALSE(rows.empty());
}

}  // namespace
}  // namespace drillbif::server
