// Factory calibration of a unit, derived from its TRUE spec with configurable error, so nodes
// start from realistic, imperfect knowledge (a unit is factory-calibrated once with a
// checkerboard and Gray codes; these errors stand for that procedure's residual).
//
// Errors are Gaussian, drawn from std::mt19937_64 seeded with (seed, unit id): the same seed
// gives the same calibration, and units differ. Zero sigmas reproduce the truth exactly.
#pragma once

#include <cstdint>

#include <nlohmann/json.hpp>

#include "common/base/status.h"
#include "common/io/unit_calibration_file.h"
#include "sim/site/site.h"

namespace sandtable::sim {

struct FactoryCalibrationError {
  double focal_relative_sigma = 0.003;    // fx, fy scaled by (1 + e)
  double principal_point_sigma_px = 2.0;  // cx, cy
  double distortion_sigma = 0.003;        // k1 (k2 gets a third of it; p1 p2 a tenth)
  double rotation_sigma_deg = 0.1;        // projector_from_camera, about a random axis
  double translation_sigma_m = 0.001;     // projector_from_camera, per axis
  Status Check() const;
};

struct FactoryCalibration {
  NodeId unit_id = kInvalidNodeId;
  CameraModel camera;
  CameraModel projector;
  Rigid3d projector_from_camera;
};

// INVALID_ARGUMENT when the unit has no camera or the error options are invalid.
Expected<FactoryCalibration> MakeFactoryCalibration(const UnitSpec& unit,
                                                    const FactoryCalibrationError& error,
                                                    uint64_t seed);

// As a unit's calibration: source "factory", no pose on the table yet.
UnitCalibration ToUnitCalibration(const FactoryCalibration& calibration);
// The factory file of a unit (make-site --factory-dir): the unit calibration file format
// (common/io/unit_calibration_file.h, "format": "sandtable.unit_calibration", version 2), so
// a node loads it with LoadUnitCalibration.
nlohmann::json FactoryCalibrationToJson(const FactoryCalibration& calibration);

}  // namespace sandtable::sim
