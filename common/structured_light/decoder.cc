#include "common/structured_light/decoder.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <limits>
#include <numbers>
#include <sstream>
#include <thread>

#include "common/structured_light/decoder_kernels.h"

namespace sandtable {

namespace sli = structured_light_internal;

namespace {

constexpr int kMinRowsPerThread = 16;

// Per-thread row buffers, reused for every row of the band (they stay in L1/L2).
struct RowScratch {
  explicit RowScratch(int width)
      : code_u(width),
        code_v(width),
        min_contrast(width),
        weak_u(width),
        weak_v(width),
        saturated(width),
        flags(width),
        weakest_contrast(width),
        weakest_bit(width),
        position_u(width),
        position_v(width),
        modulation_u(width),
        modulation_v(width),
        s(width),
        c(width) {}
  std::vector<uint16_t> code_u, code_v;
  std::vector<uint8_t> min_contrast, weak_u, weak_v, saturated, flags;
  std::vector<uint8_t> weakest_contrast, weakest_bit;  // per axis, reset for each
  std::vector<float> position_u, position_v, modulation_u, modulation_v, s, c;
};

struct DecodeJob {
  const std::vector<cv::Mat>* captures;
  const PatternOptions* patterns;
  const DecoderOptions* options;
  const PatternLayout* layout;
  Decoding* out;
};

// Decodes one axis of row y into scratch.position_* / modulation_* (and flags).
void DecodeAxisRow(const DecodeJob& job, const PatternLayout::Axis& axis, int size, int y,
                   RowScratch& r, std::vector<uint16_t>& code, std::vector<uint8_t>& weak,
                   std::vector<float>& position, std::vector<float>& modulation) {
  const int width = job.out->valid.cols;
  const uint8_t saturation_minus_one =
      static_cast<uint8_t>(std::min(job.options->saturation_level, 256) - 1);
  std::fill(code.begin(), code.end(), uint16_t{0});
  std::fill(weak.begin(), weak.end(), uint8_t{0});
  std::fill(r.weakest_contrast.begin(), r.weakest_contrast.end(), uint8_t{255});
  std::fill(r.weakest_bit.begin(), r.weakest_bit.end(), uint8_t{0});
  const uint8_t contrast_threshold = static_cast<uint8_t>(job.options->min_contrast);
  for (int k = 0; k < axis.projected_bits; ++k) {
    sli::AccumulateGrayBit((*job.captures)[axis.gray_frame[k]].ptr<uint8_t>(y),
                           (*job.captures)[axis.gray_inverse_frame[k]].ptr<uint8_t>(y), width,
                           contrast_threshold, saturation_minus_one,
                           static_cast<uint8_t>(axis.projected_bits - 1 - k), code.data(),
                           r.min_contrast.data(), weak.data(), r.saturated.data(),
                           r.weakest_contrast.data(), r.weakest_bit.data());
  }
  const int skip = axis.total_bits - axis.projected_bits;
  sli::GrayToPosition(code.data(), width, skip, size, position.data(), r.flags.data());
  if (job.options->gray_subpixel) {
    const PatternLayout& layout = *job.layout;
    sli::RefineGrayEdge(code.data(), r.weakest_contrast.data(), r.weakest_bit.data(),
                        (*job.captures)[layout.white_frame].ptr<uint8_t>(y),
                        (*job.captures)[layout.black_frame].ptr<uint8_t>(y), width, skip,
                        position.data());
  }
  const int steps = static_cast<int>(axis.phase_frame.size());
  if (steps == 0) {
    std::fill(modulation.begin(), modulation.end(), std::numeric_limits<float>::infinity());
    return;
  }
  std::fill(r.s.begin(), r.s.end(), 0.0f);
  std::fill(r.c.begin(), r.c.end(), 0.0f);
  for (int n = 0; n < steps; ++n) {
    const double shift_rad = 2.0 * std::numbers::pi * n / steps;
    sli::AccumulatePhaseSample((*job.captures)[axis.phase_frame[n]].ptr<uint8_t>(y), width,
                               static_cast<float>(std::sin(shift_rad)),
                               static_cast<float>(std::cos(shift_rad)), saturation_minus_one,
                               r.s.data(), r.c.data(), r.saturated.data());
  }
  // I_n = A + B cos(phi - d_n): sum I_n (sin d_n, cos d_n) = (N B / 2)(sin phi, cos phi),
  // so the peak-to-peak 2B is (4 / N) |(S, C)|.
  const double cell_px = static_cast<double>(1 << skip);
  sli::UnwrapPhase(r.s.data(), r.c.data(), width, static_cast<float>(job.patterns->phase_period_px),
                   4.0f / static_cast<float>(steps),
                   static_cast<float>(job.options->min_phase_modulation),
                   static_cast<float>(0.5 * cell_px + job.options->max_phase_gray_disagreement_px),
                   position.data(), modulation.data(), r.flags.data());
}

void DecodeBand(const DecodeJob& job, int row_begin, int row_end, int64_t* counts) {
  const int width = job.out->valid.cols;
  RowScratch r(width);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const PatternLayout& layout = *job.layout;
  if (!layout.columns.encoded) std::fill(r.position_u.begin(), r.position_u.end(), nan);
  if (!layout.columns.encoded)
    std::fill(r.modulation_u.begin(), r.modulation_u.end(), std::numeric_limits<float>::infinity());
  if (!layout.rows.encoded) std::fill(r.position_v.begin(), r.position_v.end(), nan);
  if (!layout.rows.encoded)
    std::fill(r.modulation_v.begin(), r.modulation_v.end(), std::numeric_limits<float>::infinity());
  for (int y = row_begin; y < row_end; ++y) {
    std::fill(r.min_contrast.begin(), r.min_contrast.end(), uint8_t{255});
    std::fill(r.saturated.begin(), r.saturated.end(), uint8_t{0});
    std::fill(r.flags.begin(), r.flags.end(), uint8_t{0});
    if (layout.columns.encoded) {
      DecodeAxisRow(job, layout.columns, job.patterns->projector_width_px, y, r, r.code_u, r.weak_u,
                    r.position_u, r.modulation_u);
    }
    if (layout.rows.encoded) {
      DecodeAxisRow(job, layout.rows, job.patterns->projector_height_px, y, r, r.code_v, r.weak_v,
                    r.position_v, r.modulation_v);
    }
    sli::FinishRow((*job.captures)[layout.white_frame].ptr<uint8_t>(y),
                   (*job.captures)[layout.black_frame].ptr<uint8_t>(y), r.min_contrast.data(),
                   r.weak_u.data(), r.weak_v.data(), r.saturated.data(), r.position_u.data(),
                   r.position_v.data(), r.modulation_u.data(), r.modulation_v.data(), width,
                   job.options->shadow_threshold, job.options->max_weak_bits_per_axis,
                   r.flags.data(), job.out->flags.ptr<uint8_t>(y),
                   job.out->projector_px.ptr<float>(y), job.out->valid.ptr<uint8_t>(y),
                   job.out->confidence.ptr<float>(y));
    sli::CountFlags(job.out->flags.ptr<uint8_t>(y), width, counts);
  }
}

Status CheckCaptures(const std::vector<cv::Mat>& captures, const PatternLayout& layout) {
  if (static_cast<int>(captures.size()) != layout.frame_count) {
    return InvalidArgumentError("structured-light decode: " + std::to_string(captures.size()) +
                                " captures given, the pattern layout has " +
                                std::to_string(layout.frame_count) + " frames");
  }
  for (size_t i = 0; i < captures.size(); ++i) {
    const cv::Mat& m = captures[i];
    if (m.empty()) {
      return InvalidArgumentError("structured-light decode: capture " + std::to_string(i) +
                                  " is empty (unreadable file?)");
    }
    if (m.type() != CV_8UC1) {
      return InvalidArgumentError("structured-light decode: capture " + std::to_string(i) +
                                  " has OpenCV type " + std::to_string(m.type()) +
                                  ", need 8-bit grayscale (CV_8UC1); read with IMREAD_GRAYSCALE");
    }
    if (m.size() != captures[0].size()) {
      return InvalidArgumentError("structured-light decode: capture " + std::to_string(i) + " is " +
                                  std::to_string(m.cols) + "x" + std::to_string(m.rows) +
                                  " px, capture 0 is " + std::to_string(captures[0].cols) + "x" +
                                  std::to_string(captures[0].rows));
    }
  }
  return OkStatus();
}

}  // namespace

Status DecoderOptions::Check() const {
  auto fail = [](const std::string& m) { return InvalidArgumentError("decoder options: " + m); };
  if (shadow_threshold < -1 || shadow_threshold > 255) {
    return fail("shadow_threshold " + std::to_string(shadow_threshold) + " not in [-1, 255]");
  }
  if (min_contrast < 0 || min_contrast > 255) {
    return fail("min_contrast " + std::to_string(min_contrast) + " not in [0, 255]");
  }
  if (saturation_level < 1 || saturation_level > 256) {
    return fail("saturation_level " + std::to_string(saturation_level) +
                " not in [1, 256] (256 disables)");
  }
  if (!std::isfinite(min_phase_modulation) || min_phase_modulation < 0.0) {
    return fail("min_phase_modulation must be finite and >= 0");
  }
  if (!std::isfinite(max_phase_gray_disagreement_px) || max_phase_gray_disagreement_px < 0.0) {
    return fail("max_phase_gray_disagreement_px must be finite and >= 0");
  }
  if (max_weak_bits_per_axis < 0 || max_weak_bits_per_axis > 16) {
    return fail("max_weak_bits_per_axis " + std::to_string(max_weak_bits_per_axis) +
                " not in [0, 16]");
  }
  if (num_threads < 0 || num_threads > 1024) {
    return fail("num_threads " + std::to_string(num_threads) + " not in [0, 1024]");
  }
  return OkStatus();
}

Status DecoderOptions::CheckAgainst(const PatternOptions& patterns) const {
  ST_RETURN_IF_ERROR(Check());
  ST_RETURN_IF_ERROR(patterns.Check());
  if (patterns.phase_steps == 0) return OkStatus();
  const double cell_px = static_cast<double>(1 << patterns.gray_lsb_skip);
  const double window_px = 0.5 * cell_px + max_phase_gray_disagreement_px;
  if (window_px >= 0.5 * patterns.phase_period_px) {
    std::ostringstream m;
    m << "decoder options: Gray cell " << cell_px << " px / 2 + max_phase_gray_disagreement_px "
      << max_phase_gray_disagreement_px << " px must be below half the phase period ("
      << patterns.phase_period_px / 2 << " px); lower gray_lsb_skip or the margin, or raise "
      << "the period";
    return InvalidArgumentError(m.str());
  }
  return OkStatus();
}

DecoderOptions DecoderOptions::OpenCvThresholds(int black_threshold, int white_threshold) {
  DecoderOptions o;
  o.shadow_threshold = black_threshold;
  o.min_contrast = white_threshold;
  o.max_weak_bits_per_axis = 0;
  o.saturation_level = 256;
  o.gray_subpixel = false;
  return o;
}

std::string DecodeReport::ToString() const {
  std::ostringstream s;
  s << decoded_pixels << " of " << camera_pixels << " camera px decoded ("
    << 100.0 * DecodedFraction() << " %); flagged: shadow " << shadow_pixels << ", low contrast "
    << low_contrast_pixels << ", saturated " << saturated_pixels << ", out of range "
    << out_of_range_pixels << ", low modulation " << low_modulation_pixels
    << ", phase/Gray disagree " << disagreement_pixels << "; " << decode_time_ms << " ms on "
    << threads_used << " thread(s)";
  return s.str();
}

Expected<Decoding> DecodeStructuredLight(const std::vector<cv::Mat>& captures,
                                         const PatternOptions& patterns,
                                         const DecoderOptions& options, DecodeReport* report) {
  Decoding out;
  ST_RETURN_IF_ERROR(DecodeStructuredLightInto(captures, patterns, options, &out, report));
  return out;
}

Status DecodeStructuredLightInto(const std::vector<cv::Mat>& captures,
                                 const PatternOptions& patterns, const DecoderOptions& options,
                                 Decoding* out_ptr, DecodeReport* report) {
  ST_CHECK(out_ptr != nullptr) << "DecodeStructuredLightInto needs an output Decoding";
  Decoding& out = *out_ptr;
  ST_RETURN_IF_ERROR(options.CheckAgainst(patterns));
  const PatternLayout layout = MakePatternLayout(patterns);
  ST_RETURN_IF_ERROR(CheckCaptures(captures, layout));

  const auto start = std::chrono::steady_clock::now();
  const int rows = captures[0].rows;
  const int cols = captures[0].cols;
  // create() keeps the buffers when size and type already match (no page faults on reuse).
  out.projector_px.create(rows, cols, CV_32FC2);
  out.valid.create(rows, cols, CV_8UC1);
  out.confidence.create(rows, cols, CV_32FC1);
  out.flags.create(rows, cols, CV_8UC1);

  int threads = options.num_threads > 0 ? options.num_threads
                                        : static_cast<int>(std::thread::hardware_concurrency());
  threads = std::clamp(threads, 1, std::max(1, rows / kMinRowsPerThread));
  const DecodeJob job{&captures, &patterns, &options, &layout, &out};
  std::vector<std::array<int64_t, 9>> counts(threads);
  for (auto& c : counts) c.fill(0);
  if (threads == 1) {
    DecodeBand(job, 0, rows, counts[0].data());
  } else {
    std::vector<std::thread> workers;
    workers.reserve(threads);
    for (int t = 0; t < threads; ++t) {
      const int begin = static_cast<int>(static_cast<int64_t>(rows) * t / threads);
      const int end = static_cast<int>(static_cast<int64_t>(rows) * (t + 1) / threads);
      workers.emplace_back(
          [&job, begin, end, c = counts[t].data()] { DecodeBand(job, begin, end, c); });
    }
    for (std::thread& w : workers) w.join();
  }
  const auto stop = std::chrono::steady_clock::now();

  if (report != nullptr) {
    std::array<int64_t, 9> total{};
    for (const auto& c : counts)
      for (int b = 0; b < 9; ++b) total[b] += c[b];
    *report = DecodeReport();
    report->camera_pixels = static_cast<int64_t>(rows) * cols;
    report->decoded_pixels = total[8];
    report->shadow_pixels = total[0];
    report->low_contrast_pixels = total[1];
    report->saturated_pixels = total[2];
    report->out_of_range_pixels = total[3];
    report->low_modulation_pixels = total[4];
    report->disagreement_pixels = total[5];
    report->threads_used = threads;
    report->decode_time_ms = std::chrono::duration<double, std::milli>(stop - start).count();
  }
  return OkStatus();
}

}  // namespace sandtable
