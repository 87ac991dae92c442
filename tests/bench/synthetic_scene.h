// Synthetic ground truth shared by bench_estimation and sandtable_numerics_sweep: a camera
// above the table, 3D points on and above the table, their true and noisy pixels.
//
// Frames: table frame (z up, metres), camera frame OpenCV (x right, y down, z forward).
// Noise: isotropic Gaussian, sigma noise_px per axis. Everything is deterministic per seed.
#pragma once

#include <cstdint>
#include <random>
#include <vector>

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"

namespace sandtable::bench {

// A 1280x800 camera, fx = 1400 px, principal point off centre, no distortion.
CameraModel BenchCamera();

// A camera distance_m from the table origin, looking at it, tilted tilt_deg from the table
// normal about the table x axis (0 = straight down). Its image x axis is the table +x axis.
Rigid3d CameraLookingAtTable(double distance_m, double tilt_deg);

struct PointData {
  std::vector<Eigen::Vector3d> points_in_table_m;
  std::vector<Eigen::Vector2d> true_px;      // exact projections
  std::vector<Eigen::Vector2d> observed_px;  // true_px + noise (or an outlier)
  std::vector<char> is_outlier;
};

struct PointDataOptions {
  int num_points = 100;
  double noise_px = 0.0;
  double half_extent_m = 0.6;  // x, y uniform in [-half, half]
  double z_spread_m = 0.3;     // z uniform in [0, z_spread_m] (0: all on the table)
  double outlier_ratio = 0.0;  // fraction replaced by a uniform pixel anywhere in the image
  uint64_t seed = 0;
  Status Check() const;
};

// Points whose true projection lies in the image (rejection sampling; ST_CHECKs that the
// camera sees the sampled volume).
PointData MakePointData(const CameraModel& camera, const Rigid3d& camera_from_table,
                        const PointDataOptions& options);

// Points on the table plane z = 0 seen through every pixel of a grid over the image (rays that
// miss the plane or hit it farther than max_range_m are skipped), for grazing views.
PointData MakePlaneDataFromPixels(const CameraModel& camera, const Rigid3d& camera_from_table,
                                  int num_points, double noise_px, double max_range_m,
                                  uint64_t seed);

// (x, y) of table points (their plane coordinates for homographies).
std::vector<Eigen::Vector2d> XyOf(const std::vector<Eigen::Vector3d>& points);

}  // namespace sandtable::bench
