// The one JSON codec of Rigid3d and CameraModel for every file the project reads or writes
// (site files, unit and factory calibrations, table_from_tracker, ...): the file counterpart of
// proto/convert.h. docs/file-formats.md lists the files.
//
// Rigid3d (target_from_source, x_in_target = R x_in_source + t):
//   {"rotation_xyzw": [x, y, z, w], "translation_m": [x, y, z]}
// written as a unit quaternion (Eigen's coefficient order) and metres. Read also, for older
// files: "rotation_wxyz": [w, x, y, z] (table_from_tracker files) and "rotation": a 3x3
// row-major matrix (unit calibration files of version 1), each with "translation_m"; an
// optional "convention" string is a comment. A quaternion must have norm within
// kQuaternionNormTolerance of 1 (then it is normalised; hand-written files with 4 decimals pass,
// a typo such as [2, 0, 0, 0] does not); a matrix must be orthonormal within
// kRotationMatrixTolerance with det > 0.
//
// CameraModel (pinhole + Brown "plumb bob", OpenCV pixel convention, common/camera):
//   {"width_px": W, "height_px": H, "fx_px": .., "fy_px": .., "cx_px": .., "cy_px": ..,
//    "distortion_k1_k2_p1_p2_k3": [k1, k2, p1, p2, k3]}
// Read also: "throw_ratio" (+ optional "lens_shift_v") in place of fx..cy (site files; see
// CameraModel::FromThrowRatio); the distortion array is optional (zeros); and the version-1
// unit calibration form {"image_width_px", "image_height_px", "camera_matrix": 3x3 without
// skew, "distortion_coefficients": [5], "distortion_model": string}. The model read is checked
// with CameraModel::Check().
//
// Errors name the field: `where` is the path of the JSON value ("unit-3.json: projector");
// e.g. "unit-3.json: projector.fx_px = -3 must be finite and > 0" (INVALID_ARGUMENT),
// "unit-3.json: projector.fx_px is missing" (PARSE_ERROR). Unknown keys are PARSE_ERRORs.
#pragma once

#include <string_view>

#include <nlohmann/json.hpp>

#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"
#include "common/io/json_reader.h"

namespace sandtable::io {

constexpr double kQuaternionNormTolerance = 1e-3;
constexpr double kRotationMatrixTolerance = 1e-6;  // |R^T R - I| (Frobenius)

nlohmann::json RigidToJson(const Rigid3d& target_from_source);
Expected<Rigid3d> RigidFromJson(const nlohmann::json& j, std::string_view where);

nlohmann::json CameraModelToJson(const CameraModel& m);
Expected<CameraModel> CameraModelFromJson(const nlohmann::json& j, std::string_view where);

// Reader-level forms, for objects that hold more than the model (a site file's projector holds
// its intrinsics beside its photometry): read the model's keys from `reader` (marking them
// read), leaving the others to the caller and its End().
Status ReadCameraModelFields(ObjectReader* reader, CameraModel* model);
// The member `key` of `parent` as a Rigid3d (required).
Expected<Rigid3d> ReadRigid(ObjectReader* parent, std::string_view key);

}  // namespace sandtable::io
