#include "client/output.h"

#include <google/protobuf/util/json_util.h>

#include <algorithm>
#include <charconv>
#include <string_view>

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

std::string SimulateResultToCsv(const v1::SimulateResult& result, SimulateTable table) {
  std::string out;
  AppendStatus(result.status(), result.message(), &out);
  if (result.has_rop()) {
    std::string line = "rop=";
    AppendNumber(result.rop(), &line);
    AppendComment(line, &out);
  }
  if (result.has_power()) {
    std::string line = "power=";
    AppendNumber(result.power(), &line);
    AppendComment(line, &out);
  }
  switch (table) {
    case SimulateTable::kNone:
      break;
    case SimulateTable::kPoincare:
      out.append("period,mode,p,y,q\n");
      for (const v1::PoincarePoint& pt : result.poincare()) {
        Row(&out)
            .Int(pt.period())
            .Str(ModeName(pt.mode()))
            .Num(pt.p())
            .Num(pt.y())
            .Num(pt.q())
            .End();
      }
      break;
    case SimulateTable::kEvents:
      out.append("period,s,t,surface,guard,from_mode,to_mode,tangential,p,y,q\n");
      for (const v1::Event& e : result.events()) {
        Row(&out)
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
      break;
    case SimulateTable::kModes:
      out.append("period,modes\n");
      for (const v1::PeriodModes& pm : result.period_modes()) {
        std::string modes;
        for (int m : pm.modes()) modes.append(modes.empty() ? "" : " ").append(ModeName(m));
        Row(&out).Int(pm.period()).Str(modes).End();
      }
      break;
    case SimulateTable::kTrajectory:
      out.append("t,mode,p,y,q,s\n");
      for (const v1::TrajectoryPoint& tp : result.trajectory()) {
        Row(&out)
            .Num(tp.t())
            .Str(ModeName(tp.mode()))
            .Num(tp.p())
            .Num(tp.y())
            .Num(tp.q())
            .Num(tp.s())
            .End();
      }
      break;
  }
  return out;
}

std::string SweepResultToCsv(const v1::SweepResult& result) {
  std::string out;
  AppendStatus(result.status(), result.message(), &out);
  auto failures = [&](std::string_view direction,
                      const google::protobuf::RepeatedPtrField<v1::SweepPoint>& points) {
    for (const v1::SweepPoint& pt : points) {
      if (pt.status() == "COMPLETED") continue;
      std::string line(direction);
      line.append(" value=");
      AppendNumber(pt.value(), &line);
      line.append(" status=").append(pt.status()).append(" message=").append(pt.message());
      AppendComment(line, &out);
    }
  };
  failures("up", result.up());
  failures("down", result.down());
  out.append("direction,value,period,p,y,q\n");
  auto rows = [&](std::string_view direction,
                  const google::protobuf::RepeatedPtrField<v1::SweepPoint>& points) {
    for (const v1::SweepPoint& pt : points) {
      for (const v1::PoincarePoint& s : pt.samples()) {
        Row(&out)
            .Str(direction)
            .Num(pt.value())
            .Int(s.period())
            .Num(s.p())
            .Num(s.y())
            .Num(s.q())
            .End();
      }
    }
  };
  rows("up", result.up());
  rows("down", result.down());
  return out;
}

std::string ContinueResultToCsv(const v1::ContinueResult& result) {
  std::string out;
  AppendStatus(result.status(), result.message(), &out);
  out.append("value,rop,power,period,stable,signature_text,mu_abs_max\n");
  for (const v1::BranchPoint& pt : result.points()) {
    double mu_abs_max = 0.0;
    for (const v1::Multiplier& mu : pt.multipliers()) mu_abs_max = std::max(mu_abs_max, mu.abs());
    Row(&out)
        .Num(pt.value())
        .Num(pt.rop())
        .Num(pt.power())
        .Num(pt.period())
        .Str(pt.stable() ? "true" : "false")
        .Str(pt.signature_text())
        .Num(mu_abs_max)
        .End();
  }
  for (const v1::SpecialPoint& sp : result.special_points()) {
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
    AppendComment(line, &out);
  }
  return out;
}

std::string TraceResultToCsv(const v1::TraceResult& result) {
  std::string out;
  AppendStatus(result.status(), result.message(), &out);
  out.append("curve,kind,a,b,omega,xi,g,phi0,rop,stable\n");
  for (int i = 0; i < result.curves_size(); ++i) {
    const v1::Curve& c = result.curves(i);
    for (const v1::CurveVertex& v : c.points()) {
      const v1::ModelParams& p = v.params();
      Row(&out)
          .Num(i)
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
  for (const v1::Codim2Point& q : result.codim2_points()) {
    std::string line = point_line(q.kind(), q.curve(), q.params());
    if (!q.detail().empty()) line.append(" detail=").append(q.detail());
    AppendComment(line, &out);
  }
  for (int i = 0; i < result.curves_size(); ++i) {
    for (const v1::CurveVertex& e : result.curves(i).unverified_ends()) {
      AppendComment(point_line("UNVERIFIED_END", i, e.params()), &out);
    }
  }
  for (const std::string& note : result.notes()) AppendComment("note: " + note, &out);
  if (result.has_region()) {
    AppendComment("region: " + result.region().message() + " (grid and polygons: JSON output)",
                  &out);
  }
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

}  // namespace drillbif::client
