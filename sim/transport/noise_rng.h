// NoiseRng: the fast, portable random source of capture synthesis.
//
// Uniforms from xoshiro256** (Blackman & Vigna) seeded through splitmix64; standard normals
// by the ziggurat method of Marsaglia & Tsang (2000, J. Stat. Softw. 5(8)) with 128 layers,
// tables computed once at start-up. The layer index and the value come from disjoint bits of
// one 64-bit draw (Doornik 2005 showed that sharing them, as the original does, correlates
// the two). About 99 % of normals take the fast path: one draw, one compare, one multiply.
// The distribution is exact (tail by Marsaglia's exponential rejection), not an approximation.
// Deterministic for a seed on every platform (integer arithmetic + IEEE float).
#pragma once

#include <cstdint>

namespace sandtable::sim {

class NoiseRng {
 public:
  explicit NoiseRng(uint64_t seed);

  uint64_t Next() {
    const uint64_t result = Rotl(s_[1] * 5, 7) * 9;
    const uint64_t t = s_[1] << 17;
    s_[2] ^= s_[0];
    s_[3] ^= s_[1];
    s_[1] ^= s_[2];
    s_[0] ^= s_[3];
    s_[2] ^= t;
    s_[3] = Rotl(s_[3], 45);
    return result;
  }
  // Uniform in [0, 1) with 53 random bits.
  double Uniform() { return static_cast<double>(Next() >> 11) * 0x1.0p-53; }

  // A standard normal N(0, 1).
  float Normal() {
    const uint64_t u = Next();
    const int32_t hz = static_cast<int32_t>(u >> 32);
    const uint32_t iz = static_cast<uint32_t>(u) & 127u;
    // |hz| < k[iz] <=> the point lies inside the layer's rectangle under the curve.
    const uint32_t abs_hz = hz < 0 ? 0u - static_cast<uint32_t>(hz) : static_cast<uint32_t>(hz);
    if (abs_hz < kTables.k[iz]) return static_cast<float>(hz) * kTables.w[iz];
    return NormalSlow(hz, iz);
  }

  // Poisson by inversion (one draw, ~1.6 sqrt(mean) steps from the mode); exact for means up
  // to kMaxSmallPoissonMean (larger means are clamped to it: use the Gaussian limit there).
  static constexpr double kMaxSmallPoissonMean = 128.0;
  int SmallPoisson(double mean);

 private:
  struct Tables {
    Tables();
    uint32_t k[128];
    float w[128];
    float f[128];
  };
  static const Tables kTables;
  struct PoissonTables {
    static constexpr int kSize = 512;  // > kMaxSmallPoissonMean + 20 sqrt(kMaxSmallPoissonMean)
    PoissonTables();
    double log_factorial[kSize];
    double inverse[kSize];  // 1 / k
  };
  static const PoissonTables kPoissonTables;

  float NormalSlow(int32_t hz, uint32_t iz);
  static uint64_t Rotl(uint64_t x, int k) { return (x << k) | (x >> (64 - k)); }
  uint64_t s_[4];
  double cached_mean_ = -1.0;  // SmallPoisson's last mean and its P(mode)
  double cached_p_mode_ = 0.0;
};

}  // namespace sandtable::sim
