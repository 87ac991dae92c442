#include "common/base/status.h"

#include <gtest/gtest.h>

#include <string>

namespace sandtable {
namespace {

Expected<int> ParsePositive(int x) {
  if (x <= 0) return InvalidArgumentError("x = " + std::to_string(x) + " must be > 0");
  return x;
}

Status Chain(int x) {
  ST_RETURN_IF_ERROR(ParsePositive(x).status());
  return OkStatus();
}

TEST(StatusTest, OkAndErrorCarryCodeAndMessage) {
  EXPECT_TRUE(OkStatus().ok());
  EXPECT_EQ(OkStatus().ToString(), "OK");
  const Status s = DegenerateError("points are coplanar");
  EXPECT_FALSE(s.ok());
  EXPECT_EQ(s.code(), StatusCode::kDegenerate);
  EXPECT_EQ(s.ToString(), "DEGENERATE: points are coplanar");
  EXPECT_EQ(s.WithContext("resection").message(), "resection: points are coplanar");
}

TEST(StatusTest, ExpectedHoldsValueOrError) {
  Expected<int> good = ParsePositive(3);
  ASSERT_TRUE(good.ok());
  EXPECT_EQ(*good, 3);
  EXPECT_TRUE(good.status().ok());
  Expected<int> bad = ParsePositive(-1);
  ASSERT_FALSE(bad.ok());
  EXPECT_EQ(bad.status().code(), StatusCode::kInvalidArgument);
  EXPECT_EQ(bad.status().message(), "x = -1 must be > 0");
}

TEST(StatusTest, ReturnIfErrorPropagates) {
  EXPECT_TRUE(Chain(1).ok());
  EXPECT_EQ(Chain(0).code(), StatusCode::kInvalidArgument);
}

TEST(StatusDeathTest, ValueOfErrorAborts) {
  Expected<int> bad = ParsePositive(-2);
  EXPECT_DEATH((void)bad.value(), "must be > 0");
}

TEST(StatusDeathTest, CheckAbortsWithMessage) {
  EXPECT_DEATH(ST_CHECK(1 + 1 == 3) << "arithmetic is broken", "arithmetic is broken");
}

}  // namespace
}  // namespace sandtable
