#include "drillbif/version.h"

#ifndef DRILLBIF_VERSION_STRING
#error "DRILLBIF_VERSION_STRING must be defined by the build (engine/CMakeLists.txt)"
#endif

namespace drillbif {

const char* EngineVersion() { return DRILLBIF_VERSION_STRING; }

}  // namespace drillbif
