#include "drillbif/model/hybrid_model.h"

namespace drillbif {

StatusOr<int> HybridModel::ParamIndex(std::string_view name) const {
  const auto& names = param_names();
  std::string valid;
  for (int i = 0; i < static_cast<int>(names.size()); ++i) {
    if (names[i] == name) return i;
    valid += (i ? ", " : "") + names[i];
  }
  return Status(StatusCode::kNotFound, "unknown parameter '" + std::string(name) + "' of model " +
                                           std::string(this->name()) + " (valid: " + valid + ")");
}

}  // namespace drillbif
