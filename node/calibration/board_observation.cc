#include "node/calibration/board_observation.h"

#include <algorithm>
#include <charconv>
#include <filesystem>
#include <utility>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgproc.hpp>

#include "common/structured_light/capture_io.h"

namespace sandtable::node {

Status BoardSpec::Check() const {
  if (inner_cols < 3 || inner_rows < 3) {
    return InvalidArgumentError("board: " + std::to_string(inner_cols) + "x" +
                                std::to_string(inner_rows) + " inner corners; at least 3x3 needed");
  }
  if (!(square_m > 0.0) || !std::isfinite(square_m)) {
    return InvalidArgumentError("board: square_m = " + std::to_string(square_m) + " must be > 0");
  }
  return OkStatus();
}

Eigen::Vector3d BoardSpec::CornerInBoard_m(int k) const {
  return {(k % inner_cols) * square_m, (k / inner_cols) * square_m, 0.0};
}

Status ObservationOptions::Check() const {
  ST_RETURN_IF_ERROR(patterns.Check());
  ST_RETURN_IF_ERROR(decoder.CheckAgainst(patterns));
  if (!patterns.encode_columns || !patterns.encode_rows) {
    return InvalidArgumentError(
        "observation: the patterns must encode both projector axes (columns and rows)");
  }
  if (dense_stride_px < 1) return InvalidArgumentError("observation: dense_stride_px must be >= 1");
  if (corner_window_px < 1)
    return InvalidArgumentError("observation: corner_window_px must be >= 1");
  return OkStatus();
}

Expected<PoseObservation> ObservePose(const std::string& name, const std::vector<cv::Mat>& captures,
                                      const BoardSpec& board, const ObservationOptions& options) {
  ST_RETURN_IF_ERROR(board.Check());
  ST_RETURN_IF_ERROR(options.Check());
  const PatternLayout layout = MakePatternLayout(options.patterns);
  if (static_cast<int>(captures.size()) != layout.frame_count) {
    return InvalidArgumentError(name + ": " + std::to_string(captures.size()) +
                                " captures, the pattern layout has " +
                                std::to_string(layout.frame_count));
  }
  if (layout.white_frame < 0) return InvalidArgumentError(name + ": layout has no white frame");
  const cv::Mat& white = captures[layout.white_frame];
  if (white.empty() || white.type() != CV_8UC1) {
    return InvalidArgumentError(name + ": white frame is empty or not 8-bit grayscale");
  }

  PoseObservation obs;
  obs.name = name;
  obs.camera_size = white.size();
  const cv::Size pattern(board.inner_cols, board.inner_rows);
  std::vector<cv::Point2f> corners;
  bool found = false;
  try {
    found = cv::findChessboardCorners(white, pattern, corners,
                                      cv::CALIB_CB_ADAPTIVE_THRESH | cv::CALIB_CB_NORMALIZE_IMAGE);
    if (found) {
      cv::cornerSubPix(
          white, corners, cv::Size(options.corner_window_px, options.corner_window_px),
          cv::Size(-1, -1),
          cv::TermCriteria(cv::TermCriteria::EPS + cv::TermCriteria::COUNT, 100, 1e-4));
    }
  } catch (const cv::Exception& e) {
    return InvalidArgumentError(name + ": chessboard detection failed: " + e.what());
  }
  if (!found || static_cast<int>(corners.size()) != board.corner_count()) {
    return NotFoundError("chessboard " + std::to_string(board.inner_cols) + "x" +
                         std::to_string(board.inner_rows) + " not found in " + name +
                         " white frame (check --board-cols/--board-rows)");
  }
  for (const cv::Point2f& c : corners) obs.corners_in_camera_px.emplace_back(c.x, c.y);

  DecodeReport report;
  Expected<Decoding> decoded =
      DecodeStructuredLight(captures, options.patterns, options.decoder, &report);
  if (!decoded.ok()) return decoded.status().WithContext(name + ": ");
  obs.decode_time_ms = report.decode_time_ms;

  // Board region: convex hull of the inner corners, as a filled mask.
  std::vector<cv::Point> hull_in;
  for (const cv::Point2f& c : corners) hull_in.emplace_back(cvRound(c.x), cvRound(c.y));
  std::vector<cv::Point> hull;
  cv::convexHull(hull_in, hull);
  cv::Mat board_mask = cv::Mat::zeros(white.size(), CV_8UC1);
  cv::fillConvexPoly(board_mask, hull, cv::Scalar(255));

  const cv::Mat& valid = decoded->valid;
  const cv::Mat& map = decoded->projector_px;
  for (int y = 0; y < board_mask.rows; ++y) {
    const uint8_t* in_board = board_mask.ptr<uint8_t>(y);
    const uint8_t* ok = valid.ptr<uint8_t>(y);
    const cv::Vec2f* uv = map.ptr<cv::Vec2f>(y);
    for (int x = 0; x < board_mask.cols; ++x) {
      if (in_board[x] == 0) continue;
      ++obs.board_pixels;
      if (ok[x] == 0) continue;
      ++obs.decoded_board_pixels;
      if (x % options.dense_stride_px != 0 || y % options.dense_stride_px != 0) continue;
      obs.dense_in_camera_px.emplace_back(x, y);
      obs.dense_in_projector_px.emplace_back(uv[x][0], uv[x][1]);
    }
  }
  if (obs.dense_in_camera_px.size() < 50) {
    return DegenerateError(name + ": only " + std::to_string(obs.dense_in_camera_px.size()) +
                           " decoded samples on the board (of " + std::to_string(obs.board_pixels) +
                           " board pixels); check the projector lights the board and the "
                           "decoder thresholds");
  }
  return obs;
}

namespace {

// Number after "capture_", or -1.
int CaptureIndex(const std::string& folder_name) {
  const std::string prefix = "capture_";
  if (folder_name.rfind(prefix, 0) != 0) return -1;
  int index = -1;
  const char* begin = folder_name.data() + prefix.size();
  const char* end = folder_name.data() + folder_name.size();
  auto [ptr, ec] = std::from_chars(begin, end, index);
  if (ec != std::errc() || ptr != end || begin == end) return -1;
  return index;
}

}  // namespace

Expected<std::vector<PoseObservation>> ObservePoseFolders(const std::string& dir,
                                                          const BoardSpec& board,
                                                          const ObservationOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) {
    return IoError("--poses " + dir + ": not a directory");
  }
  std::vector<std::pair<int, std::string>> folders;
  // The error_code forms throughout: a folder that changes while listed is an error, not a throw.
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    std::error_code type_error;
    if (!it->is_directory(type_error)) continue;
    const std::string folder_name = it->path().filename().string();
    const int index = CaptureIndex(folder_name);
    if (index >= 0) folders.emplace_back(index, folder_name);
  }
  if (ec) return IoError("--poses " + dir + ": " + ec.message());
  if (folders.empty()) {
    return IoError("--poses " + dir +
                   ": no capture_N folders (expected capture_0, capture_1, ...)");
  }
  std::sort(folders.begin(), folders.end());
  const int frame_count = MakePatternLayout(options.patterns).frame_count;
  std::vector<PoseObservation> poses;
  for (const auto& [index, folder_name] : folders) {
    const std::string path = (std::filesystem::path(dir) / folder_name).string();
    Expected<std::vector<cv::Mat>> frames = LoadCaptureSequence(path, frame_count);
    if (!frames.ok()) return frames.status();
    Expected<PoseObservation> obs = ObservePose(folder_name, *frames, board, options);
    if (!obs.ok()) return obs.status();
    poses.push_back(std::move(*obs));
  }
  return poses;
}

}  // namespace sandtable::node
