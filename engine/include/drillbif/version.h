#ifndef DRILLBIF_VERSION_H_
#define DRILLBIF_VERSION_H_

namespace drillbif {

/// Returns the engine version ("MAJOR.MINOR.PATCH"), the project version set in the top-level
/// CMakeLists.txt. Results computed by the engine (and cached by the service) are keyed on it.
/// The returned string has static storage duration.
const char* EngineVersion();

}  // namespace drillbif

#endif  // DRILLBIF_VERSION_H_
