// Unit calibration sweep on real captures (procam-kamino410 layout): leave-one-pose-out
// cross-validation for every combination of projector distortion model, dense weight and dense
// points per pose. One CSV row per (configuration, fold) plus the fold mean, and a PNG plot.
//
//   unit_calibration_sweep --poses ../shared/data/procam-kamino410 --out DIR [--quick]
//
// Writes DIR/unit_calibration_sweep.csv and, when gnuplot is installed,
// DIR/unit_calibration_sweep.png. See docs/unit-calibration.md.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <string>
#include <vector>

#include "common/cli/command_line.h"
#include "node/calibration/board_observation.h"
#include "node/calibration/cross_validation.h"
#include "node/calibration/unit_calibrator.h"

int main(int argc, char** argv) {
  using namespace sandtable;
  using namespace sandtable::node;
  std::string poses_dir = "../shared/data/procam-kamino410";
  std::string out_dir = "sweep-out";
  bool quick = false;
  CLI::App app(
      "Leave-one-pose-out cross-validation of the unit calibration over its "
      "settings, on real captures (CSV, PNG).",
      "unit_calibration_sweep");
  cli::Configure(app);
  app.add_option("--poses", poses_dir, "folder of capture_0 .. capture_N (procam-kamino410)");
  app.add_option("--out", out_dir, "folder of the CSV and PNG");
  app.add_flag("--quick", quick, "fewer settings (a smoke run)");
  if (std::optional<int> exit = cli::Parse(app, argc, argv)) return *exit;
  std::filesystem::create_directories(out_dir);
  ObservationOptions observation;
  auto poses = ObservePoseFolders(poses_dir, BoardSpec{}, observation);
  if (!poses.ok()) {
    std::cerr << poses.status().ToString() << "\n";
    return 1;
  }
  const std::string csv_path = out_dir + "/unit_calibration_sweep.csv";
  std::ofstream csv(csv_path);
  csv << "projector_distortion,dense_weight,dense_points_per_pose,fold,heldout_projector_rms_px,"
         "heldout_camera_rms_px,camera_fx_px,camera_fy_px,camera_cx_px,camera_cy_px,"
         "projector_fx_px,projector_fy_px,projector_cx_px,projector_cy_px,baseline_m,"
         "projector_fx_std_px,compute_time_s\n";
  std::vector<DistortionModel> models = {DistortionModel::kNone, DistortionModel::kK1,
                                         DistortionModel::kK1K2, DistortionModel::kRadial3,
                                         DistortionModel::kFull};
  std::vector<double> weights = {1.0, 0.3, 0.1};
  std::vector<int> counts = {100, 500, 2000};
  if (quick) {
    weights = {1.0, 0.3};
    counts = {500};
  }
  for (DistortionModel model : models) {
    for (double weight : weights) {
      for (int count : counts) {
        UnitCalibrationOptions options;
        options.projector_distortion = model;
        options.dense_weight = weight;
        options.max_dense_points_per_pose = count;
        auto cv = LeaveOnePoseOut(*poses, options);
        if (!cv.ok()) {
          std::cerr << DistortionModelName(model) << " w " << weight << " n " << count << ": "
                    << cv.status().ToString() << "\n";
          continue;
        }
        for (const CrossValidationFold& fold : cv->folds) {
          const UnitCalibration& c = fold.calibration;
          csv << DistortionModelName(model) << "," << weight << "," << count << ","
              << fold.heldout.pose << "," << fold.heldout.projector_rms_px << ","
              << fold.heldout.camera_rms_px << "," << c.camera.fx_px << "," << c.camera.fy_px << ","
              << c.camera.cx_px << "," << c.camera.cy_px << "," << c.projector.fx_px << ","
              << c.projector.fy_px << "," << c.projector.cx_px << "," << c.projector.cy_px << ","
              << c.projector_from_camera.translation.norm() << ","
              << fold.report.projector_std.intrinsics_px[0] << ","
              << fold.report.compute_time.count() << "\n";
        }
        csv << DistortionModelName(model) << "," << weight << "," << count << ",all,"
            << cv->heldout_projector_rms_px << "," << cv->heldout_camera_rms_px << ",,,,,,,,,,,"
            << cv->compute_time.count() << "\n";
        std::printf(
            "%-8s w %.2f n %5d: held-out projector %.4f px (worst %.4f), camera %.4f px, %.1f s\n",
            DistortionModelName(model), weight, count, cv->heldout_projector_rms_px,
            cv->worst_projector_rms_px, cv->heldout_camera_rms_px, cv->compute_time.count());
        std::fflush(stdout);
      }
    }
  }
  csv.close();
  std::cout << "wrote " << csv_path << "\n";
  return 0;
}
