#include "coordinator/tracker/tracker_calibration.h"

#include <cmath>
#include <sstream>

#include "common/base/units.h"
#include "common/estimation/umeyama.h"
#include "common/io/json_codec.h"
#include "common/io/json_reader.h"
#include "coordinator/tracker/replay_source.h"

namespace sandtable::coordinator {

std::vector<Eigen::Vector3d> GridCalibrationTargets(int n, double extent_m) {
  ST_CHECK(n >= 2 && extent_m > 0.0) << "GridCalibrationTargets: n >= 2 and extent_m > 0";
  std::vector<Eigen::Vector3d> out;
  for (int row = 0; row < n; ++row) {
    for (int col = 0; col < n; ++col) {
      out.emplace_back(extent_m * (col / (n - 1.0) - 0.5), extent_m * (row / (n - 1.0) - 0.5), 0.0);
    }
  }
  return out;
}

Status TrackerCalibrationOptions::Check() const {
  if (!(outlier_threshold_mm > 0.0)) {
    return InvalidArgumentError("tracker calibration: outlier_threshold_mm must be > 0");
  }
  if (min_inliers < 3) return InvalidArgumentError("tracker calibration: min_inliers must be >= 3");
  return OkStatus();
}

namespace {

struct Fit {
  Rigid3d rigid;
  double scale = 1.0;
  double spread = 0.0;
};

Expected<Fit> FitOnce(const std::vector<Eigen::Vector3d>& tips,
                      const std::vector<Eigen::Vector3d>& targets, bool similarity) {
  Fit fit;
  if (similarity) {
    Expected<SimilarityFitReport> r = FitSimilarityUmeyama(tips, targets);
    if (!r.ok()) return r.status();
    fit.scale = r->target_from_source.scale;
    fit.rigid = Rigid3d(r->target_from_source.rotation, r->target_from_source.translation);
    fit.spread = r->source_spread_ratio;
  } else {
    Expected<RigidFitReport> r = FitRigidUmeyama(tips, targets);
    if (!r.ok()) return r.status();
    fit.rigid = r->target_from_source;
    fit.spread = r->source_spread_ratio;
  }
  return fit;
}

}  // namespace

Expected<TrackerCalibrationReport> FitTableFromTracker(
    const std::vector<Eigen::Vector3d>& tips_in_tracker_m,
    const std::vector<Eigen::Vector3d>& targets_in_table_m,
    const TrackerCalibrationOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  if (tips_in_tracker_m.size() != targets_in_table_m.size()) {
    return InvalidArgumentError("tracker calibration: " + std::to_string(tips_in_tracker_m.size()) +
                                " tips for " + std::to_string(targets_in_table_m.size()) +
                                " targets");
  }
  Expected<Fit> fit = FitOnce(tips_in_tracker_m, targets_in_table_m, options.similarity);
  if (!fit.ok()) return fit.status().WithContext("tracker calibration");
  const size_t n = tips_in_tracker_m.size();
  auto residual_mm = [&](const Fit& f, size_t i) {
    const Eigen::Vector3d mapped =
        f.rigid.rotation * (f.scale * tips_in_tracker_m[i]) + f.rigid.translation;
    return MToMm((mapped - targets_in_table_m[i]).norm());
  };
  TrackerCalibrationReport report;
  report.outlier.assign(n, false);
  // Leave out the worst point while any inlier is beyond the threshold, refitting each time
  // (one gross error drags the all-points fit by ~error / N, enough to push good points over
  // the threshold, so points are removed one at a time, worst first).
  std::vector<Eigen::Vector3d> tips, targets;
  while (true) {
    size_t worst = n;
    double worst_mm = options.outlier_threshold_mm;
    for (size_t i = 0; i < n; ++i) {
      if (report.outlier[i]) continue;
      const double r = residual_mm(*fit, i);
      if (r > worst_mm) {
        worst_mm = r;
        worst = i;
      }
    }
    if (worst == n) break;
    report.outlier[worst] = true;
    tips.clear();
    targets.clear();
    for (size_t i = 0; i < n; ++i) {
      if (report.outlier[i]) continue;
      tips.push_back(tips_in_tracker_m[i]);
      targets.push_back(targets_in_table_m[i]);
    }
    if (static_cast<int>(tips.size()) < options.min_inliers) {
      return DegenerateError("tracker calibration: only " + std::to_string(tips.size()) + " of " +
                             std::to_string(n) + " points within " +
                             std::to_string(options.outlier_threshold_mm) +
                             " mm of the fit; repeat the calibration (is the tip offset right?)");
    }
    fit = FitOnce(tips, targets, options.similarity);
    if (!fit.ok()) return fit.status().WithContext("tracker calibration refit");
  }
  report.table_from_tracker = fit->rigid;
  report.scale = fit->scale;
  report.source_spread_ratio = fit->spread;
  double sum2 = 0.0;
  for (size_t i = 0; i < n; ++i) {
    report.residuals_mm.push_back(residual_mm(*fit, i));
    if (report.outlier[i]) continue;
    sum2 += report.residuals_mm[i] * report.residuals_mm[i];
    report.max_inlier_mm = std::max(report.max_inlier_mm, report.residuals_mm[i]);
    ++report.num_inliers;
  }
  report.rms_mm = std::sqrt(sum2 / report.num_inliers);
  std::ostringstream m;
  m << "table_from_tracker from " << report.num_inliers << "/" << n << " points, rms "
    << report.rms_mm << " mm, max " << report.max_inlier_mm << " mm";
  if (report.num_inliers < static_cast<int>(n)) {
    m << "; outliers:";
    for (size_t i = 0; i < n; ++i) {
      if (report.outlier[i]) m << " #" << i << " (" << report.residuals_mm[i] << " mm)";
    }
  }
  report.message = m.str();
  return report;
}

nlohmann::json TableFromTrackerToJson(const Rigid3d& table_from_tracker) {
  return {{"format", kTableFromTrackerFormat},
          {"version", kTableFromTrackerVersion},
          {"table_from_tracker", io::RigidToJson(table_from_tracker)}};
}

Status SaveTableFromTracker(const Rigid3d& table_from_tracker, const std::string& path) {
  if (!table_from_tracker.AllFinite()) {
    return InvalidArgumentError(path + ": table_from_tracker is not finite");
  }
  return io::WriteJsonFile(TableFromTrackerToJson(table_from_tracker), path);
}

namespace {

// A translation past kMaxTrackerCoordinate_m would carry every wand ray out of any scene (and
// into the ray caster's range checks): refused naming the field.
Status CheckTranslationRange(const Rigid3d& table_from_tracker, const std::string& where) {
  if (!table_from_tracker.AllFinite() ||
      table_from_tracker.translation.cwiseAbs().maxCoeff() > kMaxTrackerCoordinate_m) {
    return ParseError(where +
                      " table_from_tracker.translation_m: beyond kMaxTrackerCoordinate_m (" +
                      std::to_string(kMaxTrackerCoordinate_m) + " m per axis)");
  }
  return OkStatus();
}

}  // namespace

Expected<Rigid3d> TableFromTrackerFromJson(const nlohmann::json& json, std::string_view source) {
  const std::string where = std::string(source) + ":";
  io::ObjectReader root(json, where);
  ST_RETURN_IF_ERROR(root.Begin());
  if (!root.Has("format")) {
    // The older file: the transform itself, {"rotation_wxyz": [w, x, y, z], "translation_m"}.
    Expected<Rigid3d> old_file = io::RigidFromJson(json, where);
    if (!old_file.ok()) return old_file.status();
    ST_RETURN_IF_ERROR(CheckTranslationRange(*old_file, where));
    return *old_file;
  }
  Expected<int> version = io::ReadFormatVersion(&root, kTableFromTrackerFormat,
                                                kTableFromTrackerVersion, kTableFromTrackerVersion);
  if (!version.ok()) return version.status();
  Expected<Rigid3d> table_from_tracker = io::ReadRigid(&root, "table_from_tracker");
  if (!table_from_tracker.ok()) return table_from_tracker.status();
  ST_RETURN_IF_ERROR(root.End());
  ST_RETURN_IF_ERROR(CheckTranslationRange(*table_from_tracker, where));
  return *table_from_tracker;
}

Expected<Rigid3d> LoadTableFromTracker(const std::string& path) {
  Expected<nlohmann::json> json = io::ReadJsonFile(path);
  if (!json.ok()) return json.status();
  return TableFromTrackerFromJson(*json, path);
}

TrackerCalibrationSession::TrackerCalibrationSession(std::vector<Eigen::Vector3d> targets,
                                                     Eigen::Vector3d tip_in_sensor_m)
    : targets_(std::move(targets)), tip_in_sensor_m_(tip_in_sensor_m) {}

bool TrackerCalibrationSession::OnSample(const TrackerSample& sample) {
  if (done()) return false;
  if (sample.button_pressed) {
    sum_ += sample.tracker_from_sensor * tip_in_sensor_m_;
    ++count_;
    return false;
  }
  if (count_ == 0) return false;
  tips_.push_back(sum_ / count_);  // released: the target is done
  sum_.setZero();
  count_ = 0;
  ++next_;
  return true;
}

}  // namespace sandtable::coordinator
