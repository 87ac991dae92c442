// NoiseRng: the ziggurat normals and the small-mean Poisson draws have the right statistics,
// and a seed gives the same sequence.
#include "sim/transport/noise_rng.h"

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

namespace sandtable::sim {
namespace {

constexpr int kSamples = 2000000;

TEST(NoiseRng, NormalMomentsAndTails) {
  NoiseRng rng(42);
  double sum = 0, sum2 = 0, sum3 = 0, sum4 = 0;
  int beyond_2 = 0, beyond_3 = 0, beyond_r = 0;
  for (int i = 0; i < kSamples; ++i) {
    const double z = rng.Normal();
    sum += z;
    sum2 += z * z;
    sum3 += z * z * z;
    sum4 += z * z * z * z;
    beyond_2 += std::abs(z) > 2.0;
    beyond_3 += std::abs(z) > 3.0;
    beyond_r += std::abs(z) > 3.5;  // past the ziggurat's tail start r = 3.4426
  }
  const double n = kSamples;
  // Tolerances: 5 standard errors of each estimator for n = 2e6 standard normals
  // (mean 1/sqrt(n), variance sqrt(2/n), skewness sqrt(6/n), kurtosis sqrt(24/n)).
  EXPECT_NEAR(sum / n, 0.0, 5 * std::sqrt(1 / n));
  EXPECT_NEAR(sum2 / n, 1.0, 5 * std::sqrt(2 / n));
  EXPECT_NEAR(sum3 / n, 0.0, 5 * std::sqrt(6 / n));
  EXPECT_NEAR(sum4 / n, 3.0, 5 * std::sqrt(24 / n));
  // Tail probabilities P(|Z| > t): 0.0455003, 0.0026998, 0.00046525; binomial standard errors.
  auto expect_fraction = [&](int count, double p) {
    EXPECT_NEAR(count / n, p, 5 * std::sqrt(p * (1 - p) / n)) << "P = " << p;
  };
  expect_fraction(beyond_2, 0.0455003);
  expect_fraction(beyond_3, 0.0026998);
  expect_fraction(beyond_r, 0.00046525);
}

TEST(NoiseRng, SmallPoissonMeanAndVariance) {
  for (double mean : {0.05, 0.7, 3.0, 12.5, 31.9, 100.0}) {
    NoiseRng rng(7);
    constexpr int kDraws = 400000;
    double sum = 0, sum2 = 0;
    int zeros = 0;
    for (int i = 0; i < kDraws; ++i) {
      const double k = rng.SmallPoisson(mean);
      sum += k;
      sum2 += k * k;
      zeros += k == 0;
    }
    const double m = sum / kDraws;
    const double var = sum2 / kDraws - m * m;
    // 5 standard errors: of the mean sqrt(mean / n); of the variance ~ sqrt((2 mean^2 +
    // mean) / n) for a Poisson.
    EXPECT_NEAR(m, mean, 5 * std::sqrt(mean / kDraws)) << "mean " << mean;
    EXPECT_NEAR(var, mean, 5 * std::sqrt((2 * mean * mean + mean) / kDraws)) << "mean " << mean;
    const double p0 = std::exp(-mean);
    EXPECT_NEAR(zeros / static_cast<double>(kDraws), p0,
                5 * std::sqrt(p0 * (1 - p0) / kDraws) + 1e-9)
        << "P(0) for mean " << mean;
  }
  NoiseRng rng(1);
  EXPECT_EQ(rng.SmallPoisson(0.0), 0);
  EXPECT_EQ(rng.SmallPoisson(-1.0), 0);
}

TEST(NoiseRng, DeterministicForASeed) {
  NoiseRng a(5), b(5), c(6);
  int differ = 0;
  for (int i = 0; i < 1000; ++i) {
    const float x = a.Normal();
    EXPECT_EQ(x, b.Normal());
    differ += x != c.Normal();
  }
  EXPECT_GT(differ, 990);
}

}  // namespace
}  // namespace sandtable::sim
