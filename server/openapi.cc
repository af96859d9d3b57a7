#include "server/openapi.h"

#include <google/protobuf/any.pb.h>
#include <google/protobuf/descriptor.pb.h>
#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <google/protobuf/util/type_resolver.h>
#include <google/protobuf/util/type_resolver_util.h>

#include <cctype>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>
#include <utility>

#include "drillbif/v1/service.pb.h"
#include "google/api/annotations.pb.h"
#include "google/longrunning/operations.pb.h"
#include "proto/descriptor_set.h"
#include "server/metrics.h"

namespace drillbif::server {
namespace {

using google::protobuf::Descriptor;
using google::protobuf::DescriptorPool;
using google::protobuf::EnumDescriptor;
using google::protobuf::FieldDescriptor;
using google::protobuf::MethodDescriptor;
using google::protobuf::ServiceDescriptor;
using google::protobuf::SourceLocation;
using google::protobuf::Struct;
using google::protobuf::Value;

// The services the gateway serves: every annotated rpc of these gets a path.
constexpr const char* kServices[] = {"drillbif.v1.Jobs", "google.longrunning.Operations"};
// The proto file whose header comment becomes the document's description.
constexpr char kMainFile[] = "drillbif/v1/service.proto";
constexpr char kSchemaRef[] = "#/components/schemas/";
constexpr char kErrorSchema[] = "Error";
constexpr char kSecurityScheme[] = "bearerAuth";

// --- Building JSON as google.protobuf.Value -----------------------------------------------------

Value Str(const std::string& text) {
  Value v;
  v.set_string_value(text);
  return v;
}

Value Num(double number) {
  Value v;
  v.set_number_value(number);
  return v;
}

Value Bool(bool flag) {
  Value v;
  v.set_bool_value(flag);
  return v;
}

Value Obj(std::initializer_list<std::pair<const char*, Value>> members = {}) {
  Value v;
  auto* fields = v.mutable_struct_value()->mutable_fields();
  for (const auto& [key, value] : members) (*fields)[key] = value;
  return v;
}

Value Arr(const std::vector<Value>& items) {
  Value v;
  v.mutable_list_value();  // An empty list is still a list ("security": []).
  for (const Value& item : items) *v.mutable_list_value()->add_values() = item;
  return v;
}

// Sets `key` of the object `object` (made an object if it is not).
void Set(Value* object, const std::string& key, Value value) {
  (*object->mutable_struct_value()->mutable_fields())[key] = std::move(value);
}

Value* Member(Value* object, const std::string& key) {
  return &(*object->mutable_struct_value()->mutable_fields())[key];
}

Value Ref(const std::string& full_name) { return Obj({{"$ref", Str(kSchemaRef + full_name)}}); }

// JSON text of `value` with the keys of every object sorted: the Struct is serialized
// deterministically (map entries in key order) and printed from those bytes, so the document is
// the same byte for byte on every run.
StatusOr<std::string> PrintSorted(const Value& value) {
  std::string bytes;
  {
    google::protobuf::io::StringOutputStream stream(&bytes);
    google::protobuf::io::CodedOutputStream coded(&stream);
    coded.SetSerializationDeterministic(true);
    if (!value.SerializeToCodedStream(&coded)) return Internal("openapi: cannot serialize");
  }
  std::unique_ptr<google::protobuf::util::TypeResolver> resolver(
      google::protobuf::util::NewTypeResolverForDescriptorPool("type.googleapis.com",
                                                               DescriptorPool::generated_pool()));
  google::protobuf::util::JsonPrintOptions options;
  options.add_whitespace = true;
  std::string json;
  const auto status = google::protobuf::util::BinaryToJsonString(
      resolver.get(), "type.googleapis.com/google.protobuf.Value", bytes, &json, options);
  if (!status.ok()) return Internal("openapi: cannot print: " + std::string(status.message()));
  return json;
}

// --- Comments ------------------------------------------------------------------------------------

// The proto comments, from the embedded descriptor set (the generated pool keeps none), looked
// up by the full name of a descriptor of the generated pool.
class Comments {
 public:
  Status Load() {
    google::protobuf::FileDescriptorSet set;
    const std::string_view bytes = proto::DescriptorSet();
    if (!set.ParseFromArray(bytes.data(), static_cast<int>(bytes.size()))) {
      return Internal("openapi: the embedded descriptor set does not parse");
    }
    for (const auto& file : set.file()) {
      if (pool_.BuildFile(file) == nullptr) {
        return Internal("openapi: cannot build " + file.name() + " from the descriptor set");
      }
    }
    return Status::Ok();
  }

  std::string Of(const Descriptor* d) const {
    return Text(pool_.FindMessageTypeByName(d->full_name()));
  }
  std::string Of(const FieldDescriptor* d) const {
    return Text(d->is_extension() ? nullptr : pool_.FindFieldByName(d->full_name()));
  }
  std::string Of(const EnumDescriptor* d) const {
    return Text(pool_.FindEnumTypeByName(d->full_name()));
  }
  std::string Of(const google::protobuf::EnumValueDescriptor* d) const {
    return Text(pool_.FindEnumValueByName(d->full_name()));
  }
  std::string Of(const ServiceDescriptor* d) const {
    return Text(pool_.FindServiceByName(d->full_name()));
  }
  std::string Of(const MethodDescriptor* d) const {
    return Text(pool_.FindMethodByName(d->full_name()));
  }

  // The comment before `syntax = ...` of `file`: the file's overview.
  std::string OfFile(const std::string& file) const {
    const google::protobuf::FileDescriptor* found = pool_.FindFileByName(file);
    SourceLocation location;
    if (found == nullptr ||
        !found->GetSourceLocation({google::protobuf::FileDescriptorProto::kSyntaxFieldNumber},
                                  &location)) {
      return "";
    }
    std::string text;
    for (const std::string& detached : location.leading_detached_comments) text += detached + "\n";
    return Clean(text + location.leading_comments);
  }

 private:
  // A comment without the space protoc keeps after "//" and without trailing blanks.
  static std::string Clean(const std::string& raw) {
    std::istringstream lines(raw);
    std::string line;
    std::string out;
    while (std::getline(lines, line)) {
      if (!line.empty() && line.front() == ' ') line.erase(0, 1);
      while (!line.empty() && std::isspace(static_cast<unsigned char>(line.back())))
        line.pop_back();
      out += line + "\n";
    }
    while (!out.empty() && (out.back() == '\n' || out.front() == '\n')) {
      if (out.back() == '\n') out.pop_back();
      if (!out.empty() && out.front() == '\n') out.erase(0, 1);
    }
    return out;
  }

  template <typename D>
  static std::string Text(const D* d) {
    SourceLocation location;
    if (d == nullptr || !d->GetSourceLocation(&location)) return "";
    return Clean(location.leading_comments.empty() ? location.trailing_comments
                                                   : location.leading_comments);
  }

  DescriptorPool pool_;
};

// --- Schemas (protobuf's JSON mapping) -----------------------------------------------------------

// Adds `text` as the description of `schema`. A $ref admits no sibling in OpenAPI 3.0, so a
// described reference becomes allOf: [the reference].
Value Described(Value schema, const std::string& text) {
  if (text.empty()) return schema;
  if (schema.struct_value().fields().count("$ref") != 0) schema = Obj({{"allOf", Arr({schema})}});
  Set(&schema, "description", Str(text));
  return schema;
}

class Generator {
 public:
  explicit Generator(const Comments* comments) : comments_(comments) {}

  // A reference to the schema of `message`, added to the components (with what it reaches).
  Value RefTo(const Descriptor* message) {
    AddMessage(message);
    return Ref(message->full_name());
  }

  Value RefTo(const EnumDescriptor* type) {
    if (added_.insert(type->full_name()).second) {
      std::vector<Value> names;
      for (int i = 0; i < type->value_count(); ++i) names.push_back(Str(type->value(i)->name()));
      std::string text = comments_->Of(type);
      std::string values;
      for (int i = 0; i < type->value_count(); ++i) {
        const std::string about = comments_->Of(type->value(i));
        if (!about.empty()) values += "\n- `" + type->value(i)->name() + "`: " + about;
      }
      if (!values.empty()) text += (text.empty() ? "" : "\n") + values;
      Value schema = Obj({{"type", Str("string")}, {"enum", Arr(names)}});
      (*schemas_.mutable_fields())[type->full_name()] = Described(schema, text);
    }
    return Ref(type->full_name());
  }

  // The schema of a field: its type, an array of it (repeated), or an object (map).
  Value FieldSchema(const FieldDescriptor* field) {
    Value schema;
    if (field->is_map()) {
      schema = Obj({{"type", Str("object")},
                    {"additionalProperties", Single(field->message_type()->map_value())}});
    } else if (field->is_repeated()) {
      schema = Obj({{"type", Str("array")}, {"items", Single(field)}});
    } else {
      schema = Single(field);
    }
    std::string text = comments_->Of(field);
    const google::protobuf::OneofDescriptor* oneof = field->real_containing_oneof();
    if (oneof != nullptr) {
      std::string members;
      for (int i = 0; i < oneof->field_count(); ++i) {
        members += std::string(i == 0 ? "" : ", ") + "`" + oneof->field(i)->json_name() + "`";
      }
      text += std::string(text.empty() ? "" : "\n\n") + "One of " + members + " (oneof `" +
              oneof->name() + "`): at most one is set.";
    }
    return Described(schema, text);
  }

  Struct& schemas() { return schemas_; }

 private:
  // The schema of one value of `field` (an element of a repeated field).
  Value Single(const FieldDescriptor* field) {
    switch (field->type()) {
      case FieldDescriptor::TYPE_DOUBLE:
        return Obj({{"type", Str("number")}, {"format", Str("double")}});
      case FieldDescriptor::TYPE_FLOAT:
        return Obj({{"type", Str("number")}, {"format", Str("float")}});
      case FieldDescriptor::TYPE_INT32:
      case FieldDescriptor::TYPE_SINT32:
      case FieldDescriptor::TYPE_SFIXED32:
        return Obj({{"type", Str("integer")}, {"format", Str("int32")}});
      case FieldDescriptor::TYPE_UINT32:
      case FieldDescriptor::TYPE_FIXED32:
        return Obj({{"type", Str("integer")},
                    {"format", Str("int64")},
                    {"minimum", Num(0)},
                    {"maximum", Num(4294967295.0)}});
      // 64-bit integers are JSON strings: a double holds only 53 bits.
      case FieldDescriptor::TYPE_INT64:
      case FieldDescriptor::TYPE_SINT64:
      case FieldDescriptor::TYPE_SFIXED64:
        return Obj({{"type", Str("string")}, {"format", Str("int64")}});
      case FieldDescriptor::TYPE_UINT64:
      case FieldDescriptor::TYPE_FIXED64:
        return Obj({{"type", Str("string")}, {"format", Str("uint64")}});
      case FieldDescriptor::TYPE_BOOL:
        return Obj({{"type", Str("boolean")}});
      case FieldDescriptor::TYPE_STRING:
        return Obj({{"type", Str("string")}});
      case FieldDescriptor::TYPE_BYTES:
        return Obj({{"type", Str("string")}, {"format", Str("byte")}});
      case FieldDescriptor::TYPE_ENUM:
        if (field->enum_type()->full_name() == "google.protobuf.NullValue") {
          return Obj({{"nullable", Bool(true)}});
        }
        return RefTo(field->enum_type());
      case FieldDescriptor::TYPE_MESSAGE:
      case FieldDescriptor::TYPE_GROUP:
        return RefTo(field->message_type());
    }
    return Obj();
  }

  // The schema of a well-known type, which the JSON mapping prints in its own way; nullopt for
  // any other message.
  std::optional<Value> WellKnown(const Descriptor* message) {
    const std::string& name = message->full_name();
    if (name == "google.protobuf.Timestamp") {
      return Obj({{"type", Str("string")},
                  {"format", Str("date-time")},
                  {"example", Str("2026-01-02T03:04:05.678Z")}});
    }
    if (name == "google.protobuf.Duration") {
      return Obj({{"type", Str("string")},
                  {"pattern", Str("^-?[0-9]+(\\.[0-9]{1,9})?s$")},
                  {"example", Str("1.500s")}});
    }
    if (name == "google.protobuf.FieldMask") return Obj({{"type", Str("string")}});
    if (name == "google.protobuf.Empty") return Obj({{"type", Str("object")}});
    if (name == "google.protobuf.Struct") {
      return Obj({{"type", Str("object")}, {"additionalProperties", Bool(true)}});
    }
    if (name == "google.protobuf.Value") return Obj();  // Any JSON value.
    if (name == "google.protobuf.ListValue") {
      return Obj({{"type", Str("array")}, {"items", Obj()}});
    }
    if (name == "google.protobuf.Any") {
      return Obj({{"type", Str("object")},
                  {"properties", Obj({{"@type", Obj({{"type", Str("string")}})}})},
                  {"required", Arr({Str("@type")})},
                  {"additionalProperties", Bool(true)}});
    }
    if (message->file()->name() == "google/protobuf/wrappers.proto") {
      Value schema = Single(message->FindFieldByName("value"));
      Set(&schema, "nullable", Bool(true));
      return schema;
    }
    return std::nullopt;
  }

  void AddMessage(const Descriptor* message) {
    if (!added_.insert(message->full_name()).second) return;
    const std::string text = comments_->Of(message);
    if (std::optional<Value> known = WellKnown(message)) {
      (*schemas_.mutable_fields())[message->full_name()] = Described(*known, text);
      return;
    }
    Value schema = Obj({{"type", Str("object")}});
    Value properties = Obj();
    for (int i = 0; i < message->field_count(); ++i) {
      const FieldDescriptor* field = message->field(i);
      Set(&properties, field->json_name(), FieldSchema(field));
    }
    if (message->field_count() > 0) Set(&schema, "properties", properties);
    (*schemas_.mutable_fields())[message->full_name()] = Described(schema, text);
  }

  const Comments* comments_;
  Struct schemas_;
  std::set<std::string> added_;
};

// --- Paths ---------------------------------------------------------------------------------------

// A path template turned into an OpenAPI path: "{name=operations/*}" becomes "{name}" with a
// path parameter, and a variable without a wildcard ("{name=operations}") its literal text.
struct OpenApiPath {
  std::string path;
  std::vector<std::pair<std::string, std::string>> parameters;  // (field path, regex)
  std::set<std::string> bound;                                  // fields set by the path
};

OpenApiPath ConvertTemplate(const std::string& path_template) {
  OpenApiPath out;
  size_t at = 0;
  while (at < path_template.size()) {
    const size_t open = path_template.find('{', at);
    const size_t close = open == std::string::npos ? open : path_template.find('}', open);
    if (close == std::string::npos) {
      out.path += path_template.substr(at);
      break;
    }
    out.path += path_template.substr(at, open - at);
    const std::string variable = path_template.substr(open + 1, close - open - 1);
    const size_t equals = variable.find('=');
    const std::string field = variable.substr(0, equals);
    const std::string pattern = equals == std::string::npos ? "*" : variable.substr(equals + 1);
    out.bound.insert(field);
    if (pattern.find('*') == std::string::npos) {
      out.path += pattern;
    } else {
      // Segments: "*" one without '/', "**" anything (RFC 6570 has no such syntax: say it as a
      // pattern of the parameter's value).
      std::string regex = "^";
      size_t from = 0;
      while (from <= pattern.size()) {
        size_t slash = pattern.find('/', from);
        if (slash == std::string::npos) slash = pattern.size();
        const std::string segment = pattern.substr(from, slash - from);
        if (from != 0) regex += "/";
        regex += segment == "**" ? ".+" : segment == "*" ? "[^/]+" : segment;
        from = slash + 1;
      }
      out.path += "{" + field + "}";
      out.parameters.emplace_back(field, regex + "$");
    }
    at = close + 1;
  }
  return out;
}

// The description of an operation's Operation: the types of its metadata and response
// (google.longrunning.operation_info), whose schemas are added.
std::string OperationInfo(const MethodDescriptor* method, Generator* generator) {
  if (!method->options().HasExtension(google::longrunning::operation_info)) return "";
  const auto& info = method->options().GetExtension(google::longrunning::operation_info);
  std::string text;
  for (const auto& [what, type] :
       {std::pair<const char*, std::string>{"response", info.response_type()},
        {"metadata", info.metadata_type()}}) {
    if (type.empty()) continue;
    const DescriptorPool* pool = DescriptorPool::generated_pool();
    const Descriptor* found = pool->FindMessageTypeByName(type);
    if (found == nullptr) {
      found = pool->FindMessageTypeByName(method->file()->package() + "." + type);
    }
    if (found == nullptr) continue;
    generator->RefTo(found);
    text += std::string("\n\nThe Operation's `") + what + "` is a `" + found->full_name() +
            "` (schema " + kSchemaRef + found->full_name() + ").";
  }
  return text;
}

Value OperationOf(const HttpBinding& binding, const OpenApiPath& path, int index,
                  const Comments& comments, Generator* generator) {
  const MethodDescriptor* method = binding.method;
  const Descriptor* input = method->input_type();
  Value operation = Obj({
      {"operationId", Str(method->name() + (index == 0 ? "" : "_" + std::to_string(index)))},
      {"tags", Arr({Str(method->service()->name())})},
  });
  const std::string description = comments.Of(method) + OperationInfo(method, generator);
  if (!description.empty()) Set(&operation, "description", Str(description));
  const std::string summary = description.substr(0, description.find_first_of(".\n"));
  if (!summary.empty()) Set(&operation, "summary", Str(summary));

  std::vector<Value> parameters;
  for (const auto& [field_path, regex] : path.parameters) {
    const FieldDescriptor* field = input->FindFieldByName(field_path);
    Value schema = Obj({{"type", Str("string")}, {"pattern", Str(regex)}});
    Value parameter = Obj({{"name", Str(field_path)},
                           {"in", Str("path")},
                           {"required", Bool(true)},
                           {"schema", schema}});
    const std::string text = field != nullptr ? comments.Of(field) : "";
    Set(&parameter, "description",
        Str(text + (text.empty() ? "" : "\n\n") +
            "Its '/' may be sent as is or percent-encoded (%2F)."));
    parameters.push_back(parameter);
  }
  if (binding.body.empty()) {
    // Every other scalar field is a query parameter (by its proto name; the lowerCamelCase JSON
    // name is accepted too).
    for (int i = 0; i < input->field_count(); ++i) {
      const FieldDescriptor* field = input->field(i);
      if (path.bound.count(field->name()) != 0 || field->is_repeated() ||
          field->type() == FieldDescriptor::TYPE_MESSAGE) {
        continue;
      }
      Value schema = generator->FieldSchema(field);
      schema.mutable_struct_value()->mutable_fields()->erase("description");  // The parameter's.
      Value parameter =
          Obj({{"name", Str(field->name())}, {"in", Str("query")}, {"schema", schema}});
      if (const std::string text = comments.Of(field); !text.empty()) {
        Set(&parameter, "description", Str(text));
      }
      parameters.push_back(parameter);
    }
  } else {
    const Value schema = binding.body == "*"
                             ? generator->RefTo(input)
                             : generator->FieldSchema(input->FindFieldByName(binding.body));
    Set(&operation, "requestBody",
        Obj({{"required", Bool(path.bound.empty())},
             {"content", Obj({{"application/json", Obj({{"schema", schema}})}})}}));
  }
  if (!method->server_streaming()) {
    // The gateway's deadline of the call (a stream has none: it lasts as long as the job).
    parameters.push_back(Obj(
        {{"name", Str("X-Server-Timeout")},
         {"in", Str("header")},
         {"description", Str("Deadline of the call in seconds (default 60, at most 600).")},
         {"schema",
          Obj({{"type", Str("number")}, {"exclusiveMinimum", Bool(true)}, {"minimum", Num(0)}})}}));
  }
  if (!parameters.empty()) Set(&operation, "parameters", Arr(parameters));

  Value ok;
  const Value output = generator->RefTo(method->output_type());
  if (method->server_streaming()) {
    ok =
        Obj({{"description",
              Str("Server-Sent Events: one event `data: <" + method->output_type()->full_name() +
                  " JSON>` per message (schema " + kSchemaRef + method->output_type()->full_name() +
                  "); a stream that ends with an error sends `event: error` with `data: <" +
                  kErrorSchema + " JSON>` last.")},
             {"content",
              Obj({{"text/event-stream", Obj({{"schema", Obj({{"type", Str("string")}})}})}})}});
  } else {
    ok = Obj({{"description", Str("OK")},
              {"content", Obj({{"application/json", Obj({{"schema", output}})}})}});
  }
  Set(&operation, "responses",
      Obj({{"200", ok}, {"default", Obj({{"$ref", Str("#/components/responses/Error")}})}}));
  return operation;
}

// The gateway's routes that are not rpcs: open (no token), described by hand.
void AddOwnRoutes(Value* paths) {
  const auto open = [](const char* id, const char* summary, const char* type, Value schema) {
    return Obj(
        {{"operationId", Str(id)},
         {"summary", Str(summary)},
         {"tags", Arr({Str("Server")})},
         {"security", Arr({})},
         {"responses", Obj({{"200", Obj({{"description", Str("OK")},
                                         {"content", Obj({{type, Obj({{"schema", schema}})}})}})},
                            {"default", Obj({{"$ref", Str("#/components/responses/Error")}})}})}});
  };
  const Value health =
      Obj({{"type", Str("object")},
           {"properties",
            Obj({{"status",
                  Obj({{"type", Str("string")},
                       {"enum", Arr({Str("SERVING"), Str("NOT_SERVING"), Str("UNKNOWN")})}})}})}});
  Set(paths, "/healthz",
      Obj({{"get",
            open("GetHealth",
                 "The gRPC health service's check of the whole server: 200 SERVING, else 503",
                 "application/json", health)}}));
  Set(paths, "/metrics",
      Obj({{"get", open("GetMetrics", "Prometheus metrics (text format 0.0.4)", "text/plain",
                        Obj({{"type", Str("string")}}))}}));
  Set(paths, "/openapi.json",
      Obj({{"get", open("GetOpenApi", "This document (OpenAPI 3.0, generated from the protos)",
                        "application/json", Obj({{"type", Str("object")}}))}}));
}

// A tag per served service (its operations carry it), described by the service's comment when
// it has one, and one for the gateway's own routes.
Value Tags(const Comments& comments) {
  std::vector<Value> tags;
  for (const char* name : kServices) {
    const ServiceDescriptor* service = DescriptorPool::generated_pool()->FindServiceByName(name);
    if (service == nullptr) continue;
    Value tag = Obj({{"name", Str(service->name())}});
    if (const std::string text = comments.Of(service); !text.empty()) {
      Set(&tag, "description", Str(text));
    }
    tags.push_back(tag);
  }
  tags.push_back(Obj({{"name", Str("Server")},
                      {"description", Str("Health, metrics and this document; no token.")}}));
  return Arr(tags);
}

StatusOr<std::string> Build() {
  Comments comments;
  DRILLBIF_RETURN_IF_ERROR(comments.Load());
  Generator generator(&comments);

  Value paths = Obj();
  std::map<std::string, int> seen;  // operationId -> bindings so far (additional_bindings)
  for (const HttpBinding& binding : AnnotatedBindings()) {
    const OpenApiPath path = ConvertTemplate(binding.path_template);
    const int index = seen[binding.method->full_name()]++;
    std::string verb = binding.verb;
    for (char& c : verb) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
    Set(Member(&paths, path.path), verb, OperationOf(binding, path, index, comments, &generator));
  }
  AddOwnRoutes(&paths);

  std::vector<Value> codes;
  for (int code = 0; code <= 16; ++code) codes.push_back(Str(GrpcCodeName(code)));
  (*generator.schemas().mutable_fields())[kErrorSchema] = Obj({
      {"type", Str("object")},
      {"description",
       Str("The gateway's error body: the gRPC status code's name, a message, and the "
           "google.rpc.Status details (each an Any in the JSON mapping).")},
      {"properties",
       Obj({{"code", Obj({{"type", Str("string")}, {"enum", Arr(codes)}})},
            {"message", Obj({{"type", Str("string")}})},
            {"details", Obj({{"type", Str("array")},
                             {"items", generator.RefTo(google::protobuf::Any::descriptor())}})}})},
      {"required", Arr({Str("code"), Str("message"), Str("details")})},
  });

  Value components = Obj();
  Value schemas;
  *schemas.mutable_struct_value() = generator.schemas();
  Set(&components, "schemas", schemas);
  Set(&components, "responses",
      Obj({{"Error", Obj({{"description",
                           Str("An error: 400 INVALID_ARGUMENT / FAILED_PRECONDITION, 401 "
                               "UNAUTHENTICATED, 403 PERMISSION_DENIED, 404 NOT_FOUND, 405, 409 "
                               "ALREADY_EXISTS / ABORTED, 411, 413, 414, 431, 429 "
                               "RESOURCE_EXHAUSTED, 500, 501, 503 UNAVAILABLE, 504 "
                               "DEADLINE_EXCEEDED.")},
                          {"content",
                           Obj({{"application/json", Obj({{"schema", Ref(kErrorSchema)}})}})}})}}));
  Set(&components, "securitySchemes",
      Obj({{kSecurityScheme,
            Obj({{"type", Str("http")},
                 {"scheme", Str("bearer")},
                 {"description",
                  Str("\"Authorization: Bearer <token>\" with a token of the server's --token or "
                      "--tokens-file; needed only when the server has tokens.")}})}}));

  std::string description = comments.OfFile(kMainFile);
  const Value document = Obj({
      {"openapi", Str("3.0.3")},
      {"info", Obj({{"title", Str("drillbif")},
                    {"version", Str("v1")},
                    {"description", Str(description)}})},
      {"security", Arr({Obj({{kSecurityScheme, Arr({})}})})},
      {"tags", Tags(comments)},
      {"paths", paths},
      {"components", components},
  });
  return PrintSorted(document);
}

}  // namespace

std::vector<HttpBinding> AnnotatedBindings() {
  std::vector<HttpBinding> bindings;
  const auto add = [&bindings](const MethodDescriptor* method, const google::api::HttpRule& rule) {
    HttpBinding binding;
    binding.method = method;
    binding.body = rule.body();
    switch (rule.pattern_case()) {
      case google::api::HttpRule::kGet:
        binding.verb = "GET";
        binding.path_template = rule.get();
        break;
      case google::api::HttpRule::kPut:
        binding.verb = "PUT";
        binding.path_template = rule.put();
        break;
      case google::api::HttpRule::kPost:
        binding.verb = "POST";
        binding.path_template = rule.post();
        break;
      case google::api::HttpRule::kDelete:
        binding.verb = "DELETE";
        binding.path_template = rule.delete_();
        break;
      case google::api::HttpRule::kPatch:
        binding.verb = "PATCH";
        binding.path_template = rule.patch();
        break;
      case google::api::HttpRule::kCustom:
        binding.verb = rule.custom().kind();
        binding.path_template = rule.custom().path();
        break;
      default:
        return;
    }
    bindings.push_back(std::move(binding));
  };
  for (const char* name : kServices) {
    const ServiceDescriptor* service = DescriptorPool::generated_pool()->FindServiceByName(name);
    if (service == nullptr) continue;
    for (int i = 0; i < service->method_count(); ++i) {
      const MethodDescriptor* method = service->method(i);
      if (!method->options().HasExtension(google::api::http)) continue;
      const google::api::HttpRule& rule = method->options().GetExtension(google::api::http);
      add(method, rule);
      for (const google::api::HttpRule& more : rule.additional_bindings()) add(method, more);
    }
  }
  return bindings;
}

StatusOr<std::string> OpenApiJson() {
  static const StatusOr<std::string>* const document = new StatusOr<std::string>(Build());
  return *document;
}

}  // namespace drillbif::server
