// Prints the network of curves the trace finds in the reference (omega, a) box (problems/
// reference_box.h) as JSON, for comparing two builds (bench/compare_networks.py): per curve its
// kind, period, start kind, its crossings of omega = 0.1 and a = 0.3 (located by the curve tracer,
// CurveOptions::crossings1 / crossings2) and its codimension-2 entries. Not a benchmark: the
// acceptance of a faster trace is that it finds the same network.
//   build/bench/trace_network [threads] [max_period] [target_iterations] [condensed 0|1] > out.json
// (the curves' step settings, when not given, are CurveOptions' defaults)
#include <cstdio>
#include <cstdlib>
#include <string>

#include "drillbif/continuation/trace.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_box.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

void PrintPoint(const CurvePoint& p) { std::printf("[%.17g, %.17g]", p.value1, p.value2); }

void PrintCurve(const TracedCurve& t) {
  const CurveResult& c = t.curve;
  std::printf("{\"kind\": \"%s\", \"period\": %d, \"start\": \"%s\", \"vertices\": %zu,\n",
              CurveKindName(c.kind), t.start.point.orbit.signature.periods,
              SpecialPointKindName(t.start.kind), c.points.size());
  std::printf("  \"crossings\": [");
  for (size_t k = 0; k < c.crossings.size(); ++k) {
    if (k > 0) std::printf(", ");
    PrintPoint(c.crossings[k]);
  }
  std::printf("],\n  \"codim2\": [");
  for (size_t k = 0; k < c.codim2.size(); ++k) {
    const Codim2Point& q = c.codim2[k];
    std::printf("%s{\"kind\": \"%s\", \"at\": ", k > 0 ? ", " : "", Codim2KindName(q.kind));
    PrintPoint(q.point);
    std::printf(", \"bracket\": %.3g}", q.bracket);
  }
  std::printf("]}");
}

int Main(int argc, char** argv) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const PeriodicOrbit start =
      *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  TraceOptions options = testing::ReferenceBox();
  options.threads = argc > 1 ? std::atoi(argv[1]) : 1;
  options.max_period = argc > 2 ? std::atoi(argv[2]) : 1;
  // The curves' step settings, to compare a faster setting's network with the default's.
  if (argc > 3) options.curve.steps.target_iterations = std::atoi(argv[3]);
  if (argc > 4) options.curve.steps.condensed_solve = std::atoi(argv[4]) != 0;
  options.curve.crossings1 = {0.1};  // omega
  options.curve.crossings2 = {0.3};  // a
  const TraceResult r = TraceCurves(model, prop, start, options);
  if (!r.summary.completed()) {
    std::fprintf(stderr, "trace: %s\n", r.summary.BriefReport().c_str());
    return 1;
  }
  std::printf("{\"curves\": [\n");
  for (size_t i = 0; i < r.curves.size(); ++i) {
    if (i > 0) std::printf(",\n");
    PrintCurve(r.curves[i]);
  }
  std::printf("\n]}\n");
  return 0;
}

}  // namespace
}  // namespace drillbif

int main(int argc, char** argv) { return drillbif::Main(argc, argv); }
