// Small helpers shared by the CVODES propagator's sources (flow/cvode_*.cc): number and state
// formatting for status messages, and copies between N_Vectors and Eigen states.
#ifndef DRILLBIF_FLOW_CVODE_UTIL_H_
#define DRILLBIF_FLOW_CVODE_UTIL_H_

#include <nvector/nvector_serial.h>

#include <cstdio>
#include <string>

#include "drillbif/common/types.h"

namespace drillbif::internal {

inline std::string FormatDouble(double v) {
  char buf[32];
  std::snprintf(buf, sizeof(buf), "%.6g", v);
  return buf;
}

inline std::string FormatState(const StateVector& x) {
  std::string s = "(";
  for (int i = 0; i < x.size(); ++i) s += (i ? ", " : "") + FormatDouble(x[i]);
  return s + ")";
}

inline const double* Data(N_Vector v) { return N_VGetArrayPointer(v); }
inline double* MutableData(N_Vector v) { return N_VGetArrayPointer(v); }

inline StateVector ToState(N_Vector v, int n) {
  return Eigen::Map<const Eigen::VectorXd>(Data(v), n);
}
inline void FromState(const StateVector& x, N_Vector v) {
  Eigen::Map<Eigen::VectorXd>(MutableData(v), x.size()) = x;
}

}  // namespace drillbif::internal

#endif  // DRILLBIF_FLOW_CVODE_UTIL_H_
