// A propagator that passes every call to another and records what was asked of it: how many
// flows, and whether any advance asked for measures or samples. For tests that check that only
// what a request needs is computed.
#ifndef DRILLBIF_TESTS_SUPPORT_SPY_PROPAGATOR_H_
#define DRILLBIF_TESTS_SUPPORT_SPY_PROPAGATOR_H_

#include <string_view>

#include "drillbif/flow/propagator.h"

namespace drillbif::testing {

class SpyPropagator : public Propagator {
 public:
  explicit SpyPropagator(Propagator& inner) : inner_(inner) {}
  std::string_view name() const override { return "spy"; }
  FlowResult FlowMap(int mode, const StateVector& x0, double t, const Params& params,
                     const FlowRequest& request) override {
    ++flows;
    return inner_.FlowMap(mode, x0, t, params, request);
  }
  AdvanceResult Advance(const AdvanceRequest& request, const Params& params) override {
    measures_asked |= request.measures;
    samples_asked |= request.sample_dt > 0.0;
    return inner_.Advance(request, params);
  }
  int flows = 0;
  bool measures_asked = false;
  bool samples_asked = false;

 private:
  Propagator& inner_;
};

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_SUPPORT_SPY_PROPAGATOR_H_
