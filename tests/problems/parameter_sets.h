// Parameter sets of the drifting oscillator where the numerics are hard: the special damping
// ratios (xi = 0.5: the grazing coefficient 1 - 4 xi^2 vanishes; xi = 1: the contact mode's
// characteristic roots coincide, and just above it; tiny and large xi), extreme forcing
// frequencies, and vanishing forcing. Shared by model, flow and simulation tests.
#ifndef DRILLBIF_TESTS_PROBLEMS_PARAMETER_SETS_H_
#define DRILLBIF_TESTS_PROBLEMS_PARAMETER_SETS_H_

#include <string>
#include <vector>

#include "drillbif/model/drifting_oscillator.h"

namespace drillbif::testing {

struct NamedParams {
  std::string name;
  Params params;
};

inline std::vector<NamedParams> HardParameterSets() {
  using DO = DriftingOscillator;
  return {
      {"reference", DO::MakeParams()},
      {"xi_0_5", DO::MakeParams(0.3, 0.15, 0.1, 0.5)},
      {"xi_1", DO::MakeParams(0.3, 0.15, 0.1, 1.0)},
      {"xi_1_plus_1e_9", DO::MakeParams(0.3, 0.15, 0.1, 1.0 + 1e-9)},
      {"xi_2", DO::MakeParams(0.3, 0.15, 0.1, 2.0)},
      {"xi_0_005", DO::MakeParams(0.3, 0.15, 0.1, 0.005)},
      {"omega_0_01", DO::MakeParams(0.3, 0.15, 0.01)},
      {"omega_5", DO::MakeParams(0.3, 0.15, 5.0)},
      {"a_0", DO::MakeParams(0.0, 0.15, 0.1)},
      {"b_0", DO::MakeParams(0.3, 0.0, 0.1)},
  };
}

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_PROBLEMS_PARAMETER_SETS_H_
