// Small job requests shared by the client and service tests (seconds or less each).
#ifndef DRILLBIF_TESTS_SUPPORT_SMALL_REQUESTS_H_
#define DRILLBIF_TESTS_SUPPORT_SMALL_REQUESTS_H_

#include <string>

#include "drillbif/v1/continue.pb.h"
#include "drillbif/v1/optimum_map.pb.h"
#include "drillbif/v1/sweep.pb.h"
#include "drillbif/v1/trace.pb.h"

namespace drillbif::testing {

// omega in [0.05, 0.15], a in [0.25, 0.6] around the reference start (omega = 0.1, a = 0.3): a
// few curves, two signatures of stable period-1 motion, and an optimum the margin decides
// (tests/region/stability_region_test.cc).
inline v1::TraceRequest SmallBoxTrace() {
  v1::TraceRequest r;
  r.add_trace_params(std::string("omega"));  // not ("omega"): GCC 12 -Wrestrict false positive
  r.add_trace_params(std::string("a"));
  r.add_min(0.05);
  r.add_min(0.25);
  r.add_max(0.15);
  r.add_max(0.6);
  return r;
}

// An optimum map of SmallBoxTrace over b in [from, to] in `steps` cells (margins 0.01, 0.02 in
// omega and a; a 41 x 41 grid): ~0.5 s a cell on one thread.
inline v1::OptimumMapRequest SmallBoxMap(double from, double to, int steps) {
  v1::OptimumMapRequest r;
  v1::OptimumRequest* o = r.mutable_optimum();
  *o->mutable_trace() = SmallBoxTrace();
  o->add_margin(0.01);
  o->add_margin(0.02);
  o->add_grid(41);
  o->add_grid(41);
  r.add_over(std::string("b"));
  r.add_from(from);
  r.add_to(to);
  r.add_steps(steps);
  return r;
}

// A brute-force sweep of b over [min, 0.2] in `steps` values on one thread.
inline v1::SweepRequest SmallSweep(double min, int steps) {
  v1::SweepRequest sweep;
  sweep.set_param(std::string("b"));
  sweep.set_min(min);
  sweep.set_max(0.2);
  sweep.set_steps(steps);
  sweep.set_threads(1);
  return sweep;
}

// A sweep of b over [0, 0.2] that runs for minutes (100000 values of 501 forcing periods on one
// thread) but records little (one sample a value): a job to cancel or interrupt while it runs,
// well inside every default limit.
inline v1::SweepRequest LongSweep() {
  v1::SweepRequest sweep = SmallSweep(0.0, 100000);
  sweep.set_sample_periods(1);
  return sweep;
}

// A continuation of b from the reference orbit, decreasing, with steps capped at 1e-7: 40000
// steps (seconds to a minute) inside every default limit (admission estimates 40 s and 800 MB);
// a job to cancel or interrupt in its continuation stage (progress above the start search's 5%).
inline v1::ContinueRequest LongContinuation() {
  v1::ContinueRequest r;
  r.set_param(std::string("b"));
  r.set_min(0.1);
  r.set_max(0.2);
  r.set_direction(v1::ContinueRequest::DECREASING);
  r.set_initial_step(1e-7);
  r.set_max_step(1e-7);
  r.set_max_steps(40'000);
  return r;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_SMALL_REQUESTS_H_
