// Status, StatusOr, the RETURN_IF_ERROR / ASSIGN_OR_RETURN macros and checked arithmetic
// (common/include/drillbif/common/).
#include "drillbif/common/status.h"

#include <gtest/gtest.h>

#include <cstdint>
#include <limits>
#include <string>

#include "drillbif/common/checked.h"

namespace drillbif {
namespace {

StatusOr<int> Half(int x) {
  if (x % 2 != 0) return InvalidArgument("x: odd (" + std::to_string(x) + ")");
  return x / 2;
}

Status QuarterInto(int x, int* out) {
  DRILLBIF_ASSIGN_OR_RETURN(const int half, Half(x));
  DRILLBIF_ASSIGN_OR_RETURN(*out, Half(half));
  return Status::Ok();
}

Status FailsIfNegative(int x) {
  DRILLBIF_RETURN_IF_ERROR(x < 0 ? OutOfRange("negative") : Status::Ok());
  DRILLBIF_RETURN_IF_ERROR(Half(x));  // A StatusOr's status.
  return Status::Ok();
}

TEST(StatusMacros, AssignOrReturnPassesValuesAndReturnsTheFirstError) {
  int out = 0;
  EXPECT_TRUE(QuarterInto(12, &out).ok());
  EXPECT_EQ(out, 3);
  const Status odd_late = QuarterInto(6, &out);  // 6 -> 3, then 3 is odd.
  EXPECT_EQ(odd_late.code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(odd_late.message(), "x: odd (3)");
}

TEST(StatusMacros, ReturnIfErrorTakesStatusAndStatusOr) {
  EXPECT_TRUE(FailsIfNegative(4).ok());
  EXPECT_EQ(FailsIfNegative(-2).code(), StatusCode::kOutOfRange);
  EXPECT_EQ(FailsIfNegative(5).code(), StatusCode::kInvalidArgument);
}

TEST(StatusOr, AnOkStatusWithoutValueBecomesInternal) {
  const StatusOr<int> s = Status::Ok();
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(s.status().code(), StatusCode::kInternal);
}

TEST(StatusOrDeathTest, ValueOfAnErrorAbortsWithTheStatus) {
  const StatusOr<int> s = NotFound("no such job");
  EXPECT_DEATH((void)s.value(), "value\\(\\) on an error: NOT_FOUND: no such job");
  EXPECT_DEATH((void)*s, "NOT_FOUND");
}

TEST(StatusCodeName, NamesEveryGrpcCode) {
  // The codes are gRPC's 0..16; each has its google.rpc.Code name.
  for (int c = 0; c <= 16; ++c) {
    EXPECT_STRNE(StatusCodeName(static_cast<StatusCode>(c)), "") << c;
  }
  EXPECT_STREQ(StatusCodeName(StatusCode::kDataLoss), "DATA_LOSS");
  EXPECT_STREQ(StatusCodeName(StatusCode::kPermissionDenied), "PERMISSION_DENIED");
}

TEST(Checked, AddAndMulReportOverflowInsteadOfWrapping) {
  constexpr int64_t kMax = std::numeric_limits<int64_t>::max();
  EXPECT_EQ(CheckedAdd(kMax - 1, 1), kMax);
  EXPECT_FALSE(CheckedAdd(kMax, 1).has_value());
  EXPECT_EQ(CheckedMul(int64_t{3037000499}, int64_t{3037000499}),
            int64_t{9223372030926249001});  // floor(sqrt(2^63 - 1))^2 fits.
  EXPECT_FALSE(CheckedMul(int64_t{3037000500}, int64_t{3037000500}).has_value());
  // 2^31 - 1 forcing periods times 10^6 samples a period: the request that once wrapped.
  EXPECT_FALSE(CheckedMul(CheckedMul(int64_t{2147483647}, int64_t{1000000}),
                          int64_t{1} << 40)
                   .has_value());
  EXPECT_FALSE(CheckedMul(std::optional<int64_t>(), std::optional<int64_t>(2)).has_value());
}

TEST(Checked, FromDoubleRefusesNaNInfinityAndOutOfRange) {
  EXPECT_EQ(CheckedFromDouble(1e18), int64_t{1000000000000000000});
  EXPECT_EQ(CheckedFromDouble(-2.5), int64_t{-2});
  EXPECT_FALSE(CheckedFromDouble(9223372036854775808.0).has_value());
  EXPECT_FALSE(CheckedFromDouble(std::numeric_limits<double>::quiet_NaN()).has_value());
  EXPECT_FALSE(CheckedFromDouble(std::numeric_limits<double>::infinity()).has_value());
}

}  // namespace
}  // namespace drillbif
