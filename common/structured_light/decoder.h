// Structured-light decoder: camera captures of a PatternSequence -> a dense map from camera
// pixel to projector (u, v) in float px, a validity mask, a per-pixel confidence and the reason
// of every rejection.
//
// Algorithm (per camera pixel; see docs/structured-light.md for the derivation):
//   1. Shadow:        white - black <= shadow_threshold                 -> kShadow.
//   2. Gray bits:     bit = I > I_inverse (a per-pixel threshold that cancels ambient light,
//                     albedo and projector gamma). A bit with |I - I_inverse| < min_contrast
//                     is weak; more than max_weak_bits_per_axis weak bits on an axis ->
//                     kLowContrast. One weak bit is harmless by default: neighbouring Gray
//                     codes differ in exactly one bit, so a camera pixel centred on a stripe
//                     edge has one ambiguous bit and either value of it names one of the two
//                     pixels at that edge. OpenCV's rule is max 0. Both I and I_inverse >=
//                     saturation_level
//                     on a bit -> kSaturated. Gray -> binary; a code >= the projector size ->
//                     kOutOfRange. Gray-only position: the centre of the decoded cell (the
//                     pixel itself at full resolution), moved toward the nearest stripe edge
//                     when gray_subpixel: the bit with the least contrast belongs to the edge
//                     nearest the camera pixel, and its contrast relative to white - black
//                     says how far (0: on the edge, 1: a full cell's contrast, at the centre).
//   3. Phase (when phase_steps > 0): phi = atan2(sum I_n sin d_n, sum I_n cos d_n),
//                     d_n = 2 pi n / N; peak-to-peak modulation 4/N |(S, C)|; below
//                     min_phase_modulation -> kLowModulation; any sample >= saturation_level ->
//                     kSaturated. Unwrapped to the period that puts it nearest the Gray
//                     position; if it still lies more than (Gray cell / 2 +
//                     max_phase_gray_disagreement_px) from it, the two disagree ->
//                     kPhaseGrayDisagree. DecoderOptions::CheckAgainst requires that window
//                     to be inside half a period, so every pixel where phase and Gray code
//                     disagree by more than half a period is rejected (and stricter ones too).
// Robustness: ambient light and albedo cancel in I - I_inverse and in (S, C); gamma keeps the
// order of I and I_inverse; defocus lowers contrast (masked) and is symmetric about stripe
// edges; noise is bounded by the thresholds.
//
// Speed: row bands across threads; within a row, every frame is read once with branch-free
// loops over contiguous uint8 (the compiler vectorises them), codes bit-packed as they arrive.
// Memory traffic: one read of each capture plus 14 bytes written per camera pixel.
//
// Errors (never aborts on captures): INVALID_ARGUMENT when the count differs from the
// layout's, a capture is empty, not CV_8UC1, or of another size; or the options fail Check().
// Thread safety: pure function; it starts and joins its own threads.
#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "common/base/status.h"
#include "common/structured_light/pattern_sequence.h"

namespace sandtable {

// Reasons a camera pixel is not decoded (bitwise OR in Decoding::flags; 0 = decoded).
enum DecodeFlag : uint8_t {
  kDecodeShadow = 1,              // white - black <= shadow_threshold
  kDecodeLowContrast = 2,         // too many weak Gray bits (|I - I_inverse| < min_contrast)
  kDecodeSaturated = 4,           // a Gray pair or a phase sample at or above saturation_level
  kDecodeOutOfRange = 8,          // decoded code >= projector width or height
  kDecodeLowModulation = 16,      // phase modulation below min_phase_modulation
  kDecodePhaseGrayDisagree = 32,  // unwrapped phase too far from the Gray code position
};

struct DecoderOptions {
  // Gray levels (0..255). Lit when white - black > shadow_threshold (OpenCV's black_thr).
  int shadow_threshold = 10;
  // A Gray bit with |I - I_inverse| < min_contrast is weak (OpenCV's white_thr).
  int min_contrast = 6;
  // Weak bits tolerated per axis (0 = OpenCV's rule: every bit strong). See the top.
  int max_weak_bits_per_axis = 1;
  // A Gray pair with both values >= this, or a phase sample >= this, is saturated.
  // 256 disables the test.
  int saturation_level = 255;
  // Gray code sub-pixel position from the weakest bit's contrast (decoder_kernels.h,
  // RefineGrayEdge); false gives the integer pixel (centre of the decoded cell), as OpenCV.
  bool gray_subpixel = true;
  // Phase: minimum peak-to-peak modulation, gray levels.
  double min_phase_modulation = 6.0;
  // Phase: allowed distance beyond half a Gray cell between unwrapped phase and Gray position.
  double max_phase_gray_disagreement_px = 1.0;
  // Worker threads; 0 = std::thread::hardware_concurrency().
  int num_threads = 0;

  Status Check() const;
  // Check() plus: with phase shifting, (cell / 2 + max_phase_gray_disagreement_px) < P / 2,
  // where cell = 2^gray_lsb_skip px; otherwise the unwrapping would be ambiguous.
  Status CheckAgainst(const PatternOptions& patterns) const;

  // Thresholds with OpenCV GrayCodePattern's meaning (black_thr, white_thr): no weak bit
  // tolerated, saturation off, integer positions; gives OpenCV's decode exactly.
  static DecoderOptions OpenCvThresholds(int black_threshold, int white_threshold);
};

struct Decoding {
  // CV_32FC2, camera size. At camera pixel (x, y): projector (u, v) in px (pixel centres at
  // integers). NaN where not valid, and in the coordinate of an axis that was not encoded.
  cv::Mat projector_px;
  cv::Mat valid;  // CV_8UC1, 255 where decoded, 0 elsewhere
  // CV_32FC1, gray levels, 0 where not valid: with phase, the smaller peak-to-peak phase
  // modulation of the two axes; Gray only, the smallest |I - I_inverse| over all bits (near 0
  // on stripe edges, where the pixel could be either neighbour).
  cv::Mat confidence;
  cv::Mat flags;  // CV_8UC1, DecodeFlag bits (0 where decoded)
};

struct DecodeReport {
  int64_t camera_pixels = 0;
  int64_t decoded_pixels = 0;
  // Pixels carrying each flag (a pixel may carry several).
  int64_t shadow_pixels = 0;
  int64_t low_contrast_pixels = 0;
  int64_t saturated_pixels = 0;
  int64_t out_of_range_pixels = 0;
  int64_t low_modulation_pixels = 0;
  int64_t disagreement_pixels = 0;
  int threads_used = 0;
  double decode_time_ms = 0.0;  // wall time of the decode proper (validation excluded)
  double DecodedFraction() const {
    return camera_pixels > 0 ? static_cast<double>(decoded_pixels) / camera_pixels : 0.0;
  }
  std::string ToString() const;
};

// Decodes `captures` (in the layout of `patterns`). `report` may be null.
Expected<Decoding> DecodeStructuredLight(const std::vector<cv::Mat>& captures,
                                         const PatternOptions& patterns,
                                         const DecoderOptions& options,
                                         DecodeReport* report = nullptr);

// The same into `out`, reusing its buffers when they already have the camera size (a node
// decoding sequence after sequence avoids 14 bytes/px of fresh allocation and page faults).
// `out` must not be null (ST_CHECK); on error its contents are unspecified.
Status DecodeStructuredLightInto(const std::vector<cv::Mat>& captures,
                                 const PatternOptions& patterns, const DecoderOptions& options,
                                 Decoding* out, DecodeReport* report = nullptr);

}  // namespace sandtable
