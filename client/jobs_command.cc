#include "client/jobs_command.h"

#include <google/protobuf/util/time_util.h>

#include <cctype>
#include <charconv>
#include <memory>
#include <string_view>

#include "client/output.h"

namespace drillbif::client {
namespace {

using google::longrunning::Operation;

constexpr char kCsvHeader[] =
    "name,kind,state,progress,points,cache_hit,attempts,create_time,start_time,end_time,error\n";

// A CSV field: quoted (quotes doubled) when it holds a comma, a quote or a line break.
std::string CsvField(std::string_view text) {
  if (text.find_first_of(",\"\n\r") == std::string_view::npos) return std::string(text);
  std::string out("\"");
  for (char c : text) {
    if (c == '"') out.push_back('"');
    out.push_back(c);
  }
  out.push_back('"');
  return out;
}

std::string Number(double v) {
  char buf[32];
  const auto [end, ec] = std::to_chars(buf, buf + sizeof(buf), v);
  return std::string(buf, ec == std::errc() ? end : buf);
}

std::string Time(bool has, const google::protobuf::Timestamp& t) {
  return has ? google::protobuf::util::TimeUtil::ToString(t) : std::string();
}

// The kind as the service names it in filters and the store ("simulate", ...): the enum's own
// name in lower case; empty for JOB_KIND_UNSPECIFIED.
std::string KindText(v1::JobKind kind) {
  if (kind == v1::JOB_KIND_UNSPECIFIED || !v1::JobKind_IsValid(kind)) return std::string();
  std::string name = v1::JobKind_Name(kind);
  for (char& c : name) c = static_cast<char>(std::tolower(static_cast<unsigned char>(c)));
  return name;
}

// One CSV row of kCsvHeader. (Fields are appended one by one: `"," + std::string` trips GCC 12's
// -Wrestrict false positive.)
std::string Row(const v1::JobMetadata& m, const std::string& error) {
  std::string row;
  auto field = [&row](const std::string& text) {
    if (!row.empty()) row.push_back(',');
    row.append(text);
  };
  field(CsvField(m.name()));
  field(KindText(m.kind()));
  field(v1::JobState_Name(m.state()));
  field(Number(m.progress()));
  field(std::to_string(m.points()));
  field(m.cache_hit() ? std::string("true") : std::string("false"));
  field(std::to_string(m.attempts()));
  field(Time(m.has_create_time(), m.create_time()));
  field(Time(m.has_start_time(), m.start_time()));
  field(Time(m.has_end_time(), m.end_time()));
  row.push_back(',');
  row.append(CsvField(error));
  row.push_back('\n');
  return row;
}

std::string ErrorText(const Operation& op) {
  if (!op.has_error() || op.error().code() == 0) return std::string();
  const Status s(static_cast<StatusCode>(op.error().code()), op.error().message());
  return s.ToString();
}

// The operation's row; its name from the operation when the metadata has none.
std::string OperationRow(const Operation& op) {
  v1::JobMetadata m = MetadataOf(op);
  if (m.name().empty()) m.set_name(op.name());
  return Row(m, ErrorText(op));
}

StatusOr<std::string> FormatOperation(const Operation& op, const OutputStyle& style) {
  if (style.csv) return std::string(kCsvHeader) + OperationRow(op);
  return ToJson(op, style.pretty);
}

}  // namespace

StatusOr<std::string> ListFilter(const JobsListOptions& options) {
  std::string filter;
  if (!options.state.empty()) {
    v1::JobState state;
    if (!v1::JobState_Parse(options.state, &state) || state == v1::JOB_STATE_UNSPECIFIED) {
      return InvalidArgument("--state: unknown state '" + options.state +
                             "' (QUEUED, RUNNING, SUCCEEDED, FAILED, CANCELLED)");
    }
    filter = "state=" + options.state;
  }
  if (!options.kind.empty()) {
    bool known = false;
    for (v1::JobKind kind :
         {v1::SIMULATE, v1::SWEEP, v1::CONTINUE, v1::TRACE, v1::OPTIMUM, v1::OPTIMUM_MAP}) {
      known = known || KindText(kind) == options.kind;
    }
    if (!known) {
      return InvalidArgument("--kind: unknown kind '" + options.kind +
                             "' (simulate, sweep, continue, trace, optimum)");
    }
    if (!filter.empty()) filter += " AND ";
    filter += "kind=" + options.kind;
  }
  return filter;
}

StatusOr<std::string> JobsList(RemoteClient& client, const JobsListOptions& options,
                               const OutputStyle& style) {
  StatusOr<std::string> filter = ListFilter(options);
  if (!filter.ok()) return filter.status();
  google::longrunning::ListOperationsResponse all;
  std::string token = options.page_token;
  do {
    StatusOr<google::longrunning::ListOperationsResponse> page =
        client.List(*filter, options.page_size, token);
    if (!page.ok()) return page.status();
    for (const Operation& op : page->operations()) *all.add_operations() = op;
    token = page->next_page_token();
  } while (options.all && !token.empty());
  if (!options.all) all.set_next_page_token(token);

  if (!style.csv) return ToJson(all, style.pretty);
  std::string text(kCsvHeader);
  for (const Operation& op : all.operations()) text += OperationRow(op);
  if (!all.next_page_token().empty()) text += "# next_page_token=" + all.next_page_token() + "\n";
  return text;
}

StatusOr<std::string> JobsGet(RemoteClient& client, const std::string& id,
                              const OutputStyle& style) {
  StatusOr<Operation> op = client.Get(OperationName(id));
  if (!op.ok()) return op.status();
  return FormatOperation(*op, style);
}

StatusOr<std::string> JobsCancel(RemoteClient& client, const std::string& id,
                                 const OutputStyle& style) {
  const std::string name = OperationName(id);
  if (Status s = client.Cancel(name); !s.ok()) return s;
  // A running job stops at its next progress callback (~50 ms): wait briefly for the final state.
  StatusOr<Operation> op = client.Wait(name, 1.0);
  if (!op.ok()) return op.status();
  return FormatOperation(*op, style);
}

StatusOr<v1::JobMetadata> JobsWatch(RemoteClient& client, const std::string& id,
                                    const OutputStyle& style,
                                    const std::function<void(const std::string&)>& write,
                                    const std::function<bool()>& interrupted) {
  if (style.csv) write(kCsvHeader);
  Status format_error;
  StatusOr<v1::JobMetadata> last = client.Watch(
      OperationName(id),
      [&](const v1::JobMetadata& m) {
        if (style.csv) {
          write(Row(m, std::string()));
          return true;
        }
        StatusOr<std::string> json = ToJson(m, /*pretty=*/false);
        if (!json.ok()) {
          format_error = json.status();
          return false;
        }
        write(*json);
        return true;
      },
      interrupted);
  if (!format_error.ok()) return format_error;
  return last;
}

StatusOr<PrintedResult> JobsResult(RemoteClient& client, const std::string& id,
                                   const OutputStyle& style, const TextSink& write) {
  const std::string name = OperationName(id);
  std::unique_ptr<ResultPrinter> printer;
  const Status fetched =
      client.GetResultPages(name, [&](google::protobuf::Message& page) -> Status {
        if (printer == nullptr) {
          PrintOptions options;
          options.csv = style.csv;
          options.pretty = style.pretty;
          // options.simulate_table unset: the table of the items that come.
          DRILLBIF_ASSIGN_OR_RETURN(printer,
                                    ResultPrinter::Create(page.GetDescriptor(), options, write));
        }
        return printer->AddPage(page);
      });
  if (fetched.ok()) {
    DRILLBIF_RETURN_IF_ERROR(printer->Finish());
    return PrintedResult{printer->status(), printer->message()};
  }
  if (printer != nullptr || fetched.code() != StatusCode::kFailedPrecondition) return fetched;
  // Not SUCCEEDED: say why, with the job's own error when it failed (as --local would).
  StatusOr<Operation> op = client.Get(name);
  if (!op.ok()) return fetched;
  const v1::JobMetadata m = MetadataOf(*op);
  if (!op->done()) {
    return Status(StatusCode::kFailedPrecondition,
                  name + " is " + v1::JobState_Name(m.state()) + " (progress " +
                      Number(m.progress()) + "): wait with `drillctl jobs watch " + name + "`");
  }
  if (m.state() == v1::CANCELLED) {
    return Status(StatusCode::kCancelled, name + " was cancelled; it has no result");
  }
  if (op->has_error() && op->error().code() != 0) {
    return internal::ErrorOf(*op);
  }
  return fetched;
}

}  // namespace drillbif::client
