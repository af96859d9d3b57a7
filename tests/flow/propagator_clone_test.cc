// Propagator::Clone: a propagator for another thread gives the same results, to the bit, as the
// one it was cloned from (the curve tasks of a trace rely on it for a result independent of the
// number of threads), and carries no throttle of its own.
#include <gtest/gtest.h>

#include <cstring>
#include <memory>
#include <thread>

#include "drillbif/flow/cvode_propagator.h"
#include "drillbif/flow/exact_propagator.h"
#include "drillbif/model/drifting_oscillator.h"
#include "problems/drifting_reference.h"
#include "problems/reference_orbit.h"

namespace drillbif {
namespace {

using DO = DriftingOscillator;

bool SameBits(const Eigen::MatrixXd& a, const Eigen::MatrixXd& b) {
  return a.rows() == b.rows() && a.cols() == b.cols() &&
         std::memcmp(a.data(), b.data(), sizeof(double) * a.size()) == 0;
}

// Every segment of the reference orbit flowed with its Jacobians and advanced to its event, by
// `original` on this thread and by its clone on another.
void ExpectCloneGivesTheSameBits(const DO& model, Propagator& original) {
  const StatusOr<PeriodicOrbit> orbit =
      testing::SolvedOrbitFromRest(model, original, testing::ReferenceParams());
  ASSERT_TRUE(orbit.ok()) << orbit.status().ToString();
  std::unique_ptr<Propagator> clone = original.Clone();
  ASSERT_NE(clone, nullptr);
  EXPECT_EQ(clone->name(), original.name());
  const FlowRequest all{true, true};
  for (size_t i = 0; i < orbit->starts.size(); ++i) {
    const int mode = orbit->signature.segments[i].mode;
    const StateVector& x0 = orbit->starts[i];
    const double t = orbit->durations[i];
    const FlowResult a = original.FlowMap(mode, x0, t, orbit->params, all);
    AdvanceRequest advance{mode, x0, 2.0 * t + 1.0, true};
    const AdvanceResult c = original.Advance(advance, orbit->params);
    FlowResult b;
    AdvanceResult d;
    std::thread([&] {
      b = clone->FlowMap(mode, x0, t, orbit->params, all);
      d = clone->Advance(advance, orbit->params);
    }).join();
    ASSERT_TRUE(a.status.ok() && c.status.ok()) << i;
    EXPECT_TRUE(SameBits(a.x, b.x)) << i;
    EXPECT_TRUE(SameBits(a.state_jacobian, b.state_jacobian)) << i;
    EXPECT_TRUE(SameBits(a.param_jacobian, b.param_jacobian)) << i;
    EXPECT_EQ(c.end, d.end) << i;
    EXPECT_EQ(c.guard, d.guard) << i;
    EXPECT_TRUE(SameBits(c.x, d.x)) << i;
    EXPECT_TRUE(std::memcmp(&c.duration, &d.duration, sizeof c.duration) == 0) << i;
    EXPECT_TRUE(SameBits(c.measures, d.measures)) << i;
  }
}

TEST(PropagatorClone, ExactCloneGivesTheSameBitsOnAnotherThread) {
  DO model;
  ExactPropagator exact(model);
  ExpectCloneGivesTheSameBits(model, exact);
}

TEST(PropagatorClone, CvodeCloneGivesTheSameBitsOnAnotherThread) {
  DO model;
  CvodePropagator cvode(model);
  ExpectCloneGivesTheSameBits(model, cvode);
}

TEST(PropagatorClone, ACloneCarriesNoThrottle) {
  DO model;
  ExactPropagator exact(model);
  ProgressThrottle stopped;
  stopped.Stop();
  exact.set_progress(&stopped);
  ASSERT_TRUE(exact.stopped());
  const std::unique_ptr<Propagator> clone = exact.Clone();
  EXPECT_EQ(clone->progress(), nullptr);
  EXPECT_FALSE(clone->stopped());
}

}  // namespace
}  // namespace drillbif
