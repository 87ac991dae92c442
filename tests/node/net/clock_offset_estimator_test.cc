#include "node/net/clock_offset_estimator.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

namespace sandtable::node {
namespace {

constexpr double kNsPerS = 1e9;
constexpr double kTolerance_s = 1e-9;  // integer ns arithmetic, halving rounds by <= 1 ns

TEST(ClockOffsetEstimatorTest, SymmetricDelaysGiveTheExactOffset) {
  ClockOffsetEstimator estimator;
  const int64_t offset_ns = 2'500'000'000;  // server 2.5 s ahead
  const int64_t t0 = 1'000'000;
  const int64_t one_way_ns = 40'000;
  const int64_t t1 = t0 + offset_ns + one_way_ns;
  const int64_t t2 = t1 + 10'000;
  const int64_t t3 = t2 - offset_ns + one_way_ns;
  ASSERT_TRUE(estimator.AddSample(t0, t1, t2, t3));
  auto e = estimator.Estimate();
  ASSERT_TRUE(e.has_value());
  EXPECT_NEAR(e->offset_s, offset_ns / kNsPerS, kTolerance_s);
  EXPECT_NEAR(e->delay_s, 2 * one_way_ns / kNsPerS, kTolerance_s);
}

TEST(ClockOffsetEstimatorTest, PicksTheLeastDelayedSampleAndItsBoundHolds) {
  std::mt19937 rng(23);
  std::exponential_distribution<double> queueing_ns(1.0 / 200'000.0);  // mean 200 us
  const int64_t offset_ns = -7'000'000;
  ClockOffsetEstimator estimator(16);
  int64_t t0 = 0;
  for (int i = 0; i < 50; ++i) {
    t0 += 100'000'000;
    const int64_t out_ns = 20'000 + static_cast<int64_t>(queueing_ns(rng));
    const int64_t back_ns = 20'000 + static_cast<int64_t>(queueing_ns(rng));
    const int64_t t1 = t0 + offset_ns + out_ns;
    const int64_t t2 = t1 + 5'000;
    const int64_t t3 = t2 - offset_ns + back_ns;
    ASSERT_TRUE(estimator.AddSample(t0, t1, t2, t3));
  }
  auto e = estimator.Estimate();
  ASSERT_TRUE(e.has_value());
  EXPECT_EQ(e->samples, 16u);
  EXPECT_LE(std::abs(e->offset_s - offset_ns / kNsPerS), e->error_bound_s + kTolerance_s);
}

TEST(ClockOffsetEstimatorTest, RejectsImpossibleSamples) {
  ClockOffsetEstimator estimator;
  EXPECT_FALSE(estimator.AddSample(100, 50, 40, 200));   // server replied before receiving
  EXPECT_FALSE(estimator.AddSample(100, 150, 160, 90));  // received before sending
  EXPECT_FALSE(estimator.Estimate().has_value());
}

}  // namespace
}  // namespace sandtable::node
