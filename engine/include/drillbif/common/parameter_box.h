// A box in two named model parameters, (param1, param2) in [min1, max1] x [min2, max2]: the plane
// and bounds of a trace, a curve, a stability region. The option and result structs that have one
// derive from it, so that it is defined, copied and measured in one place.
#ifndef DRILLBIF_COMMON_PARAMETER_BOX_H_
#define DRILLBIF_COMMON_PARAMETER_BOX_H_

#include <limits>
#include <string>

namespace drillbif {

struct ParameterBox {
  std::string param1, param2;  // e.g. "omega", "a"
  // Unbounded unless set; each user says what it requires (a trace and a region: finite, min <
  // max; a curve stops at the edges it is given).
  double min1 = -std::numeric_limits<double>::infinity();
  double max1 = std::numeric_limits<double>::infinity();
  double min2 = -std::numeric_limits<double>::infinity();
  double max2 = std::numeric_limits<double>::infinity();

  double width1() const { return max1 - min1; }
  double width2() const { return max2 - min2; }
  // The box itself (of a struct derived from it), e.g. to copy one struct's box into another's.
  ParameterBox& box() { return *this; }
  const ParameterBox& box() const { return *this; }
};

}  // namespace drillbif

#endif  // DRILLBIF_COMMON_PARAMETER_BOX_H_
