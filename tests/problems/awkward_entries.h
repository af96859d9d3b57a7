// Random matrix entries for the bit-for-bit tests of hand-written products: exact zeros, negative
// zeros and ones among values of either sign over several decades, where a different order of
// the sums, or a sum started elsewhere, would show in the last bits or in a zero's sign.
#ifndef DRILLBIF_TESTS_PROBLEMS_AWKWARD_ENTRIES_H_
#define DRILLBIF_TESTS_PROBLEMS_AWKWARD_ENTRIES_H_

#include <cmath>
#include <random>

namespace drillbif::testing {

class AwkwardEntries {
 public:
  explicit AwkwardEntries(unsigned seed) : rng_(seed) {}

  // 0, -0 and 1 one time in ten each, else m 10^e with m in (-1, 1) and e in (-4, 4).
  double operator()() {
    switch (pick_(rng_)) {
      case 0:
        return 0.0;
      case 1:
        return -0.0;
      case 2:
        return 1.0;
      default:
        return unit_(rng_) * std::pow(10.0, 4.0 * unit_(rng_));
    }
  }
  // Whether an entry is kept (six times in ten): for random zero columns.
  bool Keep() { return pick_(rng_) >= 4; }

 private:
  std::mt19937 rng_;
  std::uniform_real_distribution<double> unit_{-1.0, 1.0};
  std::uniform_int_distribution<int> pick_{0, 9};
};

}  // namespace drillbif::testing

#endif  // DRILLBIF_TESTS_PROBLEMS_AWKWARD_ENTRIES_H_
