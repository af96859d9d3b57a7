// The reference (omega, a) box's trace as a graph of curve tasks, measured on one thread: each
// curve's time (from the hand-over of the curve before it to its own), the curve it depends on
// (TracedCurve::from_curve: the curve whose codimension-2 point it was switched from; -1 for a
// curve started from the one-parameter branches), and what that allows on P workers:
//   work T1 = the sum of the task times, the critical path CP = the longest chain of dependent
//   tasks, and T_P >= max(T1 / P, CP); any greedy schedule (a queue of ready tasks, as the store
//   would hand them out) finishes within T1 / P + CP (Graham's bound).
// Not a benchmark: the figures of docs/scale.md come from it.
//   build/bench/trace_tasks [max_period] > tasks.txt
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <vector>

#include "drillbif/continuation/trace.h"
#include "drillbif/flow/exact_propagator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_box.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

using Clock = std::chrono::steady_clock;

double Ms(Clock::duration d) { return std::chrono::duration<double, std::milli>(d).count(); }

double Quantile(std::vector<double> v, double q) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[static_cast<size_t>(q * static_cast<double>(v.size() - 1))];
}

int Main(int argc, char** argv) {
  DriftingOscillator model;
  ExactPropagator prop(model);
  const PeriodicOrbit start =
      *testing::SolvedOrbitFromRest(model, prop, testing::ReferenceParams());
  TraceOptions options = testing::ReferenceBox();
  options.threads = 1;
  options.max_period = argc > 1 ? std::atoi(argv[1]) : 1;
  std::vector<double> handed_ms;  // by curve index: when it was handed over, from the start
  const Clock::time_point t0 = Clock::now();
  const TraceResult r =
      TraceCurves(model, prop, start, options, {}, [&](int index, const TracedCurve&) {
        if (static_cast<size_t>(index) >= handed_ms.size()) handed_ms.resize(index + 1, -1.0);
        handed_ms[static_cast<size_t>(index)] = Ms(Clock::now() - t0);
        return true;
      });
  const double total_ms = Ms(Clock::now() - t0);
  if (!r.summary.status.ok()) {
    std::fprintf(stderr, "trace failed: %s\n", r.summary.status.ToString().c_str());
    return 1;
  }
  // Task times: the time between hand-overs in the order they happened (one thread hands curves
  // over as they are traced; period-2 curves held back to the end are charged nothing more than
  // that wait's share). The first task includes the one-parameter branches' stage, which runs
  // before any curve.
  const size_t n = r.curves.size();
  std::vector<size_t> order(n);
  for (size_t i = 0; i < n; ++i) order[i] = i;
  std::sort(order.begin(), order.end(),
            [&](size_t a, size_t b) { return handed_ms[a] < handed_ms[b]; });
  std::vector<double> task(n, 0.0);
  double previous = 0.0;
  for (size_t k = 0; k < n; ++k) {
    task[order[k]] = handed_ms[order[k]] - previous;
    previous = handed_ms[order[k]];
  }
  // Critical path: a curve finishes after the curve it was switched from (curves depend only on
  // curves of lower index), the first ones after the branch stage.
  std::vector<double> finish(n, 0.0);
  double cp = 0.0;
  int from_branches = 0;
  for (size_t i = 0; i < n; ++i) {
    const int from = r.curves[i].from_curve;
    if (from < 0) ++from_branches;
    finish[i] = (from >= 0 ? finish[static_cast<size_t>(from)] : 0.0) + task[i];
    cp = std::max(cp, finish[i]);
  }
  double work = 0.0;
  for (double t : task) work += t;
  std::printf("period %d: %zu curve tasks (%d from the branches, %zu switched), one thread\n",
              options.max_period, n, from_branches, n - static_cast<size_t>(from_branches));
  std::printf("wall %.0f ms, curve tasks T1 %.0f ms (the first with the branches)\n", total_ms,
              work);
  std::printf("task ms: p50 %.2f, p90 %.2f, p99 %.2f, max %.1f, mean %.2f\n", Quantile(task, 0.5),
              Quantile(task, 0.9), Quantile(task, 0.99), Quantile(task, 1.0),
              n > 0 ? work / static_cast<double>(n) : 0.0);
  std::printf("critical path of the curve tasks: %.0f ms\n", cp);
  std::printf("workers  lower bound ms  greedy bound ms  speed-up at least  tasks/s\n");
  for (int p : {1, 2, 8, 32, 128}) {
    const double lower = std::max(work / p, cp);
    const double upper = work / p + cp;
    std::printf("%7d  %14.0f  %15.0f  %17.2f  %7.0f\n", p, lower, upper, total_ms / upper,
                static_cast<double>(n) / (std::max(work / p, cp) / 1000.0));
  }
  return 0;
}

}  // namespace
}  // namespace drillbif

int main(int argc, char** argv) { return drillbif::Main(argc, argv); }
