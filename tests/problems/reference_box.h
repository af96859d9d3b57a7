// The reference (omega, a) box, omega in [0.05, 2], a in [0.01, 8] (at the reference b = 0.15):
// where every period-1 fold, PD and grazing curve is to be traced. Shared by tests and benches.
#ifndef DRILLBIF_TESTS_PROBLEMS_REFERENCE_BOX_H_
#define DRILLBIF_TESTS_PROBLEMS_REFERENCE_BOX_H_

#include <string>

#include "drillbif/continuation/trace.h"

namespace drillbif::testing {

// The trace options of the reference (omega, a) box, every other option at its default.
inline TraceOptions ReferenceBox() {
  TraceOptions o;
  o.param1 = std::string("omega");  // not = "omega": GCC 12 -Wrestrict false positive
  o.param2 = std::string("a");
  o.min1 = 0.05, o.max1 = 2.0;
  o.min2 = 0.01, o.max2 = 8.0;
  return o;
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_PROBLEMS_REFERENCE_BOX_H_
