#include "sim/transport/noise_rng.h"

#include <algorithm>
#include <cmath>

namespace sandtable::sim {

namespace {
// Ziggurat constants for the normal density f(x) = exp(-x^2 / 2) with 128 layers
// (Marsaglia & Tsang 2000): r is the start of the tail, v the common area of every layer.
constexpr double kR = 3.442619855899;
constexpr double kV = 9.91256303526217e-3;
constexpr double kM1 = 2147483648.0;  // 2^31: hz is a signed 32-bit integer
}  // namespace

// Layer i spans [x_i, x_{i-1}] with x_127 = r down to x_1 (x_0 = v / f(r) for the base layer,
// which includes the tail). A point hz * w[i] is accepted at once when |hz| < k[i], i.e. when
// it lies below x_{i+1}, inside the rectangle that is entirely under the curve.
NoiseRng::Tables::Tables() {
  double dn = kR, tn = kR;
  const double q = kV / std::exp(-0.5 * dn * dn);
  k[0] = static_cast<uint32_t>((dn / q) * kM1);
  k[1] = 0;
  w[0] = static_cast<float>(q / kM1);
  w[127] = static_cast<float>(dn / kM1);
  f[0] = 1.0f;
  f[127] = static_cast<float>(std::exp(-0.5 * dn * dn));
  for (int i = 126; i >= 1; --i) {
    dn = std::sqrt(-2.0 * std::log(kV / dn + std::exp(-0.5 * dn * dn)));
    k[i + 1] = static_cast<uint32_t>((dn / tn) * kM1);
    tn = dn;
    f[i] = static_cast<float>(std::exp(-0.5 * dn * dn));
    w[i] = static_cast<float>(dn / kM1);
  }
}

const NoiseRng::Tables NoiseRng::kTables;

NoiseRng::NoiseRng(uint64_t seed) {
  for (uint64_t& s : s_) {
    seed += 0x9E3779B97F4A7C15ull;  // splitmix64
    uint64_t z = seed;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    s = z ^ (z >> 31);
  }
}

float NoiseRng::NormalSlow(int32_t hz, uint32_t iz) {
  for (;;) {
    const double x = static_cast<double>(hz) * kTables.w[iz];
    if (iz == 0) {
      // The tail beyond r: Marsaglia's method, x = -ln(U1) / r accepted when
      // -2 ln(U2) > x^2.
      double tx, ty;
      do {
        tx = -std::log(1.0 - Uniform()) / kR;
        ty = -std::log(1.0 - Uniform());
      } while (ty + ty < tx * tx);
      return static_cast<float>(hz > 0 ? kR + tx : -kR - tx);
    }
    // The wedge between the rectangle and the curve: accept under the density.
    if (kTables.f[iz] + Uniform() * (kTables.f[iz - 1] - kTables.f[iz]) < std::exp(-0.5 * x * x)) {
      return static_cast<float>(x);
    }
    const uint64_t u = Next();
    hz = static_cast<int32_t>(u >> 32);
    iz = static_cast<uint32_t>(u) & 127u;
    const uint32_t abs_hz = hz < 0 ? 0u - static_cast<uint32_t>(hz) : static_cast<uint32_t>(hz);
    if (abs_hz < kTables.k[iz]) return static_cast<float>(hz) * kTables.w[iz];
  }
}

int NoiseRng::SmallPoisson(double mean) {
  if (!(mean > 0.0)) return 0;
  mean = std::min(mean, kMaxSmallPoissonMean);
  // Inversion over the support ordered outward from the mode: mode, mode - 1, mode + 1,
  // mode - 2, ... Inversion is exact for any fixed order of the support; walking from the
  // mode takes about 1.6 sqrt(mean) steps instead of about mean from 0, and one draw.
  //   P(mode) = exp(mode ln(mean) - mean - ln(mode!)),
  //   P(k - 1) = P(k) k / mean,   P(k + 1) = P(k) mean / (k + 1).
  const int mode = static_cast<int>(mean);
  // Neighbouring pixels often share a mean (ambient light on one material): reuse P(mode).
  if (mean != cached_mean_) {
    cached_mean_ = mean;
    cached_p_mode_ = std::exp(mode * std::log(mean) - mean - kPoissonTables.log_factorial[mode]);
  }
  const double p_mode = cached_p_mode_;
  double u = Uniform() - p_mode;
  if (u < 0.0) return mode;
  const double inverse_mean = 1.0 / mean;
  double p_down = p_mode, p_up = p_mode;
  int down = mode, up = mode;
  while (up + 1 < PoissonTables::kSize) {
    if (down > 0) {
      p_down *= down * inverse_mean;
      --down;
      u -= p_down;
      if (u < 0.0) return down;
    }
    ++up;
    p_up *= mean * kPoissonTables.inverse[up];
    u -= p_up;
    if (u < 0.0) return up;
  }
  return up;  // rounding left u just above the summed probabilities (never in practice)
}

NoiseRng::PoissonTables::PoissonTables() {
  log_factorial[0] = 0.0;
  inverse[0] = 0.0;
  for (int k = 1; k < kSize; ++k) {
    log_factorial[k] = log_factorial[k - 1] + std::log(static_cast<double>(k));
    inverse[k] = 1.0 / k;
  }
}

const NoiseRng::PoissonTables NoiseRng::kPoissonTables;

}  // namespace sandtable::sim
