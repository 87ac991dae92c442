#include "common/structured_light/decoder_kernels.h"

#include <algorithm>
#include <bit>
#include <cmath>
#include <limits>
#include <numbers>

#include "common/structured_light/decoder.h"

// Built with -O3 -fno-math-errno -fno-trapping-math (see CMakeLists.txt) so that GCC vectorises
// these loops at any build type. Every loop body is straight-line code: comparisons become masks,
// ternaries become blends. target_clones builds an AVX2 variant next to the baseline one and picks
// it at load time.
#if defined(__GNUC__) && defined(__x86_64__) && !defined(__clang__)
#define ST_VECTOR_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define ST_VECTOR_CLONES
#endif

namespace sandtable::structured_light_internal {

ST_VECTOR_CLONES
void AccumulateGrayBit(const uint8_t* __restrict a, const uint8_t* __restrict b, int n,
                       uint8_t contrast_threshold, uint8_t saturation_minus_one, uint8_t bit_index,
                       uint16_t* __restrict code, uint8_t* __restrict min_contrast,
                       uint8_t* __restrict weak_bits, uint8_t* __restrict saturated,
                       uint8_t* __restrict weakest_contrast, uint8_t* __restrict weakest_bit) {
  for (int x = 0; x < n; ++x) {
    const uint8_t hi = std::max(a[x], b[x]);
    const uint8_t lo = std::min(a[x], b[x]);
    code[x] = static_cast<uint16_t>((code[x] << 1) | static_cast<uint16_t>(a[x] > b[x]));
    const uint8_t contrast = static_cast<uint8_t>(hi - lo);
    min_contrast[x] = std::min(min_contrast[x], contrast);
    weak_bits[x] = static_cast<uint8_t>(weak_bits[x] + (contrast < contrast_threshold ? 1 : 0));
    saturated[x] |= static_cast<uint8_t>(lo > saturation_minus_one);
    const bool weaker = contrast < weakest_contrast[x];
    weakest_contrast[x] = weaker ? contrast : weakest_contrast[x];
    weakest_bit[x] = weaker ? bit_index : weakest_bit[x];
  }
}

ST_VECTOR_CLONES
void RefineGrayEdge(const uint16_t* __restrict code, const uint8_t* __restrict weakest_contrast,
                    const uint8_t* __restrict weakest_bit, const uint8_t* __restrict white,
                    const uint8_t* __restrict black, int n, int skip, float* __restrict position) {
  const float cell_px = static_cast<float>(1 << skip);
  for (int x = 0; x < n; ++x) {
    const uint32_t gray = code[x];
    const uint32_t flipped = gray ^ (1u << weakest_bit[x]);
    uint32_t b = gray;
    uint32_t bf = flipped;
    b ^= b >> 1;
    b ^= b >> 2;
    b ^= b >> 4;
    b ^= b >> 8;
    bf ^= bf >> 1;
    bf ^= bf >> 2;
    bf ^= bf >> 4;
    bf ^= bf >> 8;
    const float delta = static_cast<float>(static_cast<int>(bf) - static_cast<int>(b));
    const float adjacent = std::fabs(delta) == 1.0f ? 1.0f : 0.0f;
    const float range = std::max(static_cast<float>(white[x]) - static_cast<float>(black[x]), 1.0f);
    const float ratio = std::min(static_cast<float>(weakest_contrast[x]) / range, 1.0f);
    position[x] += adjacent * delta * 0.5f * (1.0f - ratio) * cell_px;
  }
}

ST_VECTOR_CLONES
void AccumulatePhaseSample(const uint8_t* __restrict image, int n, float sin_shift, float cos_shift,
                           uint8_t saturation_minus_one, float* __restrict s, float* __restrict c,
                           uint8_t* __restrict saturated) {
  for (int x = 0; x < n; ++x) {
    const float value = static_cast<float>(image[x]);
    s[x] += value * sin_shift;
    c[x] += value * cos_shift;
    saturated[x] |= static_cast<uint8_t>(image[x] > saturation_minus_one);
  }
}

ST_VECTOR_CLONES
void GrayToPosition(const uint16_t* __restrict code, int n, int skip, int size,
                    float* __restrict position, uint8_t* __restrict flags) {
  const float centre = 0.5f * static_cast<float>((1 << skip) - 1);
  for (int x = 0; x < n; ++x) {
    // Prefix XOR from the top bit down turns a Gray code into binary (16-bit codes).
    uint16_t binary = code[x];
    binary ^= static_cast<uint16_t>(binary >> 1);
    binary ^= static_cast<uint16_t>(binary >> 2);
    binary ^= static_cast<uint16_t>(binary >> 4);
    binary ^= static_cast<uint16_t>(binary >> 8);
    const int first = static_cast<int>(binary) << skip;
    flags[x] |= static_cast<uint8_t>(first >= size ? kDecodeOutOfRange : 0);
    position[x] = static_cast<float>(first) + centre;
  }
}

// atan on [0, 1] by the odd minimax polynomial a (c0 + c1 a^2 + ... + c5 a^10); the published
// coefficients below keep the error under about 1e-5 rad (checked in decoder_kernels_test).
// Octant reduction with selects instead of branches.
inline float FastAtan2Inline(float y, float x) {
  const float ax = std::fabs(x);
  const float ay = std::fabs(y);
  const float hi = std::max(ax, ay);
  const float lo = std::min(ax, ay);
  const float a = lo / std::max(hi, 1e-30f);
  const float s = a * a;
  float r = -0.01172120f;
  r = r * s + 0.05265332f;
  r = r * s - 0.11643287f;
  r = r * s + 0.19354346f;
  r = r * s - 0.33262347f;
  r = r * s + 0.99997726f;
  r *= a;
  r = ay > ax ? std::numbers::pi_v<float> * 0.5f - r : r;
  r = x < 0.0f ? std::numbers::pi_v<float> - r : r;
  return y < 0.0f ? -r : r;
}

float FastAtan2(float y, float x) { return FastAtan2Inline(y, x); }

ST_VECTOR_CLONES
void UnwrapPhase(const float* __restrict s, const float* __restrict c, int n, float period_px,
                 float modulation_scale, float min_modulation, float max_distance_px,
                 float* __restrict position, float* __restrict modulation,
                 uint8_t* __restrict flags) {
  const float px_per_rad = period_px / (2.0f * std::numbers::pi_v<float>);
  const float inverse_period = 1.0f / period_px;
  for (int x = 0; x < n; ++x) {
    // frac in (-P/2, P/2]: position modulo one period.
    const float frac = FastAtan2Inline(s[x], c[x]) * px_per_rad;
    const float gray = position[x];
    // Nearest period: k = round((gray - frac) / P). gray >= 0 and frac > -P/2 make the
    // argument > -1/2, so truncating (t + 1.5) and subtracting 1 rounds without floor().
    const float t = (gray - frac) * inverse_period;
    const float k = static_cast<float>(static_cast<int>(t + 1.5f) - 1);
    const float unwrapped = frac + k * period_px;
    const float mod = modulation_scale * std::sqrt(s[x] * s[x] + c[x] * c[x]);
    modulation[x] = mod;
    const uint8_t low = mod < min_modulation ? kDecodeLowModulation : 0;
    const uint8_t far =
        std::fabs(unwrapped - gray) > max_distance_px ? kDecodePhaseGrayDisagree : 0;
    flags[x] |= static_cast<uint8_t>(low | far);
    position[x] = unwrapped;
  }
}

ST_VECTOR_CLONES
void FinishRow(const uint8_t* __restrict white, const uint8_t* __restrict black,
               const uint8_t* __restrict min_contrast, const uint8_t* __restrict weak_bits_u,
               const uint8_t* __restrict weak_bits_v, const uint8_t* __restrict saturated,
               const float* __restrict position_u, const float* __restrict position_v,
               const float* __restrict modulation_u, const float* __restrict modulation_v, int n,
               int shadow_threshold, int max_weak_bits, const uint8_t* __restrict axis_flags,
               uint8_t* __restrict flags, float* __restrict uv, uint8_t* __restrict valid,
               float* __restrict confidence) {
  // Two loops, because GCC 12 does not vectorise a select between floats on a mask computed
  // from bytes: the float pass blends by bit masks instead.
  for (int x = 0; x < n; ++x) {
    const int lit_range = static_cast<int>(white[x]) - static_cast<int>(black[x]);
    const int weak = std::max(weak_bits_u[x], weak_bits_v[x]);
    const uint8_t f =
        static_cast<uint8_t>(axis_flags[x] | (lit_range <= shadow_threshold ? kDecodeShadow : 0) |
                             (weak > max_weak_bits ? kDecodeLowContrast : 0) |
                             (saturated[x] != 0 ? kDecodeSaturated : 0));
    flags[x] = f;
    valid[x] = f == 0 ? 255 : 0;
  }
  const uint32_t nan_bits = std::bit_cast<uint32_t>(std::numeric_limits<float>::quiet_NaN());
  const float infinity = std::numeric_limits<float>::infinity();
  for (int x = 0; x < n; ++x) {
    const uint32_t keep = 0u - static_cast<uint32_t>(flags[x] == 0);
    const uint32_t u = std::bit_cast<uint32_t>(position_u[x]);
    const uint32_t v = std::bit_cast<uint32_t>(position_v[x]);
    const float modulation = std::min(modulation_u[x], modulation_v[x]);
    const float contrast = static_cast<float>(min_contrast[x]);
    const float signal = modulation < infinity ? modulation : contrast;
    uv[2 * x] = std::bit_cast<float>((u & keep) | (nan_bits & ~keep));
    uv[2 * x + 1] = std::bit_cast<float>((v & keep) | (nan_bits & ~keep));
    confidence[x] = std::bit_cast<float>(std::bit_cast<uint32_t>(signal) & keep);
  }
}

void CountFlags(const uint8_t* __restrict flags, int n, int64_t* counts) {
  int bit_counts[9] = {};
  for (int b = 0; b < 8; ++b) {
    int sum = 0;
    for (int x = 0; x < n; ++x) sum += (flags[x] >> b) & 1;
    bit_counts[b] = sum;
  }
  int clean = 0;
  for (int x = 0; x < n; ++x) clean += flags[x] == 0 ? 1 : 0;
  bit_counts[8] = clean;
  for (int b = 0; b < 9; ++b) counts[b] += bit_counts[b];
}

}  // namespace sandtable::structured_light_internal
