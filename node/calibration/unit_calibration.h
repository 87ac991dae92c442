// A unit's factory calibration: camera intrinsics, projector intrinsics (both pinhole + Brown
// k1 k2 p1 p2 k3, OpenCV conventions) and projector_from_camera, with its JSON file format
// (docs/unit-calibration.md).
//
// Frames: camera and projector frames are OpenCV device frames (x right, y down, z forward).
// projector_from_camera maps x_in_camera to x_in_projector = R x_in_camera + t, t in METRES
// (field "translation_m"; the same R, t as cv::stereoCalibrate's, whose t is in the board's
// unit). Pixel (0, 0) is centred at (0.0, 0.0) for both devices.
//
// Loading treats the file as untrusted: every error names the file and the field
// ("unit.json: projector.camera_matrix[0][0] = -3 must be > 0"), never aborts.
#pragma once

#include <string>
#include <string_view>
#include <vector>

#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"

namespace sandtable::node {

struct UnitCalibration {
  CameraModel camera;
  CameraModel projector;
  Rigid3d projector_from_camera;  // translation in metres
  double camera_rms_px = 0.0;     // chessboard corners in the camera, joint refinement
  double projector_rms_px = 0.0;  // dense decoded points in the projector, joint refinement
  std::vector<std::string> poses_used;

  // Both models valid (CameraModel::Check), transform finite, rms finite and >= 0.
  Status Check() const;
};

// The JSON text of the file format (pretty-printed, 2 spaces).
std::string UnitCalibrationToJson(const UnitCalibration& calibration);
// Parses the JSON text; `source` (a file name) prefixes every error. PARSE_ERROR for malformed
// JSON, a missing or mistyped field, or a wrong format/version; INVALID_ARGUMENT for values out
// of range (non-positive focal length, non-rotation matrix, non-finite numbers).
Expected<UnitCalibration> ParseUnitCalibration(std::string_view json_text, std::string_view source);

// Files. IO_ERROR naming the path when it cannot be written or read.
Status SaveUnitCalibration(const UnitCalibration& calibration, const std::string& path);
Expected<UnitCalibration> LoadUnitCalibration(const std::string& path);

}  // namespace sandtable::node
