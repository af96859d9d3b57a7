// The OpenAPI document (server/openapi.h) served at GET /openapi.json by a real server on
// 127.0.0.1 with port 0, checked against the generated descriptor pool it is made from: a path
// and method for every annotated rpc (so an rpc added later is covered without a change here),
// every $ref resolved, each message's properties by their JSON names and JSON-mapping types,
// enums as strings, the event stream, the bearer scheme; served without a token and with CORS.
// And the gateway's route table against the annotations, so the two cannot drift apart.
#include "server/openapi.h"

#include <gmock/gmock.h>
#include <google/protobuf/descriptor.h>
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <gtest/gtest.h>

#include <functional>
#include <map>
#include <regex>
#include <set>
#include <string>
#include <vector>

#include "google/api/annotations.pb.h"
#include "server/rest_request.h"
#include "server/server.h"
#include "support/test_server.h"

// Last: httplib.h includes <resolv.h>, whose macro _res breaks Eigen's headers.
#include <httplib.h>

namespace drillbif::server {
namespace {

using google::protobuf::Descriptor;
using google::protobuf::DescriptorPool;
using google::protobuf::FieldDescriptor;
using google::protobuf::MethodDescriptor;
using google::protobuf::Struct;
using google::protobuf::Value;
using ::testing::HasSubstr;

constexpr char kToken[] = "openapi-test-token";
constexpr char kOrigin[] = "https://dash.example.com";
// The proto files whose services the gateway serves.
constexpr const char* kServiceFiles[] = {"drillbif/v1/service.proto",
                                         "google/longrunning/operations.proto"};
constexpr char kSchemaRef[] = "#/components/schemas/";

// The member `key` of the object `value` (a null Value, and a test failure, when missing).
const Value& At(const Value& value, const std::string& key) {
  static const Value* const kMissing = new Value();
  const auto& fields = value.struct_value().fields();
  const auto it = fields.find(key);
  if (it == fields.end()) {
    ADD_FAILURE() << "no member '" << key << "'";
    return *kMissing;
  }
  return it->second;
}

bool Has(const Value& value, const std::string& key) {
  return value.struct_value().fields().count(key) != 0;
}

// An annotated rpc: its verb and path template.
struct Annotation {
  const MethodDescriptor* method;
  std::string verb;
  std::string path_template;
};

// Every annotated rpc of the served files, read from the HttpRule itself (not from the
// generator's AnnotatedBindings, which is what is under test).
std::vector<Annotation> AnnotatedRpcs() {
  std::vector<Annotation> rpcs;
  for (const char* name : kServiceFiles) {
    const auto* file = DescriptorPool::generated_pool()->FindFileByName(name);
    EXPECT_NE(file, nullptr) << name;
    if (file == nullptr) continue;
    for (int s = 0; s < file->service_count(); ++s) {
      for (int m = 0; m < file->service(s)->method_count(); ++m) {
        const MethodDescriptor* method = file->service(s)->method(m);
        if (!method->options().HasExtension(google::api::http)) continue;
        const auto& rule = method->options().GetExtension(google::api::http);
        const std::map<std::string, std::string> verbs = {{"GET", rule.get()},
                                                          {"POST", rule.post()},
                                                          {"PUT", rule.put()},
                                                          {"PATCH", rule.patch()},
                                                          {"DELETE", rule.delete_()}};
        for (const auto& [verb, path] : verbs) {
          if (!path.empty()) rpcs.push_back({method, verb, path});
        }
      }
    }
  }
  return rpcs;
}

// The OpenAPI path of a template: "{name=operations/*}" -> "{name}", a variable without a
// wildcard ("{name=operations}") -> its text.
std::string OpenApiPathOf(const std::string& path_template) {
  static const std::regex variable(R"(\{([a-z_.]+)(=([^}]*))?\})");
  std::string out;
  auto begin = std::sregex_iterator(path_template.begin(), path_template.end(), variable);
  size_t at = 0;
  for (auto it = begin; it != std::sregex_iterator(); ++it) {
    out += path_template.substr(at, it->position() - at);
    const std::string pattern = (*it)[3];
    if (pattern.empty() || pattern.find('*') != std::string::npos) {
      out.append("{").append((*it)[1].str()).append("}");
    } else {
      out.append(pattern);
    }
    at = it->position() + it->length();
  }
  return out + path_template.substr(at);
}

class OpenApiTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    ServerOptions options;
    options.token = kToken;
    options.workers = 1;
    options.http.cors_origins = {kOrigin};
    server_ = new testing::TestServer(options, "drillbif_openapi");
    ASSERT_TRUE(server_->ok());
    httplib::Client client("127.0.0.1", server_->server().http_port());
    // No token: the document is open.
    httplib::Result result = client.Get("/openapi.json");
    ASSERT_TRUE(result);
    ASSERT_EQ(result->status, 200) << result->body;
    content_type_ = new std::string(result->get_header_value("Content-Type"));
    document_ = new Value();
    const auto status = google::protobuf::util::JsonStringToMessage(result->body, document_);
    ASSERT_TRUE(status.ok()) << status.ToString();
  }
  static void TearDownTestSuite() {
    delete server_;
    delete document_;
    delete content_type_;
  }

  void SetUp() override { ASSERT_NE(document_, nullptr); }

  static const Value& Schemas() { return At(At(*document_, "components"), "schemas"); }

  // The schema a reference `{"$ref": ...}` or `{"allOf": [{"$ref": ...}]}` points to, by name.
  static std::string RefName(const Value& schema) {
    const Value* ref = &schema;
    if (Has(schema, "allOf"))
      ref = &schema.struct_value().fields().at("allOf").list_value().values(0);
    if (!Has(*ref, "$ref")) return "";
    const std::string text = At(*ref, "$ref").string_value();
    return text.rfind(kSchemaRef, 0) == 0 ? text.substr(sizeof(kSchemaRef) - 1) : "";
  }

  static testing::TestServer* server_;
  static Value* document_;
  static std::string* content_type_;
};

testing::TestServer* OpenApiTest::server_ = nullptr;
Value* OpenApiTest::document_ = nullptr;
std::string* OpenApiTest::content_type_ = nullptr;

TEST_F(OpenApiTest, IsAnOpenApi30JsonDocumentServedWithoutAToken) {
  EXPECT_EQ(*content_type_, "application/json");
  EXPECT_THAT(At(*document_, "openapi").string_value(), ::testing::StartsWith("3.0."));
  EXPECT_FALSE(At(At(*document_, "info"), "title").string_value().empty());
  // The comment at the top of service.proto is the API's description.
  EXPECT_THAT(At(At(*document_, "info"), "description").string_value(),
              HasSubstr("google.longrunning"));
}

TEST_F(OpenApiTest, EveryAnnotatedRpcHasAPathWithItsMethodAndItsComment) {
  const std::vector<Annotation> rpcs = AnnotatedRpcs();
  // Jobs has 8 annotated rpcs and Operations 4 (WaitOperation has none); more may come, never
  // fewer.
  EXPECT_GE(rpcs.size(), 12u);
  std::set<std::string> described;
  for (const Annotation& rpc : rpcs) {
    SCOPED_TRACE(rpc.method->full_name());
    const std::string path = OpenApiPathOf(rpc.path_template);
    const Value& paths = At(*document_, "paths");
    ASSERT_TRUE(Has(paths, path)) << path;
    std::string verb = rpc.verb;
    for (char& c : verb) c = static_cast<char>(std::tolower(c));
    ASSERT_TRUE(Has(At(paths, path), verb)) << verb << " " << path;
    const Value& operation = At(At(paths, path), verb);
    EXPECT_EQ(At(operation, "operationId").string_value(), rpc.method->name());
    // Every rpc of these services has a comment: it is the operation's documentation.
    EXPECT_FALSE(At(operation, "description").string_value().empty());
    described.insert(rpc.method->name());
  }
  EXPECT_TRUE(described.count("SubmitSweep"));
  EXPECT_THAT(At(At(At(*document_, "paths"), "/v1/jobs:sweep"), "post").DebugString(),
              HasSubstr("Submits a parameter sweep"));
}

TEST_F(OpenApiTest, PathTemplatesBecomePathParametersAndTheRestQueryParameters) {
  const Value& paths = At(*document_, "paths");
  const Value& result = At(At(paths, "/v1/{name}:result"), "get");
  std::map<std::string, const Value*> parameters;
  for (const Value& p : At(result, "parameters").list_value().values()) {
    parameters[At(p, "name").string_value()] = &p;
  }
  ASSERT_EQ(parameters.count("name"), 1u);
  EXPECT_EQ(At(*parameters["name"], "in").string_value(), "path");
  EXPECT_TRUE(At(*parameters["name"], "required").bool_value());
  const std::regex pattern(At(At(*parameters["name"], "schema"), "pattern").string_value());
  EXPECT_TRUE(std::regex_match("operations/0123abcd", pattern));
  EXPECT_FALSE(std::regex_match("operations/a/b", pattern));  // {name=operations/*}: one segment.
  ASSERT_EQ(parameters.count("page_size"), 1u);
  EXPECT_EQ(At(*parameters["page_size"], "in").string_value(), "query");
  EXPECT_EQ(At(At(*parameters["page_size"], "schema"), "type").string_value(), "integer");
  EXPECT_EQ(parameters.count("page_token"), 1u);
  ASSERT_EQ(parameters.count("X-Server-Timeout"), 1u);
  EXPECT_EQ(At(*parameters["X-Server-Timeout"], "in").string_value(), "header");
  // Nothing else: the request's other fields are the path's or the query's.
  EXPECT_EQ(parameters.size(), 4u);
  EXPECT_FALSE(Has(result, "requestBody"));

  // {name=operations} has no wildcard: the literal path, and no parameter for name.
  const Value& list = At(At(paths, "/v1/operations"), "get");
  for (const Value& p : At(list, "parameters").list_value().values()) {
    EXPECT_NE(At(p, "name").string_value(), "name");
  }
  // body "*": the request message is the body.
  const Value& sweep = At(At(paths, "/v1/jobs:sweep"), "post");
  EXPECT_EQ(RefName(At(At(At(At(sweep, "requestBody"), "content"), "application/json"), "schema")),
            "drillbif.v1.SubmitSweepRequest");
  // GetOperation and DeleteOperation share {name=operations/**}, which admits '/'.
  EXPECT_TRUE(Has(At(paths, "/v1/{name}"), "get"));
  EXPECT_TRUE(Has(At(paths, "/v1/{name}"), "delete"));
}

TEST_F(OpenApiTest, WatchIsAnEventStreamOfJobMetadata) {
  const Value& ok =
      At(At(At(At(At(*document_, "paths"), "/v1/{name}:watch"), "get"), "responses"), "200");
  EXPECT_TRUE(Has(At(ok, "content"), "text/event-stream"));
  EXPECT_THAT(At(ok, "description").string_value(), HasSubstr("drillbif.v1.JobMetadata"));
  EXPECT_TRUE(Has(Schemas(), "drillbif.v1.JobMetadata"));
}

TEST_F(OpenApiTest, EveryReferenceResolves) {
  int refs = 0;
  std::function<void(const Value&)> walk = [&](const Value& value) {
    if (value.has_list_value()) {
      for (const Value& item : value.list_value().values()) walk(item);
    }
    if (!value.has_struct_value()) return;
    for (const auto& [key, member] : value.struct_value().fields()) {
      if (key == "$ref") {
        ++refs;
        const std::string ref = member.string_value();
        ASSERT_EQ(ref.rfind("#/components/", 0), 0u) << ref;
        const std::string rest = ref.substr(std::string("#/components/").size());
        const std::string kind = rest.substr(0, rest.find('/'));
        const std::string name = rest.substr(rest.find('/') + 1);
        EXPECT_TRUE(Has(At(At(*document_, "components"), kind), name)) << ref;
      } else {
        walk(member);
      }
    }
  };
  walk(*document_);
  // Each annotated rpc's output and input at least.
  EXPECT_GE(refs, 2 * static_cast<int>(AnnotatedRpcs().size()));
}

TEST_F(OpenApiTest, MessageSchemasFollowProtobufsJsonMapping) {
  int messages = 0;
  int checked_int64 = 0;
  int checked_enums = 0;
  for (const auto& [name, schema] : Schemas().struct_value().fields()) {
    const Descriptor* message = DescriptorPool::generated_pool()->FindMessageTypeByName(name);
    if (message == nullptr || message->file()->package() == "google.protobuf") continue;
    SCOPED_TRACE(name);
    ++messages;
    EXPECT_EQ(At(schema, "type").string_value(), "object");
    std::set<std::string> properties;
    if (Has(schema, "properties")) {
      for (const auto& [property, unused] : At(schema, "properties").struct_value().fields()) {
        properties.insert(property);
      }
    }
    std::set<std::string> json_names;
    for (int i = 0; i < message->field_count(); ++i) {
      const FieldDescriptor* field = message->field(i);
      json_names.insert(field->json_name());
      if (!properties.count(field->json_name())) continue;
      SCOPED_TRACE(field->name());
      const Value& property = At(At(schema, "properties"), field->json_name());
      if (field->is_map()) {
        EXPECT_EQ(At(property, "type").string_value(), "object");
        continue;
      }
      const Value& single = field->is_repeated() ? At(property, "items") : property;
      if (field->is_repeated()) {
        EXPECT_EQ(At(property, "type").string_value(), "array");
      }
      switch (field->cpp_type()) {
        case FieldDescriptor::CPPTYPE_INT64:
        case FieldDescriptor::CPPTYPE_UINT64:
          // A double holds 53 bits: 64-bit integers are strings in JSON.
          EXPECT_EQ(At(single, "type").string_value(), "string");
          ++checked_int64;
          break;
        case FieldDescriptor::CPPTYPE_INT32:
        case FieldDescriptor::CPPTYPE_UINT32:
          EXPECT_EQ(At(single, "type").string_value(), "integer");
          break;
        case FieldDescriptor::CPPTYPE_DOUBLE:
        case FieldDescriptor::CPPTYPE_FLOAT:
          EXPECT_EQ(At(single, "type").string_value(), "number");
          break;
        case FieldDescriptor::CPPTYPE_BOOL:
          EXPECT_EQ(At(single, "type").string_value(), "boolean");
          break;
        case FieldDescriptor::CPPTYPE_STRING:
          EXPECT_EQ(At(single, "type").string_value(), "string");
          break;
        case FieldDescriptor::CPPTYPE_ENUM: {
          const std::string target = RefName(single);
          ASSERT_EQ(target, field->enum_type()->full_name());
          const Value& enum_schema = At(Schemas(), target);
          EXPECT_EQ(At(enum_schema, "type").string_value(), "string");
          std::vector<std::string> names;
          for (const Value& v : At(enum_schema, "enum").list_value().values()) {
            names.push_back(v.string_value());
          }
          std::vector<std::string> expected;
          for (int v = 0; v < field->enum_type()->value_count(); ++v) {
            expected.push_back(field->enum_type()->value(v)->name());
          }
          EXPECT_EQ(names, expected);
          ++checked_enums;
          break;
        }
        case FieldDescriptor::CPPTYPE_MESSAGE:
          EXPECT_EQ(RefName(single), field->message_type()->full_name());
          break;
      }
    }
    EXPECT_EQ(properties, json_names);
  }
  // The request and result messages of five job kinds and the Operation pattern.
  EXPECT_GE(messages, 30);
  EXPECT_GT(checked_int64, 0);
  EXPECT_GT(checked_enums, 0);
  // Names are the JSON names: lowerCamelCase.
  EXPECT_TRUE(Has(At(At(Schemas(), "drillbif.v1.JobMetadata"), "properties"), "cacheHit"));
}

TEST_F(OpenApiTest, WellKnownTypesAreInTheirJsonForm) {
  const Value& timestamp = At(Schemas(), "google.protobuf.Timestamp");
  EXPECT_EQ(At(timestamp, "type").string_value(), "string");
  EXPECT_EQ(At(timestamp, "format").string_value(), "date-time");
  const Value& any = At(Schemas(), "google.protobuf.Any");
  EXPECT_TRUE(Has(At(any, "properties"), "@type"));
  // Operation.error is a google.rpc.Status; Operation.response an Any.
  EXPECT_TRUE(Has(Schemas(), "google.rpc.Status"));
  EXPECT_EQ(RefName(At(At(At(Schemas(), "google.longrunning.Operation"), "properties"), "error")),
            "google.rpc.Status");
  // A oneof's members say so (the JSON mapping has no oneof: at most one member is present).
  EXPECT_THAT(
      At(At(At(Schemas(), "google.longrunning.Operation"), "properties"), "response").DebugString(),
      HasSubstr("oneof `result`"));
  // The result types an Operation's Any response holds (operation_info) are described too.
  EXPECT_TRUE(Has(Schemas(), "drillbif.v1.SweepResult"));
}

TEST_F(OpenApiTest, ErrorsAndTheBearerSchemeAreDescribed) {
  const Value& components = At(*document_, "components");
  const Value& scheme = At(At(components, "securitySchemes"), "bearerAuth");
  EXPECT_EQ(At(scheme, "type").string_value(), "http");
  EXPECT_EQ(At(scheme, "scheme").string_value(), "bearer");
  EXPECT_TRUE(At(*document_, "security")
                  .list_value()
                  .values(0)
                  .struct_value()
                  .fields()
                  .count("bearerAuth"));
  // Health, metrics and the document need no token.
  for (const char* open : {"/healthz", "/metrics", "/openapi.json"}) {
    EXPECT_EQ(
        At(At(At(At(*document_, "paths"), open), "get"), "security").list_value().values_size(), 0)
        << open;
  }
  const Value& error = At(At(components, "schemas"), "Error");
  for (const char* member : {"code", "message", "details"}) {
    EXPECT_TRUE(Has(At(error, "properties"), member)) << member;
  }
  EXPECT_EQ(
      RefName(At(At(At(At(At(components, "responses"), "Error"), "content"), "application/json"),
                 "schema")),
      "Error");
}

TEST_F(OpenApiTest, IsServedWithCorsToAnAllowedOrigin) {
  httplib::Client client("127.0.0.1", server_->server().http_port());
  httplib::Result actual = client.Get("/openapi.json", {{"Origin", kOrigin}});
  ASSERT_TRUE(actual);
  EXPECT_EQ(actual->status, 200);
  EXPECT_EQ(actual->get_header_value("Access-Control-Allow-Origin"), kOrigin);
  httplib::Result preflight = client.Options(
      "/openapi.json", {{"Origin", kOrigin}, {"Access-Control-Request-Method", "GET"}});
  ASSERT_TRUE(preflight);
  EXPECT_EQ(preflight->status, 204);
  EXPECT_EQ(preflight->get_header_value("Access-Control-Allow-Methods"), "GET");
}

TEST(OpenApiDocument, IsTheSameOnEveryCall) {
  StatusOr<std::string> first = OpenApiJson();
  StatusOr<std::string> second = OpenApiJson();
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  ASSERT_TRUE(second.ok());
  EXPECT_EQ(*first, *second);
  // Sorted keys: "components" comes before "openapi" and "paths" whatever the hash order.
  EXPECT_LT(first->find("\"components\""), first->find("\"openapi\""));
}

TEST(RestRoutes, EveryAnnotatedRpcHasTheRouteOfItsAnnotation) {
  const std::vector<HttpBinding> bindings = AnnotatedBindings();
  EXPECT_EQ(bindings.size(), AnnotatedRpcs().size());
  for (const HttpBinding& binding : bindings) {
    SCOPED_TRACE(binding.method->full_name());
    int found = -1;
    for (int i = 0; i < kRouteCount; ++i) {
      if (binding.verb == kRoutes[i].method && binding.path_template == kRoutes[i].label) found = i;
    }
    ASSERT_GE(found, 0) << binding.verb << " " << binding.path_template << " has no route";
    ASSERT_NE(kRoutes[found].prototype, nullptr);
    EXPECT_EQ(kRoutes[found].prototype()->GetDescriptor(), binding.method->input_type());
    EXPECT_EQ(kRoutes[found].binding == Binding::kBody, binding.body == "*");
  }
}

TEST(RestRoutes, EveryApiRouteIsAnAnnotatedRpc) {
  const std::vector<HttpBinding> bindings = AnnotatedBindings();
  for (int i = 0; i < kRouteCount; ++i) {
    if (kRoutes[i].prototype == nullptr) continue;  // /metrics, /healthz, /openapi.json
    SCOPED_TRACE(kRoutes[i].label);
    bool found = false;
    for (const HttpBinding& binding : bindings) {
      found |= binding.verb == kRoutes[i].method && binding.path_template == kRoutes[i].label;
    }
    EXPECT_TRUE(found) << kRoutes[i].method << " " << kRoutes[i].label
                       << " is in no google.api.http annotation";
  }
}

}  // namespace
}  // namespace drillbif::server
