// Numbers in messages: printf's %g with a chosen number of significant digits. Internal to the
// engine.
#ifndef DRILLBIF_COMMON_FORMAT_H_
#define DRILLBIF_COMMON_FORMAT_H_

#include <cstdio>
#include <string>

namespace drillbif::internal {

// `v` with `digits` significant digits (17: enough to read a double back exactly).
inline std::string FormatNumber(double v, int digits = 17) {
  char buf[40];
  std::snprintf(buf, sizeof buf, "%.*g", digits, v);
  return buf;
}

}  // namespace drillbif::internal

#endif  // DRILLBIF_COMMON_FORMAT_H_
