// Export of a unit's calibration as OpenCV YAML, readable by cv::FileStorage and by ROS
// camera_info readers (camera_calibration_parsers): the calibration leaving the cluster for a
// renderer of the model (DESIGN.md "Interchange"; docs/file-formats.md).
//
// Top-level keys are the PROJECTOR's:
//   image_width, image_height, camera_name ("unit-3-projector"),
//   camera_matrix (3x3), distortion_model: plumb_bob, distortion_coefficients (1x5: k1 k2 p1 p2
//   k3), rectification_matrix (identity) and projection_matrix ([K | 0]) for ROS,
//   R (3x3) and T (3x1, metres) with x_in_projector = R x_in_model + T, i.e.
//   projector_from_model = table_from_projector.Inverse() * table_from_model, where the model
//   frame is the glTF model's own frame converted to z-up (docs/frames.md). The table frame and
//   table_from_model stay in the JSON file beside it (unit_calibration_file.h).
// Beside them: format "sandtable.unit_calibration.opencv", version 1, unit_id, source, and a
// "camera" map with the unit camera's image_width, image_height, camera_matrix,
// distortion_model, distortion_coefficients and projector_from_camera_R / _T_m (metres,
// x_in_projector = R x_in_camera + T). Matrices are maps {rows, cols, dt: d, data: [...]}
// (OpenCV's matrix layout without its !!opencv-matrix tag, so plain YAML parsers read them
// too); numbers are written with 17 significant digits.
//
// Failure: INVALID_ARGUMENT when the calibration is invalid or lacks table_from_projector or
// table_from_model (the export needs a unit registered in a site); IO_ERROR naming the path;
// reading: PARSE_ERROR naming the path and the key ("unit-3.yaml: R must be a 3x3 matrix").
#pragma once

#include <optional>
#include <string>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"
#include "common/io/unit_calibration_file.h"

namespace sandtable {

inline constexpr char kOpenCvYamlFormat[] = "sandtable.unit_calibration.opencv";
inline constexpr int kOpenCvYamlVersion = 1;

// What an OpenCV YAML export holds, as read back.
struct OpenCvYamlCalibration {
  NodeId unit_id = kInvalidNodeId;
  std::string source;
  CameraModel projector;
  Rigid3d projector_from_model;  // R, T (metres)
  std::optional<CameraModel> camera;
  std::optional<Rigid3d> projector_from_camera;
};

// The YAML text (what WriteOpenCvYaml writes).
Expected<std::string> OpenCvYamlText(const UnitCalibration& calibration);
Status WriteOpenCvYaml(const UnitCalibration& calibration, const std::string& path);
// For tests and tools: reads what WriteOpenCvYaml writes (the file through ReadInputFile:
// regular files only, at most kMaxTextInputBytes; then cv::FileStorage from memory). IO_ERROR
// naming the path when it cannot be read, PARSE_ERROR/INVALID_ARGUMENT naming the field.
Expected<OpenCvYamlCalibration> ReadOpenCvYaml(const std::string& path);
// The same from text; `path` names the source in messages. Never throws.
Expected<OpenCvYamlCalibration> ParseOpenCvYaml(const std::string& text, const std::string& path);

}  // namespace sandtable
