#include "node/calibration/structured_light_plan.h"

#include <cmath>
#include <tuple>

#include <opencv2/imgproc.hpp>

namespace sandtable::node {

Status PatternPlanOptions::Check() const {
  if (!(min_gray_cell_camera_px > 0)) {
    return InvalidArgumentError("pattern plan: min_gray_cell_camera_px must be > 0");
  }
  if (phase_steps < 3 || phase_steps > 64) {
    return InvalidArgumentError("pattern plan: phase_steps must be in [3, 64]");
  }
  if (phase_period_cells < 2) {
    return InvalidArgumentError("pattern plan: phase_period_cells must be >= 2");
  }
  if (max_gray_lsb_skip < 0) return InvalidArgumentError("pattern plan: max skip must be >= 0");
  return OkStatus();
}

PatternOptions PlanPatterns(int projector_width_px, int projector_height_px,
                            double projector_px_per_camera_px, const PatternPlanOptions& options) {
  PatternOptions p;
  p.projector_width_px = projector_width_px;
  p.projector_height_px = projector_height_px;
  const double needed_cell_px =
      options.min_gray_cell_camera_px * std::max(projector_px_per_camera_px, 1e-3);
  int skip = 0;
  while ((1 << skip) < needed_cell_px && skip < options.max_gray_lsb_skip) ++skip;
  // Never skip every bit of the smaller axis.
  skip = std::min(skip,
                  std::min(GrayBitsFor(projector_width_px), GrayBitsFor(projector_height_px)) - 1);
  skip = std::max(skip, 0);
  p.gray_lsb_skip = skip;
  p.phase_steps = options.phase_steps;
  // Period: phase_period_cells cells, and always wide enough for unwrapping (cell / 2 + 1 px
  // disagreement margin < P / 2).
  const double cell = static_cast<double>(1 << skip);
  p.phase_period_px = std::max(options.phase_period_cells * cell, cell + 4.0);
  return p;
}

DecoderOptions CalibrationDecoderOptions() {
  DecoderOptions d;
  d.num_threads = 1;
  return d;
}

cv::Mat To8Bit(const cv::Mat& capture, int bit_depth) {
  if (capture.type() == CV_8UC1) return capture;
  cv::Mat out;
  const double max_dn = static_cast<double>((1 << std::clamp(bit_depth, 1, 16)) - 1);
  capture.convertTo(out, CV_8UC1, 255.0 / max_dn);
  return out;
}

Expected<std::vector<ProjectorGridPoint>> DecodeToProjectorGrid(
    const std::vector<cv::Mat>& captures_8bit, const PatternOptions& patterns,
    const ProjectorGridOptions& grid, CameraDecodeReport* report, const cv::Mat* mask) {
  CameraDecodeReport local;
  Expected<Decoding> decoding =
      DecodeStructuredLight(captures_8bit, patterns, CalibrationDecoderOptions(), &local.decode);
  if (!decoding.ok()) return decoding.status();
  if (mask && !mask->empty() && mask->size() == decoding->valid.size() && mask->type() == CV_8UC1) {
    cv::Mat keep;
    cv::bitwise_and(decoding->valid, *mask, keep);
    decoding->valid = keep;
  }
  Expected<std::vector<ProjectorGridPoint>> points =
      SampleProjectorGrid(*decoding, grid, &local.grid);
  if (report) *report = local;
  return points;
}

Expected<std::vector<ProjectorGridPoint>> DecodeToProjectorCells(
    const std::vector<cv::Mat>& captures_8bit, const PatternOptions& patterns,
    ProjectorCellReport* report, const cv::Mat* mask) {
  if (patterns.phase_steps != 0 || patterns.gray_lsb_skip < 1) {
    return InvalidArgumentError(
        "cell decode: the plan must be Gray code only (phase_steps 0) with at least one skipped "
        "bit");
  }
  DecoderOptions decoder = CalibrationDecoderOptions();
  decoder.gray_subpixel = false;  // whole cells: their centroids are the measurement
  Expected<Decoding> decoding = DecodeStructuredLight(captures_8bit, patterns, decoder);
  if (!decoding.ok()) return decoding.status();
  if (mask && !mask->empty() && mask->size() == decoding->valid.size() && mask->type() == CV_8UC1) {
    cv::Mat keep;
    cv::bitwise_and(decoding->valid, *mask, keep);
    decoding->valid = keep;
  }
  ProjectorCellOptions cells;
  cells.projector_width_px = patterns.projector_width_px;
  cells.projector_height_px = patterns.projector_height_px;
  cells.cell_px = 1 << patterns.gray_lsb_skip;
  return SampleProjectorCells(*decoding, cells, report);
}

PatternOptions GrayPrefix(const PatternOptions& full) {
  PatternOptions gray = full;
  gray.phase_steps = 0;
  return gray;
}

std::vector<Track> BuildTracks(NodeId projector_unit,
                               const std::map<NodeId, std::vector<ProjectorGridPoint>>& by_camera) {
  std::map<std::pair<float, float>, size_t> index;
  std::vector<Track> tracks;
  for (const auto& [camera, points] : by_camera) {
    for (const ProjectorGridPoint& p : points) {
      const auto key = std::make_pair(p.projector_px.y(), p.projector_px.x());
      auto [it, inserted] = index.emplace(key, tracks.size());
      if (inserted) {
        Track t;
        t.projector_unit = projector_unit;
        t.projector_px = p.projector_px.cast<double>();
        tracks.push_back(t);
      }
      tracks[it->second].cameras.push_back({camera, p.camera_px.cast<double>()});
    }
  }
  return tracks;
}

cv::Mat LitMask(const cv::Mat& white_8bit, const cv::Mat& black_8bit, int threshold) {
  cv::Mat diff;
  cv::subtract(white_8bit, black_8bit, diff, cv::noArray(), CV_16S);
  return diff > threshold;
}

bool MasksOverlap(const cv::Mat& a, const cv::Mat& b, int margin_px, int min_pixels) {
  if (a.size() != b.size() || a.empty()) return false;
  cv::Mat grown, both;
  cv::dilate(
      a, grown,
      cv::getStructuringElement(cv::MORPH_RECT, cv::Size(2 * margin_px + 1, 2 * margin_px + 1)));
  cv::bitwise_and(grown, b, both);
  return cv::countNonZero(both) > min_pixels;
}

int CountLitPixels(const cv::Mat& white_8bit, const cv::Mat& black_8bit, int threshold) {
  return cv::countNonZero(LitMask(white_8bit, black_8bit, threshold));
}

}  // namespace sandtable::node
