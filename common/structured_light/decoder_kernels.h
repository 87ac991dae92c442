// Row kernels of the structured-light decoder (internal to common/structured_light).
// Each loops over n contiguous pixels without data-dependent branches so that the compiler
// vectorises it; decoder.cc calls them row by row inside row bands.
#pragma once

#include <cstdint>

namespace sandtable::structured_light_internal {

// One Gray bit pair: code = (code << 1) | (a > b); min_contrast = min(min_contrast, |a - b|);
// weak_bits += |a - b| < contrast_threshold; saturated |= min(a, b) > saturation_minus_one
// (pass 255 to disable); where |a - b| < weakest_contrast, weakest_contrast = |a - b| and
// weakest_bit = bit_index (the bit's position in the final code, 0 = least significant).
void AccumulateGrayBit(const uint8_t* a, const uint8_t* b, int n, uint8_t contrast_threshold,
                       uint8_t saturation_minus_one, uint8_t bit_index, uint16_t* code,
                       uint8_t* min_contrast, uint8_t* weak_bits, uint8_t* saturated,
                       uint8_t* weakest_contrast, uint8_t* weakest_bit);

// Sub-pixel Gray position: the weakest bit of a pixel is the one whose stripe edge lies
// nearest. If flipping it names the adjacent cell, the pixel is moved from its cell centre
// toward that edge by cell * 0.5 * (1 - weakest_contrast / (white - black)), clamped to [0, 0.5]
// cell: half a cell when the bit is fully ambiguous, none when it has full contrast. Linear
// in the fraction of the projector pixel that covers the camera pixel; independent of gamma
// (each projector pixel is fully on or off) and of albedo and ambient (ratio of differences).
void RefineGrayEdge(const uint16_t* code, const uint8_t* weakest_contrast,
                    const uint8_t* weakest_bit, const uint8_t* white, const uint8_t* black, int n,
                    int skip, float* position);

// One phase sample with shift d: s += I sin d, c += I cos d; saturated |= I > sat_minus_one.
void AccumulatePhaseSample(const uint8_t* image, int n, float sin_shift, float cos_shift,
                           uint8_t saturation_minus_one, float* s, float* c, uint8_t* saturated);

// Gray code -> binary, shifted left by `skip` and moved to the centre of its cell:
// position = (binary << skip) + (2^skip - 1) / 2, as float. flags |= kDecodeOutOfRange where
// binary << skip >= size.
void GrayToPosition(const uint16_t* code, int n, int skip, int size, float* position,
                    uint8_t* flags);

// Unwraps the phase (s, c) of period `period_px` to the period nearest `position` (the Gray
// position, overwritten with the result). Sets kDecodeLowModulation where the peak-to-peak
// modulation 4/N |(s, c)| < min_modulation, kDecodePhaseGrayDisagree where the result is more
// than max_distance_px from the Gray position. modulation receives the peak-to-peak value.
void UnwrapPhase(const float* s, const float* c, int n, float period_px, float modulation_scale,
                 float min_modulation, float max_distance_px, float* position, float* modulation,
                 uint8_t* flags);

// Combines one row: shadow (white - black <= shadow_threshold), low contrast (more than
// max_weak_bits weak bits on either axis), saturation and the per-axis flags in `axis_flags`
// into `flags`.
// Writes (u, v) interleaved (NaN where rejected), valid (255/0) and confidence (0 where
// rejected; else min(modulation_u, modulation_v) with phase, min_contrast without). Pass position
// rows filled with NaN and modulation rows with +inf for an axis that was not encoded or has no
// phase.
void FinishRow(const uint8_t* white, const uint8_t* black, const uint8_t* min_contrast,
               const uint8_t* weak_bits_u, const uint8_t* weak_bits_v, const uint8_t* saturated,
               const float* position_u, const float* position_v, const float* modulation_u,
               const float* modulation_v, int n, int shadow_threshold, int max_weak_bits,
               const uint8_t* axis_flags, uint8_t* flags, float* uv, uint8_t* valid,
               float* confidence);

// Adds to counts[b] the number of pixels of the row with flag bit b set (b = 0..7), and to
// counts[8] the number with no flag.
void CountFlags(const uint8_t* flags, int n, int64_t* counts);

// Branch-free atan2 (max error about 1e-5 rad; see decoder_kernels.cc). Exposed for tests.
float FastAtan2(float y, float x);

}  // namespace sandtable::structured_light_internal
