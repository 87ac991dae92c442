#include "node/calibration/calibrate_unit_command.h"

#include <chrono>
#include <cmath>
#include <iostream>
#include <limits>

#include <nlohmann/json.hpp>

#include "common/base/file_io.h"
#include "common/base/units.h"
#include "common/cli/command_line.h"
#include "node/calibration/board_observation.h"
#include "node/calibration/cross_validation.h"
#include "node/calibration/unit_calibration.h"
#include "node/calibration/unit_calibrator.h"

namespace sandtable::node {
namespace {

using Json = nlohmann::json;

CLI::Validator DistortionModelValidator() {
  return CLI::Validator(
      [](std::string& value) {
        Expected<DistortionModel> model = ParseDistortionModel(value);
        return model.ok() ? std::string() : model.status().message();
      },
      "none|k1|k1k2|radial3|full", "DistortionModel");
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
  std::string projector_distortion = DistortionModelName(options.projector_distortion);
  std::string camera_distortion = DistortionModelName(options.camera_distortion);

  CLI::App app(
      "The factory calibration of one unit (camera, projector, projector_from_camera) from "
      "chessboard poses with their Gray-code captures (docs/unit-calibration.md).",
      "sandtable-node calibrate-unit");
  cli::Configure(app);
  app.add_option("--poses", poses_dir,
                 "folder of capture_0 .. capture_N, each with graycode_00.png .. (OpenCV "
                 "GrayCodePattern order)")
      ->required();
  app.add_option("-o,--output", output_path, "the unit calibration (JSON) to write")->required();
  app.add_option("--report", report_path,
                 "also write a JSON report (residuals, deviations, "
                 "leave-one-pose-out cross-validation)");
  app.add_option("--board-cols", options.board.inner_cols, "inner corners per chessboard row")
      ->check(cli::Integer(2, 1000));
  app.add_option("--board-rows", options.board.inner_rows, "inner corners per chessboard column")
      ->check(cli::Integer(2, 1000));
  app.add_option("--square-mm", square_mm, "chessboard square side, mm")
      ->check(cli::Real(0.01, 10000.0));
  app.add_option("--projector-width", options.projector_width_px, "projector width, px")
      ->check(cli::Integer(16, 65536));
  app.add_option("--projector-height", options.projector_height_px, "projector height, px")
      ->check(cli::Integer(16, 65536));
  app.add_option("--projector-distortion", projector_distortion, "projector distortion model")
      ->check(DistortionModelValidator());
  app.add_option("--camera-distortion", camera_distortion, "camera distortion model")
      ->check(DistortionModelValidator());
  app.add_option("--dense-points", options.max_dense_points_per_pose,
                 "dense Gray-code points per pose in the joint refinement")
      ->check(cli::Integer(10, 1000000));
  app.add_option("--dense-weight", options.dense_weight,
                 "weight of a dense residual relative to a corner residual")
      ->check(cli::Real(1e-6, 1e6));
  bool no_cross_validation = false;
  app.add_flag("--no-cross-validation", no_cross_validation,
               "skip the leave-one-pose-out cross-validation in the report");
  if (std::optional<int> exit = cli::Parse(app, args)) return *exit;
  cross_validate = !no_cross_validation;
  options.projector_distortion = *ParseDistortionModel(projector_distortion);
  options.camera_distortion = *ParseDistortionModel(camera_distortion);
  options.board.square_m = MmToM(square_mm);
  observation.patterns =
      PatternOptions::OpenCvGrayCode(options.projector_width_px, options.projector_height_px);
  if (Status valid = options.Check(); !valid.ok()) return cli::UsageError(app, valid.message());

  Expected<std::vector<PoseObservation>> poses =
      ObservePoseFolders(poses_dir, options.board, observation);
  if (!poses.ok()) {
    std::cerr << "calibrate-unit: " << poses.status().ToString() << "\n";
    // A folder or frame that cannot be read (missing, not a regular file, too large) is bad
    // input; a failed observation is a run-time failure.
    const StatusCode code = poses.status().code();
    return code == StatusCode::kIoError || code == StatusCode::kNotFound ? cli::kExitUsage : 1;
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
  // All or nothing: a full disk leaves the previous report and exits 1.
  if (Status written = WriteFileAtomically(report_path, report.dump(2) + "\n"); !written.ok()) {
    std::cerr << "calibrate-unit: cannot write the report: " << written.message() << "\n";
    return 1;
  }
  return 0;
}

}  // namespace sandtable::node
