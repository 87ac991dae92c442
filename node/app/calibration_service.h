// The calibration a node holds at start, and its export.
//
// A node starts from its factory calibration (camera and projector intrinsics,
// projector_from_camera: the unit file of common/io/unit_calibration_file.h); registered in a
// site (self-calibration, node/app/self_calibration_service.h) it also holds
// table_from_projector and table_from_model. The lab's TEST MODE hands a node its true pose
// instead (LoadTruePose: the only place where truth reaches a node), labelled source
// "factory+true_pose" in everything exported.
// Export: <dir>/unit-<id>.json (the unit file, format sandtable.unit_calibration) and
// <dir>/unit-<id>.yaml (OpenCV YAML: projector intrinsics, R and T model -> projector), each
// written to a temporary file and renamed, so a reader never sees half a file.
#pragma once

#include <optional>
#include <string>

#include "common/base/status.h"
#include "common/geometry/rigid3.h"
#include "common/io/unit_calibration_file.h"
#include "node/net/node_runtime.h"

namespace sandtable::node {

// The lab's test-mode pose file:
//   {"format":"sandtable.true_pose","version":1,"unit_id":N,
//    "table_from_projector":RIGID,"table_from_model":RIGID}   (RIGID: common/io/json_codec.h)
struct TruePose {
  NodeId unit_id = kInvalidNodeId;
  Rigid3d table_from_projector;
  Rigid3d table_from_model;
};
Expected<TruePose> ParseTruePose(const std::string& json_text, const std::string& source);
Expected<TruePose> LoadTruePose(const std::string& path);
std::string TruePoseToJson(const TruePose& pose);

// Factory intrinsics + the true pose. INVALID_ARGUMENT when the ids differ.
Expected<UnitCalibration> ComposeTruePoseCalibration(const UnitCalibration& factory,
                                                     const TruePose& pose);

struct ExportedCalibration {
  std::string json_path;
  std::string yaml_path;  // empty when the calibration is not registered in a site
};
// Writes unit-<id>.json (and .yaml when table_from_projector and table_from_model are known).
Expected<ExportedCalibration> ExportCalibration(const UnitCalibration& calibration,
                                                const std::string& directory);

}  // namespace sandtable::node
