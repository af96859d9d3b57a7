// Propagator: advances a hybrid model's state within one mode, either for a fixed time (FlowMap) or
// until the first guard of the mode fires (Advance). Two implementations check each other:
//   ExactPropagator  closed-form / matrix-exponential flows of linear modes with harmonic forcing;
//   CvodePropagator  SUNDIALS CVODES for any smooth vector field.
// A propagator never jumps: mode switching is the simulator's job.
#ifndef DRILLBIF_FLOW_PROPAGATOR_H_
#define DRILLBIF_FLOW_PROPAGATOR_H_

#include <memory>
#include <string>

#include "drillbif/common/progress.h"
#include "drillbif/common/status.h"
#include "drillbif/common/types.h"
#include "drillbif/model/hybrid_model.h"

namespace drillbif {

// What a FlowMap call should compute besides the state.
struct FlowRequest {
  bool state_jacobian = false;  // d x(t) / d x0
  bool param_jacobian = false;  // d x(t) / d params
  int param = -1;               // with param_jacobian: only this column (the others zero); -1 all
  int also_param = -1;          // with param >= 0: this column too (a two-parameter curve's)
};

// x(t) = phi_m(t, x0; params) and its derivatives. d x / d t is the vector field at x(t).
struct FlowResult {
  Status status;
  StateVector x;               // phase component not wrapped (s0 + omega t)
  StateMatrix state_jacobian;  // filled when requested
  ParamMatrix param_jacobian;  // filled when requested
};

// One call of Advance: flow `mode` from x0 for at most t_max.
struct AdvanceRequest {
  int mode = 0;
  StateVector x0;
  double t_max = 0.0;     // duration limit (e.g. time to the next Poincare section)
  bool measures = false;  // accumulate the model's measures over the segment
  // Samples of the trajectory every `sample_dt` (0: none). Appended to AdvanceResult::samples.
  double sample_dt = 0.0;
};

enum class AdvanceEnd {
  kTimeLimit,  // reached t_max with no event
  kEvent,      // guard `guard` fired at `duration` <= t_max
  kFailed,     // see status
};

struct TrajectorySample {
  double t = 0.0;  // time since the segment start
  StateVector x;
};

struct AdvanceResult {
  Status status;
  AdvanceEnd end = AdvanceEnd::kFailed;
  int guard = -1;           // index into model.guards(mode) when end == kEvent
  bool tangential = false;  // the event is a grazing contact: h reached 0 with dh/dt ~ 0
  double duration = 0.0;    // time flowed
  StateVector x;            // state at the end (phase not wrapped)
  MeasureVector measures;   // increments over the segment, when requested
  std::vector<TrajectorySample> samples;
  int evaluations = 0;  // flow or right-hand-side evaluations spent
};

// Options shared by both propagators' event location.
struct EventOptions {
  // Grazing resolution (absolute, in the guard's units; the drifting oscillator's guards are O(1)):
  // every crossing (h reaching 0) is found, however shallow; an approach that turns back with
  // 0 < h <= tolerance fires as a tangential event at the extremum, wherever the steps end (the
  // exact propagator may miss one only where h' turns twice within one step); an approach that
  // turns back at h > tolerance never fires.
  double tolerance = 1e-12;
  // Relative accuracy of event times (Newton polish stops below this times max(1, t)).
  double time_rtol = 1e-14;
  // Safety cap on location iterations in one segment, against pathological models.
  int max_iterations = 100000;

  Status Validate() const;
};

// Cancellation. A propagator can carry a ProgressThrottle (set_progress, or ScopedProgress for a
// scope): its FlowMap and Advance then poll it at every call and inside long integrations (every
// ProgressThrottle::kTickStride-th segment step or right-hand side), and once it is stopped they
// return at once with status CANCELLED: FlowMap with x = x0 and identity / zero Jacobians where
// asked, Advance with end kFailed, x = x0 and zero measures where asked (well-formed, finite,
// meaningless). Every engine computation runs on a propagator and polls it this way; the engine's
// own loops check stopped() so that nothing computed after the stop reaches a result. The
// throttle is called on the thread that calls the propagator.
class Propagator {
 public:
  virtual ~Propagator() = default;
  virtual std::string_view name() const = 0;
  virtual FlowResult FlowMap(int mode, const StateVector& x0, double t, const Params& params,
                             const FlowRequest& request) = 0;
  virtual AdvanceResult Advance(const AdvanceRequest& request, const Params& params) = 0;
  // A new propagator of the same kind, model and options, with no throttle attached: one for
  // each thread of a computation that runs tasks in parallel (a propagator is not thread-safe).
  // Its results are those of this one, bit for bit, for the same calls. Null (the default) for a
  // propagator that cannot be copied so: such a computation then runs on the calling thread.
  virtual std::unique_ptr<Propagator> Clone() const { return nullptr; }
  // Whether FlowMap's x and state_jacobian are the same bits whatever else the request asks
  // (parameter columns, or the state Jacobian besides x): a caller may then take them from a call
  // that asked for more instead of flowing again. False by default, and for CVODES, whose error
  // control includes the sensitivities asked for.
  virtual bool FlowIndependentOfRequest() const { return false; }

  // The throttle polled by this propagator's calls, or null (never cancelled).
  ProgressThrottle* progress() const { return progress_; }
  void set_progress(ProgressThrottle* progress) { progress_ = progress; }
  // Whether the throttle has seen a stop: results computed since are not to be used.
  bool stopped() const { return progress_ != nullptr && progress_->stopped(); }

 protected:
  // For implementations, at each call and in long loops: false when the call must end
  // cancelled (ProgressThrottle::Tick of the attached throttle).
  bool KeepGoing() { return progress_ == nullptr || progress_->Tick(); }
  // The results of a call ended by a stop (see above).
  FlowResult CancelledFlow(const HybridModel& model, const StateVector& x0,
                           const FlowRequest& request) const;
  AdvanceResult CancelledAdvance(const HybridModel& model, const AdvanceRequest& request) const;

 private:
  ProgressThrottle* progress_ = nullptr;
};

// Attaches a throttle to a propagator for a scope and restores the one before at its end. A null
// throttle keeps the one attached (an outer computation's), so that a computation called without
// a callback of its own is still cancelled with the one that called it.
class ScopedProgress {
 public:
  ScopedProgress(Propagator& propagator, ProgressThrottle* progress)
      : propagator_(propagator), previous_(propagator.progress()) {
    if (progress != nullptr) propagator_.set_progress(progress);
  }
  ~ScopedProgress() { propagator_.set_progress(previous_); }
  ScopedProgress(const ScopedProgress&) = delete;
  ScopedProgress& operator=(const ScopedProgress&) = delete;

 private:
  Propagator& propagator_;
  ProgressThrottle* previous_;
};

}  // namespace drillbif

#endif  // DRILLBIF_FLOW_PROPAGATOR_H_
