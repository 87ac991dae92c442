#include "common/structured_light/pattern_sequence.h"

#include <cmath>
#include <numbers>
#include <string>

namespace sandtable {

namespace {

constexpr int kMaxProjectorSize_px = 65536;  // codes fit in 16 bits
constexpr int kMaxPhaseSteps = 64;
constexpr double kMinPhasePeriod_px = 3.0;

void AddGrayFrames(PatternLayout::Axis& axis, int& next) {
  for (int k = 0; k < axis.projected_bits; ++k) {
    axis.gray_frame.push_back(next++);
    axis.gray_inverse_frame.push_back(next++);
  }
}

void AddPhaseFrames(PatternLayout::Axis& axis, int steps, int& next) {
  if (!axis.encoded) return;
  for (int n = 0; n < steps; ++n) axis.phase_frame.push_back(next++);
}

// One row (columns: depends on u) or one value per row (rows: depends on v) of a Gray pattern.
uint8_t GrayLevel(int coordinate, int bit, bool inverse, const PatternOptions& o) {
  const bool on = ((GrayFromBinary(static_cast<uint32_t>(coordinate)) >> bit) & 1u) != 0;
  return static_cast<uint8_t>((on != inverse) ? o.high_level : o.low_level);
}

uint8_t PhaseLevel(int coordinate, int step, const PatternOptions& o) {
  const double phase_rad = 2.0 * std::numbers::pi * coordinate / o.phase_period_px -
                           2.0 * std::numbers::pi * step / o.phase_steps;
  const double level =
      o.low_level + (o.high_level - o.low_level) * (0.5 + 0.5 * std::cos(phase_rad));
  return static_cast<uint8_t>(std::lround(level));
}

// Fills a frame whose value depends only on u (columns) or only on v (rows).
cv::Mat MakeFrame(const PatternOptions& o, bool depends_on_u, auto level_of) {
  cv::Mat frame(o.projector_height_px, o.projector_width_px, CV_8UC1);
  if (depends_on_u) {
    uint8_t* row0 = frame.ptr<uint8_t>(0);
    for (int u = 0; u < o.projector_width_px; ++u) row0[u] = level_of(u);
    for (int v = 1; v < o.projector_height_px; ++v) frame.row(0).copyTo(frame.row(v));
  } else {
    for (int v = 0; v < o.projector_height_px; ++v) frame.row(v).setTo(level_of(v));
  }
  return frame;
}

}  // namespace

int GrayBitsFor(int size) {
  int bits = 0;
  while ((int64_t{1} << bits) < size) ++bits;
  return bits;
}

Status PatternOptions::Check() const {
  auto fail = [](const std::string& m) { return InvalidArgumentError("pattern options: " + m); };
  if (projector_width_px < 2 || projector_width_px > kMaxProjectorSize_px ||
      projector_height_px < 2 || projector_height_px > kMaxProjectorSize_px) {
    return fail("projector size " + std::to_string(projector_width_px) + "x" +
                std::to_string(projector_height_px) + " px is outside [2, 65536]");
  }
  if (!encode_columns && !encode_rows) return fail("neither columns nor rows are encoded");
  const int min_bits = std::min(encode_columns ? GrayBitsFor(projector_width_px) : 64,
                                encode_rows ? GrayBitsFor(projector_height_px) : 64);
  if (gray_lsb_skip < 0 || gray_lsb_skip >= min_bits) {
    return fail("gray_lsb_skip " + std::to_string(gray_lsb_skip) + " must be in [0, " +
                std::to_string(min_bits) + ")");
  }
  if (phase_steps != 0 && (phase_steps < 3 || phase_steps > kMaxPhaseSteps)) {
    return fail("phase_steps " + std::to_string(phase_steps) + " must be 0 (off) or in [3, 64]");
  }
  if (!(phase_period_px >= kMinPhasePeriod_px) || !std::isfinite(phase_period_px)) {
    return fail("phase_period_px " + std::to_string(phase_period_px) + " must be >= 3");
  }
  if (low_level < 0 || high_level > 255 || low_level >= high_level) {
    return fail("levels low " + std::to_string(low_level) + " high " + std::to_string(high_level) +
                " must satisfy 0 <= low < high <= 255");
  }
  return OkStatus();
}

PatternOptions PatternOptions::OpenCvGrayCode(int width_px, int height_px) {
  PatternOptions o;
  o.projector_width_px = width_px;
  o.projector_height_px = height_px;
  o.order = FrameOrder::kOpenCvGrayCode;
  o.phase_steps = 0;
  return o;
}

PatternLayout MakePatternLayout(const PatternOptions& options) {
  const Status status = options.Check();
  ST_CHECK(status.ok()) << "MakePatternLayout needs valid options: " << status.ToString();
  PatternLayout layout;
  auto init_axis = [&](PatternLayout::Axis& axis, bool encoded, int size) {
    axis.encoded = encoded;
    if (!encoded) return;
    axis.total_bits = GrayBitsFor(size);
    axis.projected_bits = axis.total_bits - options.gray_lsb_skip;
  };
  init_axis(layout.columns, options.encode_columns, options.projector_width_px);
  init_axis(layout.rows, options.encode_rows, options.projector_height_px);
  int next = 0;
  if (options.order == FrameOrder::kSandtable) {
    layout.white_frame = next++;
    layout.black_frame = next++;
    AddGrayFrames(layout.columns, next);
    AddGrayFrames(layout.rows, next);
  } else {
    AddGrayFrames(layout.columns, next);
    AddGrayFrames(layout.rows, next);
    layout.white_frame = next++;
    layout.black_frame = next++;
  }
  AddPhaseFrames(layout.columns, options.phase_steps, next);
  AddPhaseFrames(layout.rows, options.phase_steps, next);
  layout.frame_count = next;
  return layout;
}

Expected<std::vector<cv::Mat>> GeneratePatterns(const PatternOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  const PatternLayout layout = MakePatternLayout(options);
  std::vector<cv::Mat> frames(static_cast<size_t>(layout.frame_count));
  const cv::Size size(options.projector_width_px, options.projector_height_px);
  frames[layout.white_frame] = cv::Mat(size, CV_8UC1, cv::Scalar(options.high_level));
  frames[layout.black_frame] = cv::Mat(size, CV_8UC1, cv::Scalar(options.low_level));
  auto fill_axis = [&](const PatternLayout::Axis& axis, bool depends_on_u) {
    for (int k = 0; k < axis.projected_bits; ++k) {
      const int bit = axis.total_bits - 1 - k;
      frames[axis.gray_frame[k]] = MakeFrame(
          options, depends_on_u, [&](int c) { return GrayLevel(c, bit, false, options); });
      frames[axis.gray_inverse_frame[k]] =
          MakeFrame(options, depends_on_u, [&](int c) { return GrayLevel(c, bit, true, options); });
    }
    for (size_t n = 0; n < axis.phase_frame.size(); ++n) {
      frames[axis.phase_frame[n]] = MakeFrame(options, depends_on_u, [&](int c) {
        return PhaseLevel(c, static_cast<int>(n), options);
      });
    }
  };
  fill_axis(layout.columns, true);
  fill_axis(layout.rows, false);
  return frames;
}

}  // namespace sandtable
