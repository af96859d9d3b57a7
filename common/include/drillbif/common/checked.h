// Checked 64-bit integer arithmetic: counts, sizes and costs computed from request fields must
// never wrap around (a wrapped count turns a huge request into a small one, or a page token into
// a negative offset). Each function returns std::nullopt on overflow instead of a wrong value.
#ifndef DRILLBIF_COMMON_CHECKED_H_
#define DRILLBIF_COMMON_CHECKED_H_

#include <cstdint>
#include <optional>

namespace drillbif {

// a + b, or nullopt when it does not fit an int64_t.
inline std::optional<int64_t> CheckedAdd(int64_t a, int64_t b) {
  int64_t out = 0;
  if (__builtin_add_overflow(a, b, &out)) return std::nullopt;
  return out;
}

// a * b, or nullopt when it does not fit an int64_t.
inline std::optional<int64_t> CheckedMul(int64_t a, int64_t b) {
  int64_t out = 0;
  if (__builtin_mul_overflow(a, b, &out)) return std::nullopt;
  return out;
}

// a * b, or nullopt when either operand is nullopt or the product overflows: chains of checked
// operations read as one expression, CheckedMul(CheckedMul(a, b), c).
inline std::optional<int64_t> CheckedMul(std::optional<int64_t> a, std::optional<int64_t> b) {
  if (!a || !b) return std::nullopt;
  return CheckedMul(*a, *b);
}
inline std::optional<int64_t> CheckedAdd(std::optional<int64_t> a, std::optional<int64_t> b) {
  if (!a || !b) return std::nullopt;
  return CheckedAdd(*a, *b);
}

// The int64_t nearest to a finite double in [INT64_MIN, INT64_MAX], or nullopt for NaN,
// infinities and doubles beyond that range.
inline std::optional<int64_t> CheckedFromDouble(double x) {
  // 2^63 is exactly representable; every double below it converts without overflow.
  constexpr double kTwo63 = 9223372036854775808.0;
  if (!(x >= -kTwo63 && x < kTwo63)) return std::nullopt;
  return static_cast<int64_t>(x);
}

}  // namespace drillbif

#endif  // DRILLBIF_COMMON_CHECKED_H_
