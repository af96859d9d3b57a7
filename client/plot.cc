#include "client/plot.h"

#include <fcntl.h>
#include <google/protobuf/struct.pb.h>
#include <google/protobuf/util/json_util.h>
#include <spawn.h>
#include <stdlib.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <system_error>
#include <utility>
#include <vector>

#include "jobs/job_common.h"

extern char** environ;

namespace drillbif::client {
namespace {

constexpr std::array<const char*, 6> kParamNames = {"a", "b", "omega", "xi", "g", "phi0"};

// Shortest text that reads back to the same double.
// Non-finite values become gnuplot's missing-data "NaN".
std::string Num(double v) { return std::isfinite(v) ? jobs::internal::Num(v) : std::string("NaN"); }

// Four significant digits, for titles and labels.
std::string Short(double v) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.4g", v);
  return buffer;
}

// A gnuplot single-quoted string (a quote inside is doubled; nothing else is special).
std::string Quote(const std::string& text) {
  std::string out = "'";
  for (char c : text) {
    if (c == '\'') out += '\'';
    if (c != '\n') out += c;
  }
  return out + "'";
}

double ParamValue(const v1::ModelParams& p, const std::string& name) {
  if (name == "a") return p.a();
  if (name == "b") return p.b();
  if (name == "omega") return p.omega();
  if (name == "xi") return p.xi();
  if (name == "g") return p.g();
  if (name == "phi0") return p.phi0();
  return std::nan("");
}

// Axis label of a model parameter (proto/drillbif/v1/model.proto says what each one is).
std::string ParamLabel(const std::string& name) {
  std::string what;
  if (name == "a") what = "forcing amplitude";
  if (name == "b") what = "static force (weight on bit)";
  if (name == "omega") what = "forcing frequency";
  if (name == "xi") what = "damping ratio of the slider";
  if (name == "g") what = "gap between bit and slider";
  if (name == "phi0") return "phi0: forcing phase (dimensionless, radians)";
  if (what.empty()) return name + " (dimensionless)";
  return name + ": " + what + " (dimensionless)";
}

// "a = 0.3, omega = 0.1, ..." for every parameter but `except`.
std::string FixedParams(const v1::ModelParams& p, const std::vector<std::string>& except) {
  std::string out;
  for (const char* name : kParamNames) {
    if (std::find(except.begin(), except.end(), name) != except.end()) continue;
    if (!out.empty()) out += ", ";
    out += std::string(name) + " = " + Short(ParamValue(p, name));
  }
  return out;
}

struct Style {
  const char* color;
  int point_type;
};

// Colours (a colour-blind-friendly palette where there are few) and point types by kind.
Style SpecialPointStyle(v1::SpecialPoint::Kind kind) {
  switch (kind) {
    case v1::SpecialPoint::FOLD:
      return {"#d62728", 7};
    case v1::SpecialPoint::PERIOD_DOUBLING:
      return {"#ff7f0e", 5};
    case v1::SpecialPoint::NEIMARK_SACKER:
      return {"#8c564b", 9};
    case v1::SpecialPoint::BRANCH_POINT:
      return {"#7f7f7f", 13};
    case v1::SpecialPoint::GRAZING_L1:
      return {"#9467bd", 11};
    case v1::SpecialPoint::GRAZING_L2:
      return {"#e377c2", 11};
    case v1::SpecialPoint::GRAZING_PI:
      return {"#17becf", 11};
    case v1::SpecialPoint::SIGNATURE_CHANGE:
      return {"#bcbd22", 12};
    case v1::SpecialPoint::ROP_MAX:
      return {"#000000", 3};
    case v1::SpecialPoint::POWER_MAX:
      return {"#555555", 3};
    default:
      return {"#333333", 1};
  }
}

// Short on-figure label of a special point; the legend has the full kind name.
std::string SpecialPointTag(v1::SpecialPoint::Kind kind) {
  switch (kind) {
    case v1::SpecialPoint::FOLD:
      return "F";
    case v1::SpecialPoint::PERIOD_DOUBLING:
      return "PD";
    case v1::SpecialPoint::NEIMARK_SACKER:
      return "NS";
    case v1::SpecialPoint::BRANCH_POINT:
      return "BP";
    case v1::SpecialPoint::GRAZING_L1:
      return "G l1";
    case v1::SpecialPoint::GRAZING_L2:
      return "G l2";
    case v1::SpecialPoint::GRAZING_PI:
      return "G Pi";
    case v1::SpecialPoint::SIGNATURE_CHANGE:
      return "SC";
    case v1::SpecialPoint::ROP_MAX:
      return "ROP max";
    case v1::SpecialPoint::POWER_MAX:
      return "P max";
    default:
      return "?";
  }
}

const char* CurveColor(const std::string& kind, int index) {
  if (kind == "FOLD") return "#d62728";
  if (kind == "PERIOD_DOUBLING") return "#ff7f0e";
  if (kind == "GRAZING") return "#1f77b4";
  if (kind == "NEIMARK_SACKER") return "#8c564b";
  constexpr std::array<const char*, 5> kOthers = {"#2ca02c", "#9467bd", "#e377c2", "#7f7f7f",
                                                  "#17becf"};
  return kOthers[static_cast<size_t>(index) % kOthers.size()];
}

Style Codim2Style(int index) {
  // Open markers, so that points of different kinds at the same place stay visible.
  constexpr std::array<Style, 8> kStyles = {{{"#000000", 6},
                                             {"#6a3d9a", 4},
                                             {"#b15928", 8},
                                             {"#1b7837", 10},
                                             {"#e7298a", 12},
                                             {"#01665e", 14},
                                             {"#525252", 2},
                                             {"#8c510a", 1}}};
  return kStyles[static_cast<size_t>(index) % kStyles.size()];
}

constexpr std::array<const char*, 4> kRegionColors = {"#2ca02c", "#1f77b4", "#bcbd22", "#9467bd"};

// Mode colours and names (MODEL.md's abbreviations).
Style ModeStyle(v1::Mode mode) {
  switch (mode) {
    case v1::NO_CONTACT:
      return {"#1f77b4", 7};
    case v1::CONTACT:
      return {"#ff7f0e", 7};
    case v1::PROGRESSION:
      return {"#d62728", 7};
    default:
      return {"#555555", 7};
  }
}

std::string ModeTitle(v1::Mode mode) {
  switch (mode) {
    case v1::NO_CONTACT:
      return "NC: no contact";
    case v1::CONTACT:
      return "CwoP: contact without progression";
    case v1::PROGRESSION:
      return "CwP: contact with progression";
    default:
      return "mode not recorded";
  }
}

// The script under construction: header lines, datablocks and plot clauses.
class Script {
 public:
  // Adds a datablock named $name with `rows` (a blank line breaks a line plot; two start a new
  // data set).
  void Data(const std::string& name, const std::string& rows) {
    data_ += "$" + name + " << EOD\n" + rows + "EOD\n";
  }
  void Set(const std::string& line) { header_ += line + "\n"; }
  void Plot(const std::string& clause) { clauses_.push_back(clause); }
  bool Empty() const { return clauses_.empty(); }

  std::string Text(const std::string& comment) const {
    std::string out = "# " + comment + "\n# Re-run with: gnuplot THIS_FILE\n" + header_ + data_;
    out += "plot ";
    for (size_t i = 0; i < clauses_.size(); ++i) {
      out += clauses_[i];
      out += i + 1 < clauses_.size() ? ", \\\n     " : "\n";
    }
    return out + "unset output\n";
  }

 private:
  std::string header_;
  std::string data_;
  std::vector<std::string> clauses_;
};

StatusOr<std::string> TerminalLine(const PlotOptions& options) {
  const std::string ext = std::filesystem::path(options.output).extension().string();
  std::string lower = ext;
  std::transform(lower.begin(), lower.end(), lower.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  const std::string size = std::to_string(options.width) + "," + std::to_string(options.height);
  if (lower == ".png") {
    return "set terminal pngcairo size " + size + " noenhanced font 'DejaVu Sans,11' linewidth 1";
  }
  if (lower == ".svg") {
    return "set terminal svg size " + size +
           " dynamic noenhanced font 'DejaVu Sans,11' background '#ffffff'";
  }
  return InvalidArgument("the figure's extension must be .png or .svg, got '" + options.output +
                         "'");
}

// Settings every figure shares.
StatusOr<Script> Begin(const PlotOptions& options, const std::string& title,
                       const std::string& xlabel, const std::string& ylabel,
                       const std::string& subtitle = std::string()) {
  StatusOr<std::string> terminal = TerminalLine(options);
  if (!terminal.ok()) return terminal.status();
  Script s;
  s.Set(*terminal);
  s.Set("set output " + Quote(options.output));
  s.Set("set encoding utf8");
  if (!options.title.empty()) {
    s.Set("set title " + Quote(options.title) + " font ',13'");
  } else if (subtitle.empty()) {
    s.Set("set title " + Quote(title) + " font ',13'");
  } else {
    s.Set("set title " + Quote(title) + ".\"\\n\"." + Quote(subtitle) + " font ',13'");
  }
  s.Set("set xlabel " + Quote(xlabel));
  s.Set("set ylabel " + Quote(ylabel));
  s.Set("set key outside right top box opaque spacing 1.2 samplen 3");
  s.Set("set grid lc rgb '#dddddd'");
  s.Set("set border lw 1");
  return s;
}

// Places on-figure labels above and right of their points, moving one up (in steps of a line)
// while it would overlap a label already placed. Positions are compared in fractions of the data
// ranges; a character is taken as ~1% of the width and a line as ~3.5% of the height.
class Labels {
 public:
  Labels(double x_min, double x_span, double y_min, double y_span)
      : x_min_(x_min), x_span_(x_span), y_min_(y_min), y_span_(y_span) {}

  std::string Add(double x, double y, const std::string& text, const char* color) {
    const double nx = (x - x_min_) / x_span_ + 0.01;
    const double width = 0.011 * static_cast<double>(text.size());
    int level = 0;
    for (bool clash = true; clash; ++level) {
      const double ny = (y - y_min_) / y_span_ + 0.035 * level;
      clash = false;
      for (const Placed& p : placed_) {
        clash = clash || (nx < p.x + p.width && p.x < nx + width && std::abs(ny - p.y) < 0.035);
      }
      if (!clash) {
        placed_.push_back({nx, ny, width});
        break;
      }
    }
    return "set label " + Quote(text) + " at " + Num(x) + "," + Num(y) + " offset char 0.8,char " +
           Num(0.9 + 1.2 * level) + " font ',10' tc rgb '" + color + "' front";
  }

 private:
  struct Placed {
    double x, y, width;
  };
  double x_min_, x_span_, y_min_, y_span_;
  std::vector<Placed> placed_;
};

// The continued parameter: the one whose value equals each point's `value`.
std::string ContinuedParam(const v1::ContinueResult& r) {
  for (const char* name : kParamNames) {
    bool all = r.points_size() > 1;
    for (const v1::BranchPoint& p : r.points()) {
      all = all && ParamValue(p.params(), name) == p.value();
    }
    if (all) return name;
  }
  return "parameter";
}

double Measure(const v1::BranchPoint& p, bool power) { return power ? p.power() : p.rop(); }

// Appends a branch's stable and unstable runs (each run includes the point where stability
// changes, so that the two line styles join).
void BranchRows(const v1::ContinueResult& r, bool power, std::string* stable,
                std::string* unstable) {
  for (int i = 0; i < r.points_size(); ++i) {
    const v1::BranchPoint& p = r.points(i);
    std::string row = Num(p.value()) + " " + Num(Measure(p, power)) + "\n";
    std::string* own = p.stable() ? stable : unstable;
    *own += row;
    if (i + 1 < r.points_size() && r.points(i + 1).stable() != p.stable()) {
      *(p.stable() ? unstable : stable) += row;  // the other run starts here
      *own += "\n";                              // and this one ends after it
    }
  }
}

StatusOr<std::string> ContinueScript(const v1::ContinueResult& r, const PlotOptions& options) {
  const std::string m = options.measure;
  if (m != "rop" && m != "power" && m != "pc") {
    return InvalidArgument("--measure must be rop or power, got '" + m + "'");
  }
  const bool power = m != "rop";
  if (r.points_size() == 0) return InvalidArgument("the continuation result has no points");
  const std::string param = options.param.empty() ? ContinuedParam(r) : options.param;
  const std::string ylabel = power ? "P: mean dissipated power (dimensionless)"
                                   : "ROP: rate of progression (dimensionless)";
  StatusOr<Script> begun =
      Begin(options,
            std::string(power ? "Power" : "ROP") + " along the periodic orbit's branch in " + param,
            ParamLabel(param), ylabel, FixedParams(r.points(0).params(), {param}));
  if (!begun.ok()) return begun.status();
  Script s = std::move(begun).value();

  // The branch and, when followed, the period-doubled branches (each a colour).
  constexpr std::array<const char*, 3> kBranchColors = {"#1f4e9c", "#2a9d3f", "#8e44ad"};
  double x_min = INFINITY, x_max = -INFINITY, y_min = INFINITY, y_max = -INFINITY;
  std::vector<const v1::ContinueResult*> branches;
  for (const v1::ContinueResult* b = &r; b != nullptr && b->points_size() > 0;
       b = b->has_period_doubled_branch() ? &b->period_doubled_branch() : nullptr) {
    branches.push_back(b);
  }
  for (size_t i = 0; i < branches.size(); ++i) {
    for (const v1::BranchPoint& p : branches[i]->points()) {
      x_min = std::min(x_min, p.value());
      x_max = std::max(x_max, p.value());
      y_min = std::min(y_min, Measure(p, power));
      y_max = std::max(y_max, Measure(p, power));
    }
    std::string stable, unstable;
    BranchRows(*branches[i], power, &stable, &unstable);
    const std::string which = i == 0 ? std::string() : " (period-" + std::to_string(1 << i) + ")";
    const std::string color = kBranchColors[std::min(i, kBranchColors.size() - 1)];
    const std::string name = "branch" + std::to_string(i);
    if (!stable.empty()) {
      s.Data(name + "_stable", stable);
      s.Plot("$" + name + "_stable using 1:2 with lines lw 2.5 dashtype 1 lc rgb '" + color +
             "' title " + Quote("stable" + which));
    }
    if (!unstable.empty()) {
      s.Data(name + "_unstable", unstable);
      s.Plot("$" + name + "_unstable using 1:2 with lines lw 1.5 dashtype 2 lc rgb '" + color +
             "' title " + Quote("unstable (dashed)" + which));
    }
  }

  // Special points by kind, in the order of the enum, each with its label on the figure.
  Labels labels(x_min, std::max(x_max - x_min, 1e-12), y_min, std::max(y_max - y_min, 1e-12));
  std::map<int, std::string> by_kind;
  for (const v1::ContinueResult* b : branches) {
    for (const v1::SpecialPoint& sp : b->special_points()) {
      const double y = power ? sp.power() : sp.rop();
      by_kind[sp.kind()] += Num(sp.value()) + " " + Num(y) + "\n";
      s.Set(labels.Add(sp.value(), y, SpecialPointTag(sp.kind()),
                       SpecialPointStyle(sp.kind()).color));
    }
  }
  for (const auto& [kind_number, rows] : by_kind) {
    const auto kind = static_cast<v1::SpecialPoint::Kind>(kind_number);
    const Style style = SpecialPointStyle(kind);
    const std::string name = v1::SpecialPoint::Kind_Name(kind);
    s.Data("sp_" + name, rows);
    s.Plot("$sp_" + name + " using 1:2 with points pt " + std::to_string(style.point_type) +
           " ps 1.8 lw 2 lc rgb '" + style.color + "' title " +
           Quote(name + " (" + SpecialPointTag(kind) + ")"));
  }
  // 5% of room around the data so that markers and labels at the edges show.
  const double dx = 0.03 * std::max(x_max - x_min, 1e-12);
  const double dy = 0.08 * std::max(y_max - y_min, 1e-12);
  s.Set("set xrange [" + Num(x_min - dx) + ":" + Num(x_max + dx) + "]");
  s.Set("set yrange [" + Num(y_min - dy) + ":" + Num(y_max + 2 * dy) + "]");
  return s.Text("drillctl plot: one-parameter continuation in " + param);
}

double Coordinate(const v1::PoincarePoint& p, char c) {
  return c == 'p' ? p.p() : c == 'q' ? p.q() : p.y();
}

std::string CoordinateLabel(char c) {
  if (c == 'p') return "p at the section s = 0: bit position (dimensionless)";
  if (c == 'q') return "q at the section s = 0: slider-top position (dimensionless)";
  return "y at the section s = 0: bit velocity (dimensionless)";
}

StatusOr<std::string> SweepScript(const v1::SweepResult& r, const PlotOptions& options) {
  const std::string& c = options.coordinate;
  if (c != "p" && c != "y" && c != "q") {
    return InvalidArgument("--coordinate must be p, y or q, got '" + c + "'");
  }
  const std::string param = options.param.empty() ? std::string("parameter") : options.param;
  const std::string dirs = r.up_size() > 0 && r.down_size() > 0 ? "up and down sweeps"
                           : r.up_size() > 0                    ? "up sweep"
                                                                : "down sweep";
  const int values = std::max(r.up_size(), r.down_size());
  StatusOr<Script> begun = Begin(options,
                                 "Brute-force bifurcation diagram in " + param + " (" + dirs +
                                     ", " + std::to_string(values) + " values)",
                                 ParamLabel(param), CoordinateLabel(c[0]));
  if (!begun.ok()) return begun.status();
  Script s = std::move(begun).value();
  const auto rows = [&](const google::protobuf::RepeatedPtrField<v1::SweepPoint>& points) {
    std::string out;
    for (const v1::SweepPoint& point : points) {
      for (const v1::PoincarePoint& sample : point.samples()) {
        out += Num(point.value()) + " " + Num(Coordinate(sample, c[0])) + "\n";
      }
    }
    return out;
  };
  const std::string up = rows(r.up()), down = rows(r.down());
  if (!up.empty()) {
    s.Data("up", up);
    s.Plot("$up using 1:2 with points pt 7 ps 0.5 lc rgb '#1f4e9c' title 'sweep up (" + param +
           " increasing)'");
  }
  if (!down.empty()) {
    s.Data("down", down);
    s.Plot("$down using 1:2 with points pt 6 ps 0.9 lc rgb '#d62728' title 'sweep down (" + param +
           " decreasing)'");
  }
  if (s.Empty()) return InvalidArgument("the sweep result has no Poincare samples to draw");
  return s.Text("drillctl plot: brute-force bifurcation diagram in " + param);
}

// The two traced parameters: the region's, else the two that vary most over the curves.
std::pair<std::string, std::string> TracePlane(const v1::TraceResult& r) {
  if (r.region().params_size() == 2) return {r.region().params(0), r.region().params(1)};
  std::vector<std::pair<double, std::string>> spans;
  for (const char* name : kParamNames) {
    double lo = INFINITY, hi = -INFINITY;
    for (const v1::Curve& curve : r.curves()) {
      for (const v1::CurveVertex& v : curve.points()) {
        lo = std::min(lo, ParamValue(v.params(), name));
        hi = std::max(hi, ParamValue(v.params(), name));
      }
    }
    const double span = hi > lo ? (hi - lo) / std::max(std::abs(hi) + std::abs(lo), 1e-300) : 0.0;
    spans.push_back({span, name});
  }
  std::stable_sort(spans.begin(), spans.end(),
                   [](const auto& x, const auto& y) { return x.first > y.first; });
  return {spans[0].second, spans[1].second};
}

StatusOr<std::string> TraceScript(const v1::TraceResult& r, const PlotOptions& options) {
  const auto [px, py] = TracePlane(r);
  std::string fixed;
  if (r.curves_size() > 0 && r.curves(0).points_size() > 0) {
    fixed = FixedParams(r.curves(0).points(0).params(), {px, py});
  }
  StatusOr<Script> begun =
      Begin(options,
            "Two-parameter bifurcation diagram in (" + px + ", " + py + ")" +
                (r.has_region() ? " with the stability region of period-1 motion" : std::string()),
            ParamLabel(px), ParamLabel(py), fixed);
  if (!begun.ok()) return begun.status();
  Script s = std::move(begun).value();
  // Many long entries (signatures): the legend goes below the plot, in two columns.
  s.Set("set key below center box vertical maxrows 5 spacing 1.2 samplen 3 height 0.5");
  s.Set("set xlabel offset 0,0.6");

  // The stability region first, so that curves and points are drawn over it.
  const v1::StabilityRegion& region = r.region();
  if (r.has_region()) {
    if (region.min_size() == 2 && region.max_size() == 2) {
      // The box, outlined, with 3% of room around it so that markers on its edges show whole.
      const double dx = 0.03 * (region.max(0) - region.min(0));
      const double dy = 0.03 * (region.max(1) - region.min(1));
      s.Set("set xrange [" + Num(region.min(0) - dx) + ":" + Num(region.max(0) + dx) + "]");
      s.Set("set yrange [" + Num(region.min(1) - dy) + ":" + Num(region.max(1) + dy) + "]");
      s.Set("set object 1 rect from " + Num(region.min(0)) + "," + Num(region.min(1)) + " to " +
            Num(region.max(0)) + "," + Num(region.max(1)) +
            " fs empty border lc rgb '#777777' dt 3 lw 1 back");
    }
    std::map<int, std::string> rings;
    for (const v1::RegionPolygon& polygon : region.polygons()) {
      std::string& out = rings[polygon.signature()];
      for (const v1::RegionVertex& v : polygon.vertices()) {
        out += Num(v.value1()) + " " + Num(v.value2()) + "\n";
      }
      out += "\n";
    }
    for (const auto& [signature, rows] : rings) {
      const std::string name = "region" + std::to_string(signature);
      const std::string text = signature >= 0 && signature < region.signatures_size()
                                   ? region.signatures(signature)
                                   : std::to_string(signature);
      s.Data(name, rows);
      s.Plot("$" + name + " using 1:2 with filledcurves closed fs transparent solid 0.3 noborder" +
             " lc rgb '" + kRegionColors[static_cast<size_t>(signature) % kRegionColors.size()] +
             "' title " + Quote("stable period-1: " + text));
    }
  }

  // Curves grouped by kind and period (one legend entry each); period > 1 dashed.
  std::map<std::pair<std::string, int>, std::string> curves;
  for (const v1::Curve& curve : r.curves()) {
    std::string& out = curves[{curve.kind(), curve.period()}];
    for (const v1::CurveVertex& v : curve.points()) {
      out += Num(ParamValue(v.params(), px)) + " " + Num(ParamValue(v.params(), py)) + "\n";
    }
    out += "\n";
  }
  int index = 0;
  for (const auto& [key, rows] : curves) {
    const auto& [kind, period] = key;
    const std::string name = "curve" + std::to_string(index);
    s.Data(name, rows);
    // Grazing curves run next to period-doubling ones: drawn wider (and first) they show as a
    // border around them.
    const std::string width = kind == "GRAZING" ? "5" : "2";
    s.Plot("$" + name + " using 1:2 with lines lw " + width + " dashtype " +
           (period > 1 ? "2" : "1") + " lc rgb '" + CurveColor(kind, index) + "' title " +
           Quote(kind + " curve" +
                 (period > 1 ? " (period " + std::to_string(period) + ")" : std::string())));
    ++index;
  }

  // Codimension-2 points by kind.
  std::map<std::string, std::string> codim2;
  for (const v1::Codim2Point& p : r.codim2_points()) {
    codim2[p.kind()] +=
        Num(ParamValue(p.params(), px)) + " " + Num(ParamValue(p.params(), py)) + "\n";
  }
  index = 0;
  for (const auto& [kind, rows] : codim2) {
    const Style style = Codim2Style(index);
    const std::string name = "codim2_" + std::to_string(index);
    s.Data(name, rows);
    // Sizes grow with the index: coincident points of different kinds nest.
    s.Plot("$" + name + " using 1:2 with points pt " + std::to_string(style.point_type) + " ps " +
           Num(1.6 + 0.5 * index) + " lw 2 lc rgb '" + style.color + "' title " + Quote(kind));
    ++index;
  }

  if (options.optimum.has_value()) {
    const v1::OptimumResult& o = *options.optimum;
    const double x = ParamValue(o.params(), px), y = ParamValue(o.params(), py);
    s.Data("optimum", Num(x) + " " + Num(y) + "\n");
    std::string margin;
    for (int i = 0; i < o.margin_size(); ++i) margin += (i ? ", " : "") + Short(o.margin(i));
    s.Plot("$optimum using 1:2 with points pt 3 ps 3.5 lw 3 lc rgb '#000000' title " +
           Quote("optimum: ROP " + Short(o.rop()) +
                 (margin.empty() ? "" : " (margin " + margin + ")")));
    s.Set("set label " + Quote("optimum " + px + " = " + Short(x) + ", " + py + " = " + Short(y)) +
          " at " + Num(x) + "," + Num(y) +
          " offset char 1.2,char 1.2 font ',11' tc rgb '#000000' front");
  }
  if (s.Empty()) return InvalidArgument("the trace result has no curves and no region to draw");
  return s.Text("drillctl plot: two-parameter diagram in (" + px + ", " + py + ")");
}

StatusOr<std::string> SimulateScript(const v1::SimulateResult& r, const PlotOptions& options) {
  const bool trajectory = r.trajectory_size() > 0;
  StatusOr<Script> begun =
      Begin(options,
            trajectory ? "Phase portrait: trajectory (" + std::to_string(r.trajectory_size()) +
                             " points) coloured by mode"
                       : "Poincare samples at the section s = 0 (" +
                             std::to_string(r.poincare_size()) + " periods)",
            "p: bit position relative to the slider bottom (dimensionless)",
            "y: bit velocity (dimensionless)");
  if (!begun.ok()) return begun.status();
  Script s = std::move(begun).value();
  if (trajectory) {
    // Runs of one mode; each run starts at the previous run's last point so that they join.
    std::map<int, std::string> by_mode;
    for (int i = 0; i < r.trajectory_size(); ++i) {
      const v1::TrajectoryPoint& p = r.trajectory(i);
      const std::string row = Num(p.p()) + " " + Num(p.y()) + "\n";
      if (i > 0 && r.trajectory(i - 1).mode() != p.mode()) {
        by_mode[r.trajectory(i - 1).mode()] += row + "\n";
        const v1::TrajectoryPoint& q = r.trajectory(i - 1);
        by_mode[p.mode()] += Num(q.p()) + " " + Num(q.y()) + "\n";
      }
      by_mode[p.mode()] += row;
    }
    for (const auto& [mode_number, rows] : by_mode) {
      const auto mode = static_cast<v1::Mode>(mode_number);
      const std::string name = "mode" + std::to_string(mode_number);
      s.Data(name, rows);
      s.Plot("$" + name + " using 1:2 with lines lw 2 lc rgb '" + ModeStyle(mode).color +
             "' title " + Quote(ModeTitle(mode)));
    }
  }
  if (r.poincare_size() > 0) {
    std::map<int, std::string> by_mode;
    for (const v1::PoincarePoint& p : r.poincare()) {
      by_mode[trajectory ? 0 : p.mode()] += Num(p.p()) + " " + Num(p.y()) + "\n";
    }
    for (const auto& [mode_number, rows] : by_mode) {
      const auto mode = static_cast<v1::Mode>(mode_number);
      const std::string name = "poincare" + std::to_string(mode_number);
      s.Data(name, rows);
      const std::string title =
          trajectory ? std::string("Poincare section s = 0")
                     : "Poincare samples" +
                           (mode == v1::MODE_UNSPECIFIED ? std::string() : ", " + ModeTitle(mode));
      s.Plot("$" + name + " using 1:2 with points pt 6 ps 1.6 lw 2 lc rgb '" +
             (trajectory ? std::string("#000000") : std::string(ModeStyle(mode).color)) +
             "' title " + Quote(title));
    }
  }
  if (s.Empty()) {
    return InvalidArgument(
        "the simulate result has no trajectory and no Poincare samples to draw (simulate with "
        "--trajectory-dt DT or --poincare)");
  }
  return s.Text("drillctl plot: phase portrait");
}

// An optimum map over one condition: the optimum's ROP against the condition (left axis) and its
// two trace parameters (right axis), one point per cell in the condition's order; a cell without
// an optimum is a gap in the lines and a cross on the axis. Over two conditions: each cell a
// square at its two conditions, coloured by ROP (crosses where none).
StatusOr<std::string> MapScript(const v1::OptimumMapResult& r, const PlotOptions& options) {
  std::vector<const v1::OptimumMapCell*> cells;
  for (const v1::OptimumMapCell& c : r.cells()) cells.push_back(&c);
  std::stable_sort(cells.begin(), cells.end(), [](const auto* x, const auto* y) {
    return std::lexicographical_compare(x->condition().rbegin(), x->condition().rend(),
                                        y->condition().rbegin(), y->condition().rend());
  });
  if (r.over_size() < 1 || r.over_size() > 2) {
    return InvalidArgument("the optimum map names no condition (over) to draw against");
  }
  const std::string p1 = r.optimum().trace().trace_params_size() == 2
                             ? r.optimum().trace().trace_params(0)
                             : std::string("omega");
  const std::string p2 = r.optimum().trace().trace_params_size() == 2
                             ? r.optimum().trace().trace_params(1)
                             : std::string("a");
  std::string found, missing;
  for (const v1::OptimumMapCell* c : cells) {
    std::string at;
    for (double v : c->condition()) at += Num(v) + " ";
    if (c->optimum().status() == "COMPLETED" && c->optimum().has_params()) {
      found += at + Num(c->optimum().rop()) + " " + Num(ParamValue(c->optimum().params(), p1)) +
               " " + Num(ParamValue(c->optimum().params(), p2)) + "\n";
    } else {
      found += r.over_size() == 1 ? "\n" : "";  // a gap in the lines
      missing += at + "0\n";
    }
  }
  const bool two = r.over_size() == 2;
  StatusOr<Script> begun =
      Begin(options,
            "Robust ROP optimum over " + r.over(0) + (two ? " and " + r.over(1) : std::string()) +
                " (" + std::to_string(cells.size()) + " cells)",
            ParamLabel(r.over(0)), two ? ParamLabel(r.over(1)) : std::string("ROP at the optimum"));
  if (!begun.ok()) return begun.status();
  Script s = std::move(begun).value();
  s.Data("found", found);
  if (two) {
    s.Set("set cblabel 'ROP at the optimum'");
    s.Plot("$found using 1:2:3 with points pt 5 ps 3 lc palette title 'optimum found'");
    if (!missing.empty()) s.Data("missing", missing);
    if (!missing.empty())
      s.Plot(
          "$missing using 1:2 with points pt 2 ps 2 lc rgb '#000000' "
          "title 'no optimum'");
  } else {
    s.Set("set y2label '" + p1 + ", " + p2 + " at the optimum'");
    s.Set("set y2tics");
    s.Set("set ytics nomirror");
    s.Plot("$found using 1:2 with linespoints pt 7 lc rgb '#1f4e9c' title 'ROP'");
    s.Plot("$found using 1:3 axes x1y2 with linespoints pt 4 lc rgb '#d62728' title '" + p1 + "'");
    s.Plot("$found using 1:4 axes x1y2 with linespoints pt 6 lc rgb '#2ca02c' title '" + p2 + "'");
    if (!missing.empty()) {
      s.Data("missing", missing);
      s.Plot("$missing using 1:2 with points pt 2 ps 2 lc rgb '#000000' title 'no optimum'");
    }
  }
  return s.Text("drillctl plot: optimum map over " + r.over(0));
}

template <typename T>
bool TryParse(const std::string& json, T* message) {
  google::protobuf::util::JsonParseOptions options;
  options.ignore_unknown_fields = false;
  return google::protobuf::util::JsonStringToMessage(json, message, options).ok();
}

}  // namespace

std::string ResultKindName(const AnyResult& result) {
  constexpr std::array<const char*, 6> kNames = {"continue", "sweep",   "trace",
                                                 "simulate", "optimum", "optimum-map"};
  return kNames[result.index()];
}

StatusOr<AnyResult> ParseResultJson(const std::string& json) {
  if (v1::ContinueResult r; TryParse(json, &r) && r.points_size() > 0) return AnyResult(r);
  if (v1::SweepResult r; TryParse(json, &r) && r.up_size() + r.down_size() > 0) {
    return AnyResult(r);
  }
  if (v1::TraceResult r; TryParse(json, &r) && (r.curves_size() > 0 || r.has_region())) {
    return AnyResult(r);
  }
  if (v1::SimulateResult r; TryParse(json, &r) && r.trajectory_size() + r.poincare_size() > 0) {
    return AnyResult(r);
  }
  if (v1::OptimumResult r; TryParse(json, &r) && r.has_params()) return AnyResult(r);
  if (v1::OptimumMapResult r; TryParse(json, &r) && r.cells_size() > 0) return AnyResult(r);

  google::protobuf::Struct object;
  const auto status = google::protobuf::util::JsonStringToMessage(json, &object);
  if (!status.ok()) return InvalidArgument("not a JSON object: " + std::string(status.message()));
  std::string keys;
  for (const auto& [key, value] : object.fields()) keys += (keys.empty() ? "" : ", ") + key;
  return InvalidArgument(
      "unknown result kind: its fields (" + keys +
      ") are those of no drillctl result with something to draw (a continue result with "
      "points, a sweep with up or down, a trace with curves or region, a simulation with "
      "trajectory or poincare, an optimum, an optimum map with cells)");
}

StatusOr<std::string> BuildPlotScript(const AnyResult& result, const PlotOptions& options) {
  if (const auto* r = std::get_if<v1::ContinueResult>(&result)) return ContinueScript(*r, options);
  if (const auto* r = std::get_if<v1::SweepResult>(&result)) return SweepScript(*r, options);
  if (const auto* r = std::get_if<v1::TraceResult>(&result)) return TraceScript(*r, options);
  if (const auto* r = std::get_if<v1::SimulateResult>(&result)) return SimulateScript(*r, options);
  if (const auto* r = std::get_if<v1::OptimumMapResult>(&result)) return MapScript(*r, options);
  return InvalidArgument(
      "an optimum result alone has nothing to draw but a point: plot the trace of the same box "
      "with its region (drillctl trace --region ... -o trace.json) and mark the optimum on it: "
      "drillctl plot trace.json --optimum OPTIMUM.json -o FIGURE.png");
}

Status RenderWithGnuplot(const std::string& script, const std::string& output) {
  std::string dir = (std::filesystem::temp_directory_path() / "drillctl-plot-XXXXXX").string();
  if (mkdtemp(dir.data()) == nullptr) {
    return Internal("cannot create a temporary directory: " + std::string(std::strerror(errno)));
  }
  struct Cleanup {
    std::string dir;
    ~Cleanup() {
      std::error_code ignored;
      std::filesystem::remove_all(dir, ignored);
    }
  } cleanup{dir};
  const std::string script_path = dir + "/plot.gp", err_path = dir + "/gnuplot.err";
  {
    std::ofstream file(script_path, std::ios::binary);
    file << script;
    if (!file.flush()) return Internal("cannot write " + script_path);
  }
  std::error_code ignored;
  std::filesystem::remove(output, ignored);  // so that a stale figure is not taken for a new one

  std::vector<std::string> args = {"gnuplot", script_path};
  std::vector<char*> argv;
  for (std::string& a : args) argv.push_back(a.data());
  argv.push_back(nullptr);
  posix_spawn_file_actions_t actions;
  posix_spawn_file_actions_init(&actions);
  posix_spawn_file_actions_addopen(&actions, STDIN_FILENO, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_addopen(&actions, STDOUT_FILENO, err_path.c_str(),
                                   O_WRONLY | O_CREAT | O_APPEND, 0644);
  posix_spawn_file_actions_addopen(&actions, STDERR_FILENO, err_path.c_str(),
                                   O_WRONLY | O_CREAT | O_APPEND, 0644);
  pid_t pid = -1;
  const int rc = posix_spawnp(&pid, "gnuplot", &actions, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&actions);
  if (rc == ENOENT) {
    return Status(StatusCode::kFailedPrecondition,
                  "gnuplot is not installed (not found on PATH): install it, e.g. apt-get install "
                  "gnuplot-nox (scripts/setup.sh does), or write the script with --script FILE "
                  "and run it elsewhere");
  }
  if (rc != 0) return Internal("cannot start gnuplot: " + std::string(std::strerror(rc)));
  int wait_status = 0;
  while (waitpid(pid, &wait_status, 0) < 0) {
    if (errno != EINTR)
      return Internal("waiting for gnuplot: " + std::string(std::strerror(errno)));
  }
  std::ifstream err_file(err_path);
  std::stringstream err;
  err << err_file.rdbuf();
  const bool exited_ok = WIFEXITED(wait_status) && WEXITSTATUS(wait_status) == 0;
  if (!exited_ok) return Internal("gnuplot failed:\n" + err.str());
  if (!std::filesystem::exists(output, ignored) ||
      std::filesystem::file_size(output, ignored) == 0) {
    return Internal("gnuplot wrote no figure to " + output + ":\n" + err.str());
  }
  return Status::Ok();
}

}  // namespace drillbif::client
