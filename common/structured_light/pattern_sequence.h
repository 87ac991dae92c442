// Structured-light pattern sequences: Gray code (columns and rows, each bit followed by its
// inverse), N-step phase shifting (period P projector px) for columns and rows, and the white
// and black frames; generated at any projector resolution.
//
// Projector pixel convention (OpenCV, docs/frames.md): pixel (u, v) is centred at (u, v).
//   Gray code:   g(u) = u XOR (u >> 1) over B_u = ceil(log2(width)) bits (B_v for rows). The
//                pattern of bit b (b = B-1 is the most significant) is `high_level` at
//                projector pixel (u, v) when bit b of g(u) is 1, else `low_level`; its inverse
//                swaps the two. `gray_lsb_skip` least significant bits are not projected: the
//                code then names a cell of 2^skip pixels.
//   Phase shift: frame n = 0..N-1 of an axis shows
//                  low + (high - low) * (0.5 + 0.5 cos(2 pi u / P - 2 pi n / N)),
//                rounded to 8 bits, so the phase at pixel centre u is 2 pi u / P (mod 2 pi).
//
// Frame order (FrameOrder):
//   kSandtable:        white, black, then for columns each Gray bit MSB first followed by its
//                      inverse, then the same for rows, then the N column phase frames (n = 0..
//                      N-1), then the N row phase frames.
//   kOpenCvGrayCode:   the order of cv::structured_light::GrayCodePattern and of the
//                      procam-kamino410 captures: column bits MSB first each followed by its
//                      inverse, row bits likewise, then white, then black; phase frames (if
//                      any) after those, columns then rows.
// PatternLayout gives the index of every frame, so a decoder never hard-codes an order.
#pragma once

#include <vector>

#include <opencv2/core.hpp>

#include "common/base/status.h"

namespace sandtable {

enum class FrameOrder { kSandtable, kOpenCvGrayCode };

struct PatternOptions {
  int projector_width_px = 1024;
  int projector_height_px = 768;
  bool encode_columns = true;  // u (x) coordinate
  bool encode_rows = true;     // v (y) coordinate
  // Least significant Gray bits left out (0 = full resolution). With phase shifting the
  // finest stripes are the first to blur away, and the phase does not need them.
  int gray_lsb_skip = 0;
  // Phase shifting: 0 disables it; otherwise at least 3 steps. 8 steps cancel the harmonics
  // that projector gamma adds up to the 6th (an N-step sum aliases harmonics N +- 1 only).
  int phase_steps = 8;
  // Period of the sinusoid in projector px; > 2 * the Gray cell + 2 * the decoder's
  // disagreement margin (checked by DecoderOptions::Check against these options).
  double phase_period_px = 16.0;
  int low_level = 0;     // 8-bit level of "off"
  int high_level = 255;  // 8-bit level of "on"
  FrameOrder order = FrameOrder::kSandtable;

  // INVALID_ARGUMENT naming the field: sizes < 2 or > 65536, no axis encoded, skip out of
  // [0, bits), phase_steps 1 or 2 or > 64, period < 3 px, levels out of [0, 255] or low >= high.
  Status Check() const;

  // The dataset layout: OpenCV GrayCodePattern order, full-resolution Gray code, no phase.
  // (A default-constructed PatternOptions has phase, in Sandtable order.)
  static PatternOptions OpenCvGrayCode(int width_px, int height_px);
};

// Number of Gray bits for a coordinate range [0, size): ceil(log2(size)) (0 for size 1).
int GrayBitsFor(int size);

inline uint32_t GrayFromBinary(uint32_t binary) { return binary ^ (binary >> 1); }
inline uint32_t BinaryFromGray(uint32_t gray) {
  gray ^= gray >> 16;
  gray ^= gray >> 8;
  gray ^= gray >> 4;
  gray ^= gray >> 2;
  gray ^= gray >> 1;
  return gray;
}

// Where each frame sits in a sequence. Index -1 means "not in this sequence".
struct PatternLayout {
  struct Axis {
    bool encoded = false;
    int total_bits = 0;      // ceil(log2(size))
    int projected_bits = 0;  // total_bits - gray_lsb_skip
    // For k = 0..projected_bits-1 (MSB first): the frame of bit total_bits-1-k and its inverse.
    std::vector<int> gray_frame;
    std::vector<int> gray_inverse_frame;
    std::vector<int> phase_frame;  // N frames, shift 2 pi n / N
  };
  Axis columns;
  Axis rows;
  int white_frame = -1;
  int black_frame = -1;
  int frame_count = 0;
};

// Layout for the options (which must pass Check(); ST_CHECKs it).
PatternLayout MakePatternLayout(const PatternOptions& options);

// All frames in layout order, CV_8UC1 of projector_height_px x projector_width_px.
// Errors: options.Check().
Expected<std::vector<cv::Mat>> GeneratePatterns(const PatternOptions& options);

}  // namespace sandtable
