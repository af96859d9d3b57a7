#include "client/output.h"

#include <google/protobuf/io/coded_stream.h>
#include <google/protobuf/io/zero_copy_stream_impl_lite.h>
#include <google/protobuf/reflection.h>
#include <google/protobuf/util/json_util.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string_view>
#include <utility>

#include "jobs/registry.h"

namespace drillbif::client {
namespace {

// Shortest decimal form that reads back to the same double ("0.1", "-60.184375812345678").
void AppendNumber(double v, std::string* out) {
  char buf[32];
  const auto [end, ec] = std::to_chars(buf, buf + sizeof(buf), v);
  out->append(buf, ec == std::errc() ? end : buf);
}

void AppendInt(long long v, std::string* out) { out->append(std::to_string(v)); }

// Appends one CSV row: fields joined by commas, End() closes the line.
class Row {
 public:
  explicit Row(std::string* out) : out_(out) {}
  void End() { out_->push_back('\n'); }
  Row& Str(std::string_view s) {
    Sep();
    out_->append(s);
    return *this;
  }
  Row& Num(double v) {
    Sep();
    AppendNumber(v, out_);
    return *this;
  }
  Row& Int(long long v) {
    Sep();
    AppendInt(v, out_);
    return *this;
  }

 private:
  void Sep() {
    if (!first_) out_->push_back(',');
    first_ = false;
  }
  std::string* out_;
  bool first_ = true;
};

std::string_view ModeName(int mode) { return v1::Mode_Name(static_cast<v1::Mode>(mode)); }

// A comment line "# text"; newlines in the text become spaces to keep it one line.
void AppendComment(std::string_view text, std::string* out) {
  out->append("# ");
  for (char c : text) out->push_back(c == '\n' || c == '\r' ? ' ' : c);
  out->push_back('\n');
}

// "# status=FAILED" and "# message=..." when a run did not complete.
void AppendStatus(const std::string& status, const std::string& message, std::string* out) {
  if (status == "COMPLETED") return;
  AppendComment("status=" + status, out);
  AppendComment("message=" + message, out);
}

// Protobuf's JSON printer writes '<' and '>' as \u003c and \u003e (safe to embed in HTML);
// drillctl prints them as themselves, so that signatures read as written ("NC>Pi CwoP>l1 ...").
// The JSON value is the same. Backslashes occur only inside strings, and every other escape
// sequence is copied whole, so an escaped backslash followed by "u003e" is left alone.
std::string UnescapeAngleBrackets(const std::string& json) {
  std::string out;
  out.reserve(json.size());
  for (size_t i = 0; i < json.size(); ++i) {
    if (json[i] != '\\') {
      out.push_back(json[i]);
    } else if (json.compare(i, 6, "\\u003c") == 0 || json.compare(i, 6, "\\u003C") == 0) {
      out.push_back('<');
      i += 5;
    } else if (json.compare(i, 6, "\\u003e") == 0 || json.compare(i, 6, "\\u003E") == 0) {
      out.push_back('>');
      i += 5;
    } else {
      out.push_back(json[i]);
      if (i + 1 < json.size()) out.push_back(json[++i]);
    }
  }
  return out;
}

}  // namespace

StatusOr<std::string> ToJson(const google::protobuf::Message& message, bool pretty) {
  google::protobuf::util::JsonPrintOptions options;
  options.add_whitespace = pretty;
  options.always_print_primitive_fields = true;
  options.preserve_proto_field_names = false;
  std::string json;
  const auto status = google::protobuf::util::MessageToJsonString(message, &json, options);
  if (!status.ok()) return Internal("cannot print the result as JSON: " + status.ToString());
  json = UnescapeAngleBrackets(json);
  if (json.empty() || json.back() != '\n') json.push_back('\n');
  return json;
}

StatusOr<SimulateTable> CsvTableFor(const v1::SimulateRequest::Outputs& outputs) {
  SimulateTable table = SimulateTable::kNone;
  int tables = 0;
  if (outputs.poincare()) table = SimulateTable::kPoincare, ++tables;
  if (outputs.events()) table = SimulateTable::kEvents, ++tables;
  if (outputs.modes()) table = SimulateTable::kModes, ++tables;
  if (outputs.trajectory_dt() > 0.0) table = SimulateTable::kTrajectory, ++tables;
  if (tables > 1) {
    return InvalidArgument(
        "CSV holds one table: request at most one of Poincare samples, events, modes and "
        "trajectory with it (or use JSON)");
  }
  return table;
}

namespace {

// ---------------------------------------------------------------------------------------------
// The pieces of each kind's CSV, shared by the whole-result functions below and the page formats
// of ResultPrinter.

constexpr char kPoincareHeader[] = "period,mode,p,y,q\n";
constexpr char kEventsHeader[] = "period,s,t,surface,guard,from_mode,to_mode,tangential,p,y,q\n";
constexpr char kModesHeader[] = "period,modes\n";
constexpr char kTrajectoryHeader[] = "t,mode,p,y,q,s\n";
constexpr char kSweepHeader[] = "direction,value,period,p,y,q,start\n";
constexpr char kContinueHeader[] = "value,rop,power,period,stable,signature_text,mu_abs_max\n";
constexpr char kTraceHeader[] = "curve,kind,a,b,omega,xi,g,phi0,rop,stable\n";

const char* TableHeader(SimulateTable table) {
  switch (table) {
    case SimulateTable::kPoincare:
      return kPoincareHeader;
    case SimulateTable::kEvents:
      return kEventsHeader;
    case SimulateTable::kModes:
      return kModesHeader;
    case SimulateTable::kTrajectory:
      return kTrajectoryHeader;
    case SimulateTable::kNone:
      break;
  }
  return "";
}

// The table a simulate result's paged field fills (kNone for any other field).
SimulateTable TableOfField(const std::string& name) {
  if (name == "poincare") return SimulateTable::kPoincare;
  if (name == "events") return SimulateTable::kEvents;
  if (name == "period_modes") return SimulateTable::kModes;
  if (name == "trajectory") return SimulateTable::kTrajectory;
  return SimulateTable::kNone;
}

void AppendRow(const v1::PoincarePoint& pt, std::string* out) {
  Row(out).Int(pt.period()).Str(ModeName(pt.mode())).Num(pt.p()).Num(pt.y()).Num(pt.q()).End();
}

void AppendRow(const v1::Event& e, std::string* out) {
  Row(out)
      .Int(e.period())
      .Num(e.s())
      .Num(e.t())
      .Str(e.surface())
      .Str(e.guard())
      .Str(ModeName(e.from_mode()))
      .Str(ModeName(e.to_mode()))
      .Str(e.tangential() ? "true" : "false")
      .Num(e.p())
      .Num(e.y())
      .Num(e.q())
      .End();
}

void AppendRow(const v1::PeriodModes& pm, std::string* out) {
  std::string modes;
  for (int m : pm.modes()) modes.append(modes.empty() ? "" : " ").append(ModeName(m));
  Row(out).Int(pm.period()).Str(modes).End();
}

void AppendRow(const v1::TrajectoryPoint& tp, std::string* out) {
  Row(out)
      .Num(tp.t())
      .Str(ModeName(tp.mode()))
      .Num(tp.p())
      .Num(tp.y())
      .Num(tp.q())
      .Num(tp.s())
      .End();
}

// The rows of `table` from the items in `result` (the other tables' items are not printed).
void AppendTableRows(const v1::SimulateResult& result, SimulateTable table, std::string* out) {
  switch (table) {
    case SimulateTable::kNone:
      break;
    case SimulateTable::kPoincare:
      for (const v1::PoincarePoint& pt : result.poincare()) AppendRow(pt, out);
      break;
    case SimulateTable::kEvents:
      for (const v1::Event& e : result.events()) AppendRow(e, out);
      break;
    case SimulateTable::kModes:
      for (const v1::PeriodModes& pm : result.period_modes()) AppendRow(pm, out);
      break;
    case SimulateTable::kTrajectory:
      for (const v1::TrajectoryPoint& tp : result.trajectory()) AppendRow(tp, out);
      break;
  }
}

// A simulate CSV's lines before its table: status, rop and power.
void AppendSimulateHead(const v1::SimulateResult& result, std::string* out) {
  AppendStatus(result.status(), result.message(), out);
  if (result.has_rop()) {
    std::string line = "rop=";
    AppendNumber(result.rop(), &line);
    AppendComment(line, out);
  }
  if (result.has_power()) {
    std::string line = "power=";
    AppendNumber(result.power(), &line);
    AppendComment(line, out);
  }
}

// "# up value=... status=... message=..." of a sweep value that did not complete.
void AppendSweepFailure(std::string_view direction, const v1::SweepPoint& pt, std::string* out) {
  if (pt.status() == "COMPLETED") return;
  std::string line(direction);
  line.append(" value=");
  AppendNumber(pt.value(), &line);
  line.append(" status=").append(pt.status()).append(" message=").append(pt.message());
  AppendComment(line, out);
}

// One row per Poincare sample of a sweep value, with how the value was started.
void AppendSweepRows(std::string_view direction, const v1::SweepPoint& pt, std::string* out) {
  const std::string& start = v1::SweepPoint::Start_Name(pt.start());
  for (const v1::PoincarePoint& s : pt.samples()) {
    Row(out)
        .Str(direction)
        .Num(pt.value())
        .Int(s.period())
        .Num(s.p())
        .Num(s.y())
        .Num(s.q())
        .Str(start)
        .End();
  }
}

void AppendBranchRow(const v1::BranchPoint& pt, std::string* out) {
  double mu_abs_max = 0.0;
  for (const v1::Multiplier& mu : pt.multipliers()) mu_abs_max = std::max(mu_abs_max, mu.abs());
  Row(out)
      .Num(pt.value())
      .Num(pt.rop())
      .Num(pt.power())
      .Num(pt.period())
      .Str(pt.stable() ? "true" : "false")
      .Str(pt.signature_text())
      .Num(mu_abs_max)
      .End();
}

// One comment line per special point, in the order found.
void AppendSpecialPoints(const google::protobuf::RepeatedPtrField<v1::SpecialPoint>& points,
                         std::string* out) {
  for (const v1::SpecialPoint& sp : points) {
    std::string line = v1::SpecialPoint::Kind_Name(sp.kind());
    line.append(" value=");
    AppendNumber(sp.value(), &line);
    line.append(" rop=");
    AppendNumber(sp.rop(), &line);
    line.append(" power=");
    AppendNumber(sp.power(), &line);
    line.append(" stable=").append(sp.stable() ? "true" : "false");
    line.append(" signature=").append(sp.signature_text());
    if (!sp.detail().empty()) line.append(" detail=").append(sp.detail());
    // At a grazing, each side's stability (the point's own `stable` needs both).
    auto side = [&line](const char* name, const v1::SideStability& s) {
      line.append(" stable_").append(name).append("=").append(s.stable() ? "true" : "false");
      line.append(" mu_abs_max_").append(name).append("=");
      AppendNumber(s.max_abs(), &line);
    };
    if (sp.has_stability_before()) side("before", sp.stability_before());
    if (sp.has_stability_after()) side("after", sp.stability_after());
    if (sp.stability_changes()) line.append(" stability_changes=true");
    // Part of a grazing's unfolding: the grazing's own line has each side's multipliers.
    if (sp.has_near_grazing()) {
      const v1::NearGrazing& near = sp.near_grazing();
      line.append(" near_grazing=").append(v1::SpecialPoint::Kind_Name(near.kind()));
      line.append(" near_grazing_value=");
      AppendNumber(near.value(), &line);
      line.append(" near_grazing_distance=");
      AppendNumber(near.distance(), &line);
    }
    // The width of the interval known to hold the point (0: solved directly).
    line.append(" bracket=");
    AppendNumber(sp.bracket(), &line);
    AppendComment(line, out);
  }
}

// The rows of curve `index`.
void AppendCurveRows(int index, const v1::Curve& c, std::string* out) {
  for (const v1::CurveVertex& v : c.points()) {
    const v1::ModelParams& p = v.params();
    Row(out)
        .Num(index)
        .Str(c.kind())
        .Num(p.a())
        .Num(p.b())
        .Num(p.omega())
        .Num(p.xi())
        .Num(p.g())
        .Num(p.phi0())
        .Num(v.rop())
        .Str(v.stable() ? "true" : "false")
        .End();
  }
}

// An unverified end of a curve: the curve's index and the end's parameters.
using UnverifiedEnd = std::pair<int, v1::ModelParams>;

// The comment lines after a trace's table: codimension-2 points, unverified curve ends, notes,
// the region's summary.
void AppendTraceTrailer(const v1::TraceResult& summary, const std::vector<UnverifiedEnd>& ends,
                        std::string* out) {
  // "KIND curve=i a=... phi0=...".
  auto point_line = [](const std::string& kind, int curve, const v1::ModelParams& p) {
    std::string line = kind + " curve=" + std::to_string(curve);
    for (const auto& [name, v] :
         {std::pair{" a=", p.a()}, std::pair{" b=", p.b()}, std::pair{" omega=", p.omega()},
          std::pair{" xi=", p.xi()}, std::pair{" g=", p.g()}, std::pair{" phi0=", p.phi0()}}) {
      line.append(name);
      AppendNumber(v, &line);
    }
    return line;
  };
  for (const v1::Codim2Point& q : summary.codim2_points()) {
    std::string line = point_line(q.kind(), q.curve(), q.params());
    if (!q.detail().empty()) line.append(" detail=").append(q.detail());
    AppendComment(line, out);
  }
  for (const auto& [curve, params] : ends) {
    AppendComment(point_line("UNVERIFIED_END", curve, params), out);
  }
  for (const std::string& note : summary.notes()) AppendComment("note: " + note, out);
  if (summary.has_region()) {
    AppendComment("region: " + summary.region().message() + " (grid and polygons: JSON output)",
                  out);
  }
}

void AppendUnverifiedEnds(int index, const v1::Curve& c, std::vector<UnverifiedEnd>* ends) {
  for (const v1::CurveVertex& e : c.unverified_ends()) ends->emplace_back(index, e.params());
}

}  // namespace

std::string SimulateResultToCsv(const v1::SimulateResult& result, SimulateTable table) {
  std::string out;
  AppendSimulateHead(result, &out);
  out.append(TableHeader(table));
  AppendTableRows(result, table, &out);
  return out;
}

std::string SweepResultToCsv(const v1::SweepResult& result) {
  std::string out;
  AppendStatus(result.status(), result.message(), &out);
  for (const v1::SweepPoint& pt : result.up()) AppendSweepFailure("up", pt, &out);
  for (const v1::SweepPoint& pt : result.down()) AppendSweepFailure("down", pt, &out);
  out.append(kSweepHeader);
  for (const v1::SweepPoint& pt : result.up()) AppendSweepRows("up", pt, &out);
  for (const v1::SweepPoint& pt : result.down()) AppendSweepRows("down", pt, &out);
  return out;
}

std::string ContinueResultToCsv(const v1::ContinueResult& result) {
  std::string out;
  AppendStatus(result.status(), result.message(), &out);
  out.append(kContinueHeader);
  for (const v1::BranchPoint& pt : result.points()) AppendBranchRow(pt, &out);
  AppendSpecialPoints(result.special_points(), &out);
  return out;
}

std::string TraceResultToCsv(const v1::TraceResult& result) {
  std::string out;
  AppendStatus(result.status(), result.message(), &out);
  out.append(kTraceHeader);
  std::vector<UnverifiedEnd> ends;
  for (int i = 0; i < result.curves_size(); ++i) {
    AppendCurveRows(i, result.curves(i), &out);
    AppendUnverifiedEnds(i, result.curves(i), &ends);
  }
  AppendTraceTrailer(result, ends, &out);
  return out;
}

std::string OptimumResultToCsv(const v1::OptimumResult& result) {
  std::string out;
  AppendStatus(result.status(), result.message(), &out);
  out.append(
      "a,b,omega,xi,g,phi0,rop,margin1,margin2,distance_scaled,nearest_curve_kind,signature,"
      "attractors\n");
  if (!result.has_params()) return out;
  const v1::ModelParams& p = result.params();
  Row row(&out);
  row.Num(p.a()).Num(p.b()).Num(p.omega()).Num(p.xi()).Num(p.g()).Num(p.phi0()).Num(result.rop());
  for (int k = 0; k < 2; ++k) {
    if (k < result.margin_size()) {
      row.Num(result.margin(k));
    } else {
      row.Str("");
    }
  }
  row.Num(result.distance_scaled()).Str(result.nearest_curve_kind()).Str(result.signature());
  row.Num(result.attractors_size()).End();
  return out;
}

// ---------------------------------------------------------------------------------------------
// ResultPrinter.

namespace internal {

// What ResultPrinter delegates to: one output format of one kind. Each method appends text to
// `out`, which the printer writes to its sink after each call.
class PageFormat {
 public:
  virtual ~PageFormat() = default;
  // Checks a page's items (a result message holding nothing else) before anything of the page
  // is printed.
  virtual Status CheckPage(const google::protobuf::Message& items) {
    (void)items;
    return Status::Ok();
  }
  // The text before the items, from the first page's summary (its paged fields empty).
  virtual Status Begin(const google::protobuf::Message& summary, std::string* out) = 0;
  // The next items: `chunk` holds items of paged field `field` (the index-th paged field) only.
  virtual Status Items(int index, const google::protobuf::FieldDescriptor* field,
                       const google::protobuf::Message& chunk, std::string* out) = 0;
  // The text after the last item; `out` is empty, and a format may write to `sink` itself.
  virtual Status End(std::string* out, const TextSink& sink) = 0;
};

}  // namespace internal

namespace {

using google::protobuf::Descriptor;
using google::protobuf::FieldDescriptor;
using google::protobuf::Message;
using internal::PageFormat;

// Items printed per ToJson call (and per CSV call) at most: serialized bytes, then at least one
// item. Bounds the text held at once when a page is a whole result (--local).
constexpr size_t kChunkBytes = 1 << 20;

// The end of the JSON string starting at json[begin] == '"': the index of its closing quote.
size_t StringEnd(std::string_view json, size_t begin) {
  for (size_t i = begin + 1; i < json.size(); ++i) {
    if (json[i] == '\\') {
      ++i;
    } else if (json[i] == '"') {
      return i;
    }
  }
  return std::string_view::npos;
}

// The index of the value of key `name` in the top-level object of `json` (as protobuf prints
// it: a key is a string followed by ':' and optional whitespace), or npos. Strings are skipped
// whole, so a key of a nested object or text inside a string never matches.
size_t TopLevelValue(std::string_view json, std::string_view name) {
  int depth = 0;
  for (size_t i = 0; i < json.size(); ++i) {
    const char c = json[i];
    if (c == '{' || c == '[') {
      ++depth;
    } else if (c == '}' || c == ']') {
      --depth;
    } else if (c == '"') {
      const size_t end = StringEnd(json, i);
      if (end == std::string_view::npos) return end;
      size_t k = end + 1;
      while (k < json.size() && (json[k] == ' ' || json[k] == '\n')) ++k;
      if (depth == 1 && k < json.size() && json[k] == ':' &&
          json.substr(i + 1, end - i - 1) == name) {
        ++k;
        while (k < json.size() && (json[k] == ' ' || json[k] == '\n')) ++k;
        return k;
      }
      i = end;
    }
  }
  return std::string_view::npos;
}

// The index just past the array or object that starts at json[begin], or npos.
size_t ValueEnd(std::string_view json, size_t begin) {
  int depth = 0;
  for (size_t i = begin; i < json.size(); ++i) {
    const char c = json[i];
    if (c == '{' || c == '[') {
      ++depth;
    } else if (c == '}' || c == ']') {
      if (--depth == 0) return i + 1;
    } else if (c == '"') {
      i = StringEnd(json, i);
      if (i == std::string_view::npos) return i;
    }
  }
  return std::string_view::npos;
}

// JSON, as ToJson prints the whole result. Protobuf's printer (3.21, JsonObjectWriter) writes a
// repeated message field of the top-level object, whose key line is indented by L spaces
// (pretty: L = 1; compact: no whitespace), as
//   "[]"                                                  when empty,
//   "[" + join(",", "\n" + (L+1 spaces) + item_i) + "\n" + (L spaces) + "]"      when pretty,
//   "[" + join(",", item_i) + "]"                          when compact,
// where item_i is the item's text at that depth, the same whatever the other fields and items
// (each value's text depends only on the value, the options and the depth). So the whole text is
// the summary's text (the paged fields printed as "[]") with each "[]" replaced by its array:
// Begin prints the summary's text up to the first paged field's '[', each chunk of items is
// printed as a result message holding only them (the same depth) and its array's inside is cut
// out and joined with ',' to the ones before, and each array is closed when the next field's
// items begin or at the end.
class JsonFormat final : public PageFormat {
 public:
  JsonFormat(std::vector<const FieldDescriptor*> paged, bool pretty)
      : paged_(std::move(paged)), pretty_(pretty) {}

  Status Begin(const Message& summary, std::string* out) override {
    DRILLBIF_ASSIGN_OR_RETURN(skeleton_, ToJson(summary, pretty_));
    for (const FieldDescriptor* field : paged_) {
      const size_t at = TopLevelValue(skeleton_, field->json_name());
      if (at == std::string::npos || skeleton_.compare(at, 2, "[]") != 0 ||
          (!open_.empty() && at <= open_.back())) {
        return Internal("cannot place the items of " + field->full_name() + " in the JSON text");
      }
      open_.push_back(at);
      // The key line's indentation: the spaces after the line break before the key.
      const size_t line = skeleton_.rfind('\n', at);
      const size_t key = skeleton_.find_first_not_of(' ', line == std::string::npos ? 0 : line + 1);
      std::string close;
      if (pretty_) close.append(1, '\n').append(key - (line + 1), ' ');
      close_.push_back(close.append(1, ']'));
    }
    if (paged_.empty()) return Status::Ok();
    out->append(skeleton_, 0, open_[0] + 1);
    return Status::Ok();
  }

  Status Items(int index, const FieldDescriptor* field, const Message& chunk,
               std::string* out) override {
    if (index != current_) {
      Close(out);
      const size_t from = open_[current_] + 2;  // past the "[]" of the closed field
      out->append(skeleton_, from, open_[index] + 1 - from);
      current_ = index;
      printed_ = 0;
    }
    DRILLBIF_ASSIGN_OR_RETURN(const std::string text, ToJson(chunk, pretty_));
    const size_t begin = TopLevelValue(text, field->json_name());
    const size_t end = begin == std::string::npos ? begin : ValueEnd(text, begin);
    if (end == std::string::npos || text[begin] != '[') {
      return Internal("cannot find the items of " + field->full_name() + " in their JSON text");
    }
    // The inside of "[...]" without the line break and indentation before the ']'.
    std::string_view inside(text.data() + begin + 1, end - begin - 2);
    while (!inside.empty() && (inside.back() == ' ' || inside.back() == '\n')) {
      inside.remove_suffix(1);
    }
    if (printed_ > 0) out->push_back(',');
    out->append(inside);
    printed_ += chunk.GetReflection()->FieldSize(chunk, field);
    return Status::Ok();
  }

  Status End(std::string* out, const TextSink&) override {
    if (paged_.empty()) {
      out->append(skeleton_);
      return Status::Ok();
    }
    Close(out);
    out->append(skeleton_, open_[current_] + 2);
    return Status::Ok();
  }

 private:
  // Closes the current field's array: "]" after its '[' when it has no items.
  void Close(std::string* out) const { out->append(printed_ > 0 ? close_[current_] : "]"); }

  const std::vector<const FieldDescriptor*> paged_;
  const bool pretty_;
  std::string skeleton_;            // the summary's text, paged fields "[]"
  std::vector<size_t> open_;        // per paged field: the index of its '[' in skeleton_
  std::vector<std::string> close_;  // per paged field: what closes a non-empty array
  int current_ = 0;                 // the paged field whose array is open
  int64_t printed_ = 0;             // items printed in it
};

// Text kept for later, in order: in memory up to kSpillBytes, the rest in an unlinked temporary
// file ($TMPDIR, else /tmp).
class SpillBuffer {
 public:
  SpillBuffer() = default;
  ~SpillBuffer() {
    if (file_ != nullptr) std::fclose(file_);
  }
  SpillBuffer(const SpillBuffer&) = delete;
  SpillBuffer& operator=(const SpillBuffer&) = delete;

  Status Append(std::string_view text) {
    memory_.append(text);
    if (memory_.size() < kSpillBytes) return Status::Ok();
    if (file_ == nullptr) DRILLBIF_RETURN_IF_ERROR(Open());
    if (std::fwrite(memory_.data(), 1, memory_.size(), file_) != memory_.size()) {
      return Internal(std::string("cannot write a temporary file: ") + std::strerror(errno));
    }
    memory_.clear();
    return Status::Ok();
  }

  // Writes everything appended to `sink`.
  Status WriteTo(const TextSink& sink) {
    if (file_ != nullptr) {
      if (std::fflush(file_) != 0 || std::fseek(file_, 0, SEEK_SET) != 0) {
        return Internal(std::string("cannot read a temporary file back: ") + std::strerror(errno));
      }
      std::string block(kSpillBytes, '\0');
      for (;;) {
        const size_t n = std::fread(block.data(), 1, block.size(), file_);
        if (n > 0) DRILLBIF_RETURN_IF_ERROR(sink(std::string_view(block.data(), n)));
        if (n < block.size()) break;
      }
      if (std::ferror(file_)) {
        return Internal(std::string("cannot read a temporary file back: ") + std::strerror(errno));
      }
    }
    if (!memory_.empty()) DRILLBIF_RETURN_IF_ERROR(sink(memory_));
    return Status::Ok();
  }

 private:
  static constexpr size_t kSpillBytes = 1 << 20;

  Status Open() {
    const char* dir = std::getenv("TMPDIR");
    std::string path =
        std::string(dir != nullptr && *dir != '\0' ? dir : "/tmp") + "/drillctl-rows-XXXXXX";
    const int fd = mkstemp(path.data());
    if (fd < 0) {
      return Internal("cannot create a temporary file " + path + ": " + std::strerror(errno));
    }
    unlink(path.c_str());
    file_ = fdopen(fd, "w+b");
    if (file_ == nullptr) {
      close(fd);
      return Internal(std::string("cannot open a temporary file: ") + std::strerror(errno));
    }
    return Status::Ok();
  }

  std::string memory_;
  std::FILE* file_ = nullptr;
};

// Simulate CSV (SimulateResultToCsv): the head, then one table's header and rows.
class SimulateCsv final : public PageFormat {
 public:
  explicit SimulateCsv(std::optional<SimulateTable> table)
      : infer_(!table.has_value()), table_(table.value_or(SimulateTable::kNone)) {}

  Status CheckPage(const Message& items) override {
    if (!infer_) return Status::Ok();
    const auto& r = static_cast<const v1::SimulateResult&>(items);
    v1::SimulateRequest::Outputs present;
    present.set_poincare(r.poincare_size() > 0 || table_ == SimulateTable::kPoincare);
    present.set_events(r.events_size() > 0 || table_ == SimulateTable::kEvents);
    present.set_modes(r.period_modes_size() > 0 || table_ == SimulateTable::kModes);
    present.set_trajectory_dt(
        r.trajectory_size() > 0 || table_ == SimulateTable::kTrajectory ? 1.0 : 0.0);
    return CsvTableFor(present).status();
  }

  Status Begin(const Message& summary, std::string* out) override {
    AppendSimulateHead(static_cast<const v1::SimulateResult&>(summary), out);
    if (!infer_) out->append(TableHeader(table_));
    return Status::Ok();
  }

  Status Items(int, const FieldDescriptor* field, const Message& chunk, std::string* out) override {
    const SimulateTable table = TableOfField(field->name());
    if (infer_ && table_ == SimulateTable::kNone) {
      table_ = table;
      out->append(TableHeader(table_));
    }
    if (table == table_) AppendTableRows(static_cast<const v1::SimulateResult&>(chunk), table, out);
    return Status::Ok();
  }

  Status End(std::string*, const TextSink&) override { return Status::Ok(); }

 private:
  const bool infer_;     // the table is the one whose items come (jobs result)
  SimulateTable table_;  // the table printed; kNone while inferred and no item came
};

// Sweep CSV (SweepResultToCsv): the status, the values that did not complete, the header and
// the rows. The last three wait for the last page (the failures precede the table).
class SweepCsv final : public PageFormat {
 public:
  Status Begin(const Message& summary, std::string* out) override {
    const auto& r = static_cast<const v1::SweepResult&>(summary);
    AppendStatus(r.status(), r.message(), out);
    return Status::Ok();
  }

  Status Items(int, const FieldDescriptor* field, const Message& chunk, std::string*) override {
    const auto& r = static_cast<const v1::SweepResult&>(chunk);
    const bool up = field->name() == "up";
    std::string failures, rows;
    for (const v1::SweepPoint& pt : up ? r.up() : r.down()) {
      AppendSweepFailure(field->name(), pt, &failures);
      AppendSweepRows(field->name(), pt, &rows);
    }
    DRILLBIF_RETURN_IF_ERROR((up ? failures_up_ : failures_down_).Append(failures));
    return rows_.Append(rows);
  }

  Status End(std::string*, const TextSink& sink) override {
    DRILLBIF_RETURN_IF_ERROR(failures_up_.WriteTo(sink));
    DRILLBIF_RETURN_IF_ERROR(failures_down_.WriteTo(sink));
    DRILLBIF_RETURN_IF_ERROR(sink(kSweepHeader));
    return rows_.WriteTo(sink);
  }

 private:
  SpillBuffer failures_up_, failures_down_, rows_;
};

// Continue CSV (ContinueResultToCsv): the status and header, the rows, the special points.
class ContinueCsv final : public PageFormat {
 public:
  Status Begin(const Message& summary, std::string* out) override {
    const auto& r = static_cast<const v1::ContinueResult&>(summary);
    AppendStatus(r.status(), r.message(), out);
    out->append(kContinueHeader);
    special_points_ = r.special_points();
    return Status::Ok();
  }

  Status Items(int, const FieldDescriptor*, const Message& chunk, std::string* out) override {
    for (const v1::BranchPoint& pt : static_cast<const v1::ContinueResult&>(chunk).points()) {
      AppendBranchRow(pt, out);
    }
    return Status::Ok();
  }

  Status End(std::string* out, const TextSink&) override {
    AppendSpecialPoints(special_points_, out);
    return Status::Ok();
  }

 private:
  google::protobuf::RepeatedPtrField<v1::SpecialPoint> special_points_;
};

// Trace CSV (TraceResultToCsv): the status and header, the rows of each curve, then the
// codimension-2 points, unverified ends (kept from the curves as they pass), notes and region.
class TraceCsv final : public PageFormat {
 public:
  Status Begin(const Message& summary, std::string* out) override {
    summary_ = static_cast<const v1::TraceResult&>(summary);
    AppendStatus(summary_.status(), summary_.message(), out);
    out->append(kTraceHeader);
    if (summary_.has_region()) {  // only its message is printed: drop the grid
      std::string message = summary_.region().message();
      summary_.mutable_region()->Clear();
      summary_.mutable_region()->set_message(std::move(message));
    }
    return Status::Ok();
  }

  Status Items(int, const FieldDescriptor*, const Message& chunk, std::string* out) override {
    for (const v1::Curve& c : static_cast<const v1::TraceResult&>(chunk).curves()) {
      AppendCurveRows(next_curve_, c, out);
      AppendUnverifiedEnds(next_curve_, c, &ends_);
      ++next_curve_;
    }
    return Status::Ok();
  }

  Status End(std::string* out, const TextSink&) override {
    AppendTraceTrailer(summary_, ends_, out);
    return Status::Ok();
  }

 private:
  v1::TraceResult summary_;
  std::vector<UnverifiedEnd> ends_;
  int next_curve_ = 0;  // index of the next curve
};

// Optimum CSV (OptimumResultToCsv): no paged fields, all from the summary.
class OptimumCsv final : public PageFormat {
 public:
  Status Begin(const Message& summary, std::string* out) override {
    out->append(OptimumResultToCsv(static_cast<const v1::OptimumResult&>(summary)));
    return Status::Ok();
  }
  Status Items(int, const FieldDescriptor* field, const Message&, std::string*) override {
    return Internal("an optimum result has no paged field " + field->name());
  }
  Status End(std::string*, const TextSink&) override { return Status::Ok(); }
};

// Optimum map CSV: a row per cell (in the order the cells finished): the conditions
// ("condition_b", ...), the cell's status, the optimum's parameters, ROP and margin. The counts go
// in the trailer.
class OptimumMapCsv final : public PageFormat {
 public:
  Status Begin(const Message& summary, std::string* out) override {
    summary_ = static_cast<const v1::OptimumMapResult&>(summary);
    AppendStatus(summary_.status(), summary_.message(), out);
    for (const std::string& name : summary_.over()) out->append("condition_" + name + ",");
    out->append("status,a,b,omega,xi,g,phi0,rop,margin1,margin2,signature\n");
    return Status::Ok();
  }
  Status Items(int, const FieldDescriptor*, const Message& chunk, std::string* out) override {
    for (const v1::OptimumMapCell& c : static_cast<const v1::OptimumMapResult&>(chunk).cells()) {
      Row row(out);
      for (double v : c.condition()) row.Num(v);
      const v1::OptimumResult& o = c.optimum();
      row.Str(o.status());
      if (!o.has_params()) {
        row.Str("").Str("").Str("").Str("").Str("").Str("").Str("").Str("").Str("").Str("").End();
        continue;
      }
      const v1::ModelParams& p = o.params();
      row.Num(p.a()).Num(p.b()).Num(p.omega()).Num(p.xi()).Num(p.g()).Num(p.phi0()).Num(o.rop());
      for (int k = 0; k < 2; ++k) {
        if (k < o.margin_size()) {
          row.Num(o.margin(k));
        } else {
          row.Str("");
        }
      }
      row.Str(o.signature()).End();
    }
    return Status::Ok();
  }
  Status End(std::string* out, const TextSink&) override {
    AppendComment("cells_found=" + std::to_string(summary_.cells_found()) +
                      " cells_not_found=" + std::to_string(summary_.cells_not_found()) +
                      " cells_failed=" + std::to_string(summary_.cells_failed()),
                  out);
    return Status::Ok();
  }

 private:
  v1::OptimumMapResult summary_;
};

StatusOr<std::unique_ptr<PageFormat>> MakeFormat(const Descriptor* type,
                                                 std::vector<const FieldDescriptor*> paged,
                                                 const PrintOptions& options) {
  if (!options.csv)
    return std::unique_ptr<PageFormat>(new JsonFormat(std::move(paged), options.pretty));
  if (type == v1::SimulateResult::descriptor()) {
    return std::unique_ptr<PageFormat>(new SimulateCsv(options.simulate_table));
  }
  if (type == v1::SweepResult::descriptor()) return std::unique_ptr<PageFormat>(new SweepCsv);
  if (type == v1::ContinueResult::descriptor()) return std::unique_ptr<PageFormat>(new ContinueCsv);
  if (type == v1::TraceResult::descriptor()) return std::unique_ptr<PageFormat>(new TraceCsv);
  if (type == v1::OptimumResult::descriptor()) return std::unique_ptr<PageFormat>(new OptimumCsv);
  if (type == v1::OptimumMapResult::descriptor()) {
    return std::unique_ptr<PageFormat>(new OptimumMapCsv);
  }
  return InvalidArgument("no CSV format for " + type->full_name());
}

// The string field `name` of a result (status, message), empty when it has none.
std::string StringField(const Message& message, const std::string& name) {
  const FieldDescriptor* field = message.GetDescriptor()->FindFieldByName(name);
  if (field == nullptr || field->cpp_type() != FieldDescriptor::CPPTYPE_STRING ||
      field->is_repeated()) {
    return std::string();
  }
  return message.GetReflection()->GetString(message, field);
}

}  // namespace

StatusOr<std::unique_ptr<ResultPrinter>> ResultPrinter::Create(const Descriptor* result_type,
                                                               const PrintOptions& options,
                                                               TextSink sink) {
  const jobs::JobKindSpec* kind = result_type == nullptr ? nullptr : jobs::FindKind(result_type);
  if (kind == nullptr || kind->result_type != result_type) {
    return InvalidArgument("not a job result type: " + (result_type == nullptr
                                                            ? std::string("null")
                                                            : result_type->full_name()));
  }
  std::vector<const FieldDescriptor*> paged;
  for (const std::string& name : kind->paged_fields) {
    const FieldDescriptor* field = result_type->FindFieldByName(name);
    if (field == nullptr || !field->is_repeated() ||
        field->cpp_type() != FieldDescriptor::CPPTYPE_MESSAGE) {
      return Internal("paged field " + name + " of " + result_type->full_name() +
                      " is not a repeated message field");
    }
    paged.push_back(field);
  }
  DRILLBIF_ASSIGN_OR_RETURN(std::unique_ptr<PageFormat> format,
                            MakeFormat(result_type, paged, options));
  auto printer = std::unique_ptr<ResultPrinter>(
      new ResultPrinter(result_type, std::move(format), std::move(sink)));
  printer->paged_fields_ = std::move(paged);
  for (const std::string& name : kind->first_page_fields) {
    const FieldDescriptor* field = result_type->FindFieldByName(name);
    if (field == nullptr) return Internal("no field " + name + " in " + result_type->full_name());
    printer->first_page_fields_.push_back(field);
  }
  return printer;
}

ResultPrinter::ResultPrinter(const Descriptor* result_type, std::unique_ptr<PageFormat> format,
                             TextSink sink)
    : result_type_(result_type), format_(std::move(format)), sink_(std::move(sink)) {}

ResultPrinter::~ResultPrinter() = default;

std::string ResultPrinter::SummaryBytes(const Message& summary) const {
  std::unique_ptr<Message> copy(summary.New());
  copy->CopyFrom(summary);
  const auto* reflection = copy->GetReflection();
  for (const FieldDescriptor* field : first_page_fields_) reflection->ClearField(copy.get(), field);
  std::string bytes;
  {
    google::protobuf::io::StringOutputStream stream(&bytes);
    google::protobuf::io::CodedOutputStream coded(&stream);
    coded.SetSerializationDeterministic(true);
    copy->SerializeToCodedStream(&coded);
  }
  return bytes;
}

Status ResultPrinter::Flush(std::string* out) {
  if (out->empty()) return Status::Ok();
  Status s = sink_(*out);
  out->clear();
  return s;
}

Status ResultPrinter::AddPage(Message& page) {
  if (finished_) return Internal("a result page after the last one");
  if (page.GetDescriptor() != result_type_) {
    return Internal("a result page of type " + page.GetDescriptor()->full_name() + " where " +
                    result_type_->full_name() + " was expected");
  }
  // The page's items move to `items`; `page` keeps the summary.
  std::unique_ptr<Message> items(page.New());
  page.GetReflection()->SwapFields(&page, items.get(), paged_fields_);
  DRILLBIF_RETURN_IF_ERROR(StartPage(page, *items));
  ++pages_;
  return PrintItems(*items);
}

Status ResultPrinter::StartPage(const Message& summary, const Message& items) {
  const auto* reflection = items.GetReflection();
  for (int i = 0; i < current_field_; ++i) {
    if (reflection->FieldSize(items, paged_fields_[i]) > 0) {
      return Internal("page " + std::to_string(pages_ + 1) + " of the result holds items of " +
                      paged_fields_[i]->name() + " after items of " +
                      paged_fields_[current_field_]->name());
    }
  }
  std::string bytes = SummaryBytes(summary);
  if (pages_ > 0) {
    if (bytes != first_summary_) {
      return Internal("page " + std::to_string(pages_ + 1) +
                      " of the result has another summary (status, counters, ...) than the first");
    }
    return format_->CheckPage(items);
  }
  DRILLBIF_RETURN_IF_ERROR(format_->CheckPage(items));
  first_summary_ = std::move(bytes);
  status_ = StringField(summary, "status");
  message_ = StringField(summary, "message");
  std::string out;
  DRILLBIF_RETURN_IF_ERROR(format_->Begin(summary, &out));
  return Flush(&out);
}

Status ResultPrinter::PrintItems(Message& items) {
  const auto* reflection = items.GetReflection();
  std::unique_ptr<Message> chunk(items.New());
  std::string out;
  for (int i = 0; i < static_cast<int>(paged_fields_.size()); ++i) {
    const FieldDescriptor* field = paged_fields_[i];
    const int n = reflection->FieldSize(items, field);
    if (n > 0) current_field_ = i;
    for (int begin = 0; begin < n;) {
      // Moves the next items, up to kChunkBytes of them (at least one), into `chunk`.
      size_t bytes = 0;
      int end = begin;
      while (end < n && (end == begin || bytes < kChunkBytes)) {
        Message* next = reflection->MutableRepeatedMessage(&items, field, end);
        bytes += next->ByteSizeLong();
        Message* item = reflection->AddMessage(chunk.get(), field);
        item->GetReflection()->Swap(item, next);
        ++end;
      }
      DRILLBIF_RETURN_IF_ERROR(format_->Items(i, field, *chunk, &out));
      DRILLBIF_RETURN_IF_ERROR(Flush(&out));
      items_ += end - begin;
      chunk->Clear();
      begin = end;
    }
  }
  return Status::Ok();
}

Status ResultPrinter::Finish() {
  if (finished_) return Status::Ok();
  if (pages_ == 0) return Internal("no result page to print");
  finished_ = true;
  std::string out;
  DRILLBIF_RETURN_IF_ERROR(format_->End(&out, sink_));
  return Flush(&out);
}

}  // namespace drillbif::client
