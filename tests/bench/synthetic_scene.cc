#include "tests/bench/synthetic_scene.h"

#include <cmath>

#include "common/base/check.h"
#include "common/base/units.h"

namespace sandtable::bench {

CameraModel BenchCamera() { return CameraModel(1280, 800, 1400.0, 1400.0, 652.0, 391.0); }

Rigid3d CameraLookingAtTable(double distance_m, double tilt_deg) {
  const double tilt_rad = DegToRad(tilt_deg);
  const Eigen::Vector3d centre_in_table(0.0, -distance_m * std::sin(tilt_rad),
                                        distance_m * std::cos(tilt_rad));
  // Rows of camera_from_table's rotation: the camera axes in table coordinates.
  const Eigen::Vector3d z_axis = -centre_in_table.normalized();
  const Eigen::Vector3d x_axis = Eigen::Vector3d::UnitX();
  const Eigen::Vector3d y_axis = z_axis.cross(x_axis);
  Eigen::Matrix3d rotation;
  rotation.row(0) = x_axis;
  rotation.row(1) = y_axis;
  rotation.row(2) = z_axis;
  return Rigid3d(rotation, -rotation * centre_in_table);
}

Status PointDataOptions::Check() const {
  if (num_points < 1 || !(noise_px >= 0.0) || !(half_extent_m > 0.0) || !(z_spread_m >= 0.0) ||
      !(outlier_ratio >= 0.0 && outlier_ratio <= 1.0)) {
    return InvalidArgumentError(
        "point data: num_points >= 1, noise >= 0, half extent > 0, z spread >= 0, outlier "
        "ratio in [0, 1]");
  }
  return OkStatus();
}

PointData MakePointData(const CameraModel& camera, const Rigid3d& camera_from_table,
                        const PointDataOptions& options) {
  ST_CHECK(options.Check().ok()) << options.Check().ToString();
  std::mt19937_64 rng(options.seed);
  std::uniform_real_distribution<double> xy(-options.half_extent_m, options.half_extent_m);
  std::uniform_real_distribution<double> z(0.0, 1.0);
  std::uniform_real_distribution<double> u(-0.5, camera.width_px - 0.5);
  std::uniform_real_distribution<double> v(-0.5, camera.height_px - 0.5);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  std::normal_distribution<double> noise(0.0, 1.0);
  PointData data;
  int attempts = 0;
  while (static_cast<int>(data.true_px.size()) < options.num_points) {
    ST_CHECK(++attempts < 100 * options.num_points + 1000)
        << "MakePointData: the camera does not see the sampled volume";
    const Eigen::Vector3d x(xy(rng), xy(rng), options.z_spread_m * z(rng));
    const auto pixel = camera.Project(camera_from_table * x);
    if (!pixel.has_value() || !camera.InImage(*pixel)) continue;
    data.points_in_table_m.push_back(x);
    data.true_px.push_back(*pixel);
    const bool outlier = unit(rng) < options.outlier_ratio;
    data.is_outlier.push_back(outlier ? 1 : 0);
    data.observed_px.push_back(
        outlier
            ? Eigen::Vector2d(u(rng), v(rng))
            : Eigen::Vector2d(*pixel + options.noise_px * Eigen::Vector2d(noise(rng), noise(rng))));
  }
  return data;
}

PointData MakePlaneDataFromPixels(const CameraModel& camera, const Rigid3d& camera_from_table,
                                  int num_points, double noise_px, double max_range_m,
                                  uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-0.5, camera.width_px - 0.5);
  std::uniform_real_distribution<double> v(-0.5, camera.height_px - 0.5);
  std::normal_distribution<double> noise(0.0, 1.0);
  const Rigid3d table_from_camera = camera_from_table.Inverse();
  const Eigen::Vector3d centre_in_table = table_from_camera.translation;
  PointData data;
  for (int attempt = 0;
       attempt < 200 * num_points && static_cast<int>(data.true_px.size()) < num_points;
       ++attempt) {
    const Eigen::Vector2d pixel(u(rng), v(rng));
    const Expected<Eigen::Vector3d> ray = camera.Unproject(pixel);
    if (!ray.ok()) continue;
    const Eigen::Vector3d direction_in_table = table_from_camera.rotation * *ray;
    if (!(direction_in_table.z() < 0.0)) continue;  // above the horizon
    const double s = -centre_in_table.z() / direction_in_table.z();
    const Eigen::Vector3d hit = centre_in_table + s * direction_in_table;
    if ((hit - centre_in_table).norm() > max_range_m) continue;
    data.points_in_table_m.push_back(Eigen::Vector3d(hit.x(), hit.y(), 0.0));
    data.true_px.push_back(pixel);
    data.is_outlier.push_back(0);
    data.observed_px.push_back(pixel + noise_px * Eigen::Vector2d(noise(rng), noise(rng)));
  }
  return data;
}

std::vector<Eigen::Vector2d> XyOf(const std::vector<Eigen::Vector3d>& points) {
  std::vector<Eigen::Vector2d> xy;
  xy.reserve(points.size());
  for (const Eigen::Vector3d& p : points) xy.emplace_back(p.x(), p.y());
  return xy;
}

}  // namespace sandtable::bench
