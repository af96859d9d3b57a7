// `drillctl plot`: figures of drillctl's JSON results, rendered by gnuplot.
//
// The library part builds a self-contained gnuplot script (the data inline as datablocks, so the
// script can be kept, edited and re-run with `gnuplot FILE`) from a result proto; it needs no
// gnuplot and is what the tests check. RenderWithGnuplot runs the gnuplot binary on such a script.
//
// Figures, by result kind:
//   ContinueResult  ROP (or power) against the continued parameter; stable solid, unstable
//                   dashed; special points marked by kind and labelled; the period-doubled
//                   branch, when present, in a second colour.
//   SweepResult     Poincare samples' coordinate (y by default) against the swept parameter,
//                   dots, up and down sweeps in two colours.
//   TraceResult     the curves in the plane of the two traced parameters coloured by kind,
//                   codimension-2 points marked by kind, the stability region shaded from its
//                   polygons (when the trace has one), and an optimum marked (when given).
//   SimulateResult  phase portrait (p, y) of the trajectory coloured by mode, with the Poincare
//                   samples; without a trajectory, the Poincare samples alone.
// An OptimumResult alone is a single point: it is only drawn on a trace's figure.
#ifndef DRILLBIF_CLIENT_PLOT_H_
#define DRILLBIF_CLIENT_PLOT_H_

#include <optional>
#include <string>
#include <variant>

#include "drillbif/common/status.h"
#include "drillbif/v1/continue.pb.h"
#include "drillbif/v1/optimum.pb.h"
#include "drillbif/v1/optimum_map.pb.h"
#include "drillbif/v1/simulate.pb.h"
#include "drillbif/v1/sweep.pb.h"
#include "drillbif/v1/trace.pb.h"

namespace drillbif::client {

// Any result drillctl prints.
using AnyResult = std::variant<v1::ContinueResult, v1::SweepResult, v1::TraceResult,
                               v1::SimulateResult, v1::OptimumResult, v1::OptimumMapResult>;

// "continue", "sweep", "trace", "simulate", "optimum" or "optimum-map".
std::string ResultKindName(const AnyResult& result);

// Parses a result printed by drillctl as JSON: each result type is tried with unknown fields
// refused, and the first that parses and has its characteristic fields wins (continue: points;
// sweep: up or down; trace: curves or region; simulate: trajectory or poincare; optimum: params;
// optimum map: cells).
// INVALID_ARGUMENT when the text is not JSON or is no result with anything to draw; the message
// says what was tried.
StatusOr<AnyResult> ParseResultJson(const std::string& json);

// What to draw and where.
struct PlotOptions {
  // The figure's path, written into the script's `set output`. Its extension picks the terminal:
  // .png (pngcairo) or .svg; anything else is INVALID_ARGUMENT.
  std::string output = "figure.png";
  // Continue: the measure on the vertical axis, "rop" or "power" ("pc" is accepted for power).
  std::string measure = "rop";
  // Sweep: the Poincare coordinate on the vertical axis, "p", "y" or "q". y (the bit velocity at
  // the section) separates period-1 and period-n motion best.
  std::string coordinate = "y";
  // The parameter's name when the result does not carry it (a sweep result does not); empty:
  // found from the result where possible (continue, trace), else "parameter".
  std::string param;
  // Trace: an optimum to mark (drillctl optimum's result for the same box).
  std::optional<v1::OptimumResult> optimum;
  // Overrides the derived title when not empty.
  std::string title;
  // Figure size in pixels (the SVG's nominal size too). 1100 x 720 keeps an outside legend and
  // 11-point text readable.
  int width = 1100;
  int height = 720;
};

// The gnuplot script that draws `result` into options.output. INVALID_ARGUMENT for a bad output
// extension, measure or coordinate, an optimum result alone (nothing to draw but a point: plot the
// trace with --region of the same box and pass the optimum with --optimum), or a result with
// nothing to draw.
StatusOr<std::string> BuildPlotScript(const AnyResult& result, const PlotOptions& options);

// Runs `gnuplot SCRIPT` (no shell; posix_spawnp on PATH) on `script` written to a fresh temporary
// directory, which is removed afterwards. FAILED_PRECONDITION when gnuplot is not installed;
// INTERNAL with gnuplot's stderr when it fails or the output file is missing afterwards.
Status RenderWithGnuplot(const std::string& script, const std::string& output);

}  // namespace drillbif::client

#endif  // DRILLBIF_CLIENT_PLOT_H_
