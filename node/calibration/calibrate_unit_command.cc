#include "node/calibration/calibrate_unit_command.h"

#include <chrono>
#include <cmath>
#include <fstream>
#include <iostream>
#include <limits>

#include <nlohmann/json.hpp>

#include "common/base/units.h"
#include "node/calibration/board_observation.h"
#include "node/calibration/cross_validation.h"
#include "node/calibration/unit_calibration.h"
#include "node/calibration/unit_calibrator.h"

namespace sandtable::node {
namespace {

using Json = nlohmann::json;

int Usage(const std::string& why) {
  std::cerr << "sandtable-node calibrate-unit: " << why << "\n"
            << "usage: sandtable-node calibrate-unit --poses DIR -o unit.json [--report FILE]\n"
            << "         [--board-cols 9] [--board-rows 7] [--square-mm 75]\n"
            << "         [--projector-width 1024] [--projector-height 768]\n"
            << "         [--projector-distortion none|k1|k1k2|radial3|full]\n"
            << "         [--camera-distortion none|k1|k1k2|radial3|full]\n"
            << "         [--dense-points 500] [--dense-weight 1] [--no-cross-validation]\n";
  return 2;
}

bool ParseInt(const std::string& text, int* out) {
  char* end = nullptr;
  const long v = std::strtol(text.c_str(), &end, 10);
  if (end == text.c_str() || *end != '\0' || v < 1 || v > 1000000) return false;
  *out = static_cast<int>(v);
  return true;
}

bool ParseDouble(const std::string& text, double* out) {
  char* end = nullptr;
  const double v = std::strtod(text.c_str(), &end);
  if (end == text.c_str() || *end != '\0' || !std::isfinite(v) || v <= 0.0) return false;
  *out = v;
  return true;
}

// NaN is not JSON: null instead.
Json Number(double x) { return std::isfinite(x) ? Json(x) : Json(nullptr); }

Json Deviations(const ParameterDeviations& d) {
  return Json{{"fx_px", Number(d.intrinsics_px[0])}, {"fy_px", Number(d.intrinsics_px[1])},
              {"cx_px", Number(d.intrinsics_px[2])}, {"cy_px", Number(d.intrinsics_px[3])},
              {"k1", Number(d.distortion[0])},       {"k2", Number(d.distortion[1])},
              {"p1", Number(d.distortion[2])},       {"p2", Number(d.distortion[3])},
              {"k3", Number(d.distortion[4])}};
}

}  // namespace

int RunCalibrateUnit(const std::vector<std::string>& args) {
  const auto start = std::chrono::steady_clock::now();
  std::string poses_dir, output_path, report_path;
  UnitCalibrationOptions options;
  ObservationOptions observation;
  bool cross_validate = true;
  double square_mm = 75.0;
  for (size_t i = 0; i < args.size(); ++i) {
    const std::string& flag = args[i];
    if (flag == "--no-cross-validation") {
      cross_validate = false;
      continue;
    }
    if (i + 1 >= args.size()) return Usage("missing value after " + flag);
    const std::string& value = args[++i];
    bool ok = true;
    if (flag == "--poses") {
      poses_dir = value;
    } else if (flag == "-o" || flag == "--output") {
      output_path = value;
    } else if (flag == "--report") {
      report_path = value;
    } else if (flag == "--board-cols") {
      ok = ParseInt(value, &options.board.inner_cols);
    } else if (flag == "--board-rows") {
      ok = ParseInt(value, &options.board.inner_rows);
    } else if (flag == "--square-mm") {
      ok = ParseDouble(value, &square_mm);
    } else if (flag == "--projector-width") {
      ok = ParseInt(value, &options.projector_width_px);
    } else if (flag == "--projector-height") {
      ok = ParseInt(value, &options.projector_height_px);
    } else if (flag == "--dense-points") {
      ok = ParseInt(value, &options.max_dense_points_per_pose);
    } else if (flag == "--dense-weight") {
      ok = ParseDouble(value, &options.dense_weight);
    } else if (flag == "--projector-distortion" || flag == "--camera-distortion") {
      Expected<DistortionModel> model = ParseDistortionModel(value);
      if (!model.ok()) return Usage(flag + ": " + model.status().message());
      (flag == "--projector-distortion" ? options.projector_distortion
                                        : options.camera_distortion) = *model;
    } else {
      return Usage("unknown flag " + flag);
    }
    if (!ok) return Usage(flag + " " + value + ": not a valid positive number");
  }
  if (poses_dir.empty()) return Usage("--poses DIR is required");
  if (output_path.empty()) return Usage("-o unit.json is required");
  options.board.square_m = MmToM(square_mm);
  observation.patterns =
      PatternOptions::OpenCvGrayCode(options.projector_width_px, options.projector_height_px);
  if (Status valid = options.Check(); !valid.ok()) return Usage(valid.message());

  Expected<std::vector<PoseObservation>> poses =
      ObservePoseFolders(poses_dir, options.board, observation);
  if (!poses.ok()) {
    std::cerr << "calibrate-unit: " << poses.status().ToString() << "\n";
    return 1;
  }
  Expected<UnitCalibrationResult> result = CalibrateUnit(*poses, options);
  if (!result.ok()) {
    std::cerr << "calibrate-unit: " << result.status().ToString() << "\n";
    return 1;
  }
  if (Status saved = SaveUnitCalibration(result->calibration, output_path); !saved.ok()) {
    std::cerr << "calibrate-unit: " << saved.ToString() << "\n";
    return 1;
  }
  const UnitCalibration& c = result->calibration;
  const UnitCalibrationReport& r = result->report;
  std::cout << "calibrate-unit: " << poses->size() << " poses; camera fx " << c.camera.fx_px
            << " fy " << c.camera.fy_px << " px, rms " << r.camera_rms_px << " px; projector fx "
            << c.projector.fx_px << " fy " << c.projector.fy_px << " px, rms " << r.projector_rms_px
            << " px; baseline " << c.projector_from_camera.translation.norm() << " m -> "
            << output_path << "\n";

  if (report_path.empty()) return 0;
  Json report{{"camera_rms_px", r.camera_rms_px},
              {"projector_rms_px", r.projector_rms_px},
              {"camera_fx_px", c.camera.fx_px},
              {"camera_fy_px", c.camera.fy_px},
              {"camera_cx_px", c.camera.cx_px},
              {"camera_cy_px", c.camera.cy_px},
              {"projector_fx_px", c.projector.fx_px},
              {"projector_fy_px", c.projector.fy_px},
              {"projector_cx_px", c.projector.cx_px},
              {"projector_cy_px", c.projector.cy_px},
              {"baseline_m", c.projector_from_camera.translation.norm()},
              {"poses_used", c.poses_used},
              {"projector_distortion_model", DistortionModelName(options.projector_distortion)},
              {"camera_distortion_model", DistortionModelName(options.camera_distortion)},
              {"dense_points_per_pose", r.dense_inliers_per_pose},
              {"dense_residuals", r.dense_residuals},
              {"corner_residuals", r.corner_residuals},
              {"initial_camera_rms_px", r.initial_camera_rms_px},
              {"initial_projector_rms_px", r.initial_projector_rms_px},
              {"termination", r.termination},
              {"iterations", r.iterations},
              {"covariance_ok", r.covariance_ok},
              {"covariance_message", r.covariance_message},
              {"camera_std", Deviations(r.camera_std)},
              {"projector_std", Deviations(r.projector_std)},
              {"calibration_time_s", r.compute_time.count()}};
  if (cross_validate) {
    Expected<CrossValidationReport> cv = LeaveOnePoseOut(*poses, options);
    if (!cv.ok()) {
      std::cerr << "calibrate-unit: cross-validation: " << cv.status().ToString() << "\n";
      report["heldout_projector_rms_px"] = nullptr;
      report["heldout_camera_rms_px"] = nullptr;
      report["heldout_error"] = cv.status().ToString();
    } else {
      report["heldout_projector_rms_px"] = cv->heldout_projector_rms_px;
      report["heldout_camera_rms_px"] = cv->heldout_camera_rms_px;
      report["heldout_worst_projector_rms_px"] = cv->worst_projector_rms_px;
      Json folds = Json::array();
      for (const CrossValidationFold& f : cv->folds) {
        folds.push_back({{"heldout_pose", f.heldout.pose},
                         {"projector_rms_px", f.heldout.projector_rms_px},
                         {"projector_rms_all_px", f.heldout.projector_rms_all_px},
                         {"projector_points", f.heldout.projector_points},
                         {"projector_candidates", f.heldout.projector_candidates},
                         {"camera_rms_px", f.heldout.camera_rms_px},
                         {"camera_fx_px", f.calibration.camera.fx_px},
                         {"projector_fx_px", f.calibration.projector.fx_px},
                         {"projector_fy_px", f.calibration.projector.fy_px},
                         {"projector_cx_px", f.calibration.projector.cx_px},
                         {"projector_cy_px", f.calibration.projector.cy_px},
                         {"baseline_m", f.calibration.projector_from_camera.translation.norm()}});
      }
      report["heldout_folds"] = folds;
    }
  } else {
    report["heldout_projector_rms_px"] = nullptr;
    report["heldout_camera_rms_px"] = nullptr;
  }
  report["compute_time_s"] = Seconds(std::chrono::steady_clock::now() - start).count();
  std::ofstream out(report_path);
  out << report.dump(2) << "\n";
  out.close();
  if (!out) {
    std::cerr << "calibrate-unit: " << report_path << ": cannot write the report\n";
    return 1;
  }
  return 0;
}

}  // namespace sandtable::node
