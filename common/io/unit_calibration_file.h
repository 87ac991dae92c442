// A unit's calibration (camera intrinsics, projector intrinsics, projector_from_camera and,
// once registered in a site, its pose on the table) and its JSON file, the one file a node
// starts from and exports: docs/unit-calibration.md, docs/file-formats.md.
//
// Frames: camera and projector frames are OpenCV device frames (x right, y down, z forward);
// the table frame is docs/frames.md's (origin on the table top, +z up); the model frame is the
// glTF model's own frame converted to z-up (table (x, y, z) = glTF (x, -z, y)).
//   projector_from_camera: x_in_projector = R x_in_camera + t, t in METRES (cv::stereoCalibrate's
//     R and T with the board measured in metres).
//   table_from_projector:  x_in_table = R x_in_projector + t (metres).
//   table_from_model:      x_in_table = R x_in_model + t (metres): where the model stands.
// Pixel (0, 0) is centred at (0.0, 0.0) for both devices.
//
// File (version 2; json_codec.h gives the Rigid and CameraModel forms):
//   {"format": "sandtable.unit_calibration", "version": 2, "unit_id": 3, "source": "factory",
//    "camera": CAMERA_MODEL, "projector": CAMERA_MODEL, "projector_from_camera": RIGID,
//    "table_from_projector": RIGID, "table_from_model": RIGID,          (optional)
//    "camera_rms_px": 0.12, "projector_rms_px": 0.31, "poses_used": ["capture_0", ...],
//    "projector_response": {"gamma": 2.21, "black_level": 0.002},  (optional; black_level too)
//    "predicted_error": {"rms_px": 0.04, "rms_mm": 0.09, "samples": 180, "sigma_px": 0.05,
//                        "weak_direction": "...", "weak_share": 0.6, "undetermined": "..."}}
//    (optional: what the solve's covariance predicts, node/calibration/cluster_uncertainty.h;
//    rms_mm absent when it had too few points on the table to say)
// unit_id, source, table_from_* and the rms/poses fields are optional (rms and poses are written
// when the calibration came from poses). Also loaded: version 1 files
// ("format": "sandtable-unit-calibration", 3x3 rotation, camera_matrix intrinsics; source
// becomes "unit_calibration") and the factory files that `sandtable-world make-site
// --factory-dir` wrote before they carried format/version (unit_id, camera, projector,
// projector_from_camera; source becomes "factory").
//
// Loading treats the file as untrusted: every error names the file and the field
// ("unit-3.json: projector.fx_px = -3 must be finite and > 0"), never aborts. PARSE_ERROR for
// malformed JSON, a missing, unknown or mistyped field, or a wrong format/version;
// INVALID_ARGUMENT for values out of range (non-positive focal length, non-rotation matrix,
// negative rms); IO_ERROR naming the path when a file cannot be read or written.
#pragma once

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"

namespace sandtable {

inline constexpr char kUnitCalibrationFormat[] = "sandtable.unit_calibration";
inline constexpr int kUnitCalibrationVersion = 2;

// Values of UnitCalibration::source.
inline constexpr char kSourceUnitCalibration[] = "unit_calibration";  // calibrate-unit (boards)
inline constexpr char kSourceFactory[] = "factory";
inline constexpr char kSourceFactoryTruePose[] = "factory+true_pose";  // lab test mode only
inline constexpr char kSourceStructuredLight[] = "structured_light";

// The projector's response as its own camera measured it (the self-calibration's pre-pass,
// node/calibration/projector_response.h): input level v emits b + (1 - b) (v / 255)^gamma.
struct ProjectorResponseRecord {
  double gamma = 2.2;
  double black_level = -1.0;  // fraction of peak; < 0: not measured
};

// What a self-calibration's covariance predicts of this unit's registration error (1 sigma):
// where its projector images the surface (px) and where its pixels land on the table (mm).
struct PredictedErrorRecord {
  double rms_px = 0.0;
  double rms_mm = -1.0;        // < 0: not predicted (too few of its points on the table)
  int samples = 0;             // points the mm figure is the rms over
  double sigma_px = 0.0;       // the observation noise it was scaled by
  std::string weak_direction;  // the direction carrying most of it, in words
  double weak_share = 0.0;     // that direction's share of the variance, [0, 1]
  std::string undetermined;    // what the data leave to the gauge (table frame, model)
};

struct UnitCalibration {
  NodeId unit_id = kInvalidNodeId;  // kInvalidNodeId: not written
  std::string source;               // one of the kSource* values above; empty: not written
  CameraModel camera;
  CameraModel projector;
  Rigid3d projector_from_camera;                // metres
  std::optional<Rigid3d> table_from_projector;  // once registered in a site
  std::optional<Rigid3d> table_from_model;      // where the glTF model (z-up) stands on the table
  double camera_rms_px = 0.0;     // chessboard corners in the camera, joint refinement
  double projector_rms_px = 0.0;  // dense decoded points in the projector, joint refinement
  std::vector<std::string> poses_used;
  std::optional<ProjectorResponseRecord> projector_response;  // once measured
  std::optional<PredictedErrorRecord> predicted_error;        // a self-calibration's

  // Both models valid (CameraModel::Check), transforms finite, rms finite and >= 0, unit_id a
  // node id or kInvalidNodeId. The message names the field ("projector: fx_px = -3 ...").
  Status Check() const;
};

// The file's JSON (UnitCalibrationToJson: pretty-printed, 2 spaces, final newline).
nlohmann::json UnitCalibrationToJsonValue(const UnitCalibration& calibration);
std::string UnitCalibrationToJson(const UnitCalibration& calibration);

// `source` (a file name) prefixes every error.
Expected<UnitCalibration> UnitCalibrationFromJson(const nlohmann::json& json,
                                                  std::string_view source);
Expected<UnitCalibration> ParseUnitCalibration(std::string_view json_text, std::string_view source);

// Files. Save checks the calibration first (INVALID_ARGUMENT naming the path and field).
Status SaveUnitCalibration(const UnitCalibration& calibration, const std::string& path);
Expected<UnitCalibration> LoadUnitCalibration(const std::string& path);

}  // namespace sandtable
