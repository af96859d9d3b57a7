// The progress and cancellation of one engine computation that takes a ProgressCallback
// (common/progress.h, flow/propagator.h): given a callback, its own throttle, attached to the
// propagator for the computation's duration so that every flow polls it; without one, the
// throttle the propagator carries from the computation that called it (whose fractions this one
// does not report: they are the outer one's), or none.
#ifndef DRILLBIF_COMMON_PHASE_PROGRESS_H_
#define DRILLBIF_COMMON_PHASE_PROGRESS_H_

#include "drillbif/common/progress.h"
#include "drillbif/flow/propagator.h"

namespace drillbif::internal {

class PhaseProgress {
 public:
  PhaseProgress(Propagator& propagator, const ProgressCallback& callback)
      : own_(callback),
        scope_(propagator, callback ? &own_ : nullptr),
        throttle_(propagator.progress()),
        reports_(static_cast<bool>(callback)) {}
  PhaseProgress(const PhaseProgress&) = delete;
  PhaseProgress& operator=(const PhaseProgress&) = delete;

  // ProgressThrottle::Continue / Tick with this computation's fraction (recorded only when it
  // has its own callback); true without a throttle.
  bool Continue(double fraction) {
    if (throttle_ == nullptr) return true;
    return reports_ ? throttle_->Continue(fraction) : throttle_->Continue();
  }
  bool Continue() { return throttle_ == nullptr || throttle_->Continue(); }
  bool Tick(double fraction) {
    if (throttle_ == nullptr) return true;
    return reports_ ? throttle_->Tick(fraction) : throttle_->Tick();
  }
  bool Tick() { return throttle_ == nullptr || throttle_->Tick(); }
  // Whether a stop was seen: nothing computed since may reach a result.
  bool stopped() const { return throttle_ != nullptr && throttle_->stopped(); }

  // The callback for a nested computation that takes one: its fraction in [0, 1] mapped to
  // [from, to] of this one. Empty when this computation has no callback of its own (the nested
  // one then polls the propagator's throttle, as this one does).
  ProgressCallback Sub(double from, double to) {
    if (!reports_) return {};
    ProgressThrottle* t = throttle_;
    return [t, from, to](double f) { return t->Continue(from + (to - from) * f); };
  }

 private:
  ProgressThrottle own_;
  ScopedProgress scope_;
  ProgressThrottle* throttle_;
  bool reports_;
};

}  // namespace drillbif::internal

#endif  // DRILLBIF_COMMON_PHASE_PROGRESS_H_
