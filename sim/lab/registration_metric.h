// The registration metric of the site lab (../shared/DESIGN.md "Metrics", docs/lab.md), computed
// on the lab's side with the world's ground truth. Nodes never see any of this.
//
// Definition. Points X are sampled on the model's surfaces where the model truly stands
// (area-weighted over every triangle, seeded). For each projector i that truly lights X
// (World::ProjectorTruthAtPoint: the projector's first surface towards X is X, inside its
// image) at an incidence angle under `max_incidence_deg`:
//   X_model = model_from_table_true * X
//   u_hat   = projector_est.Project(projector_from_table_est * table_from_model_est * X_model)
//             (the node's EXPORTED calibration: intrinsics with distortion, its
//             table_from_projector estimate and its estimate of where the model stands, so an
//             error in finding the model counts)
//   u_true  = projector_true.Project(projector_from_table_true * X)
//   X'      = the TRUE ray of projector i through u_hat (true intrinsics and distortion, true
//             pose) intersected with the PLANE of the triangle holding X (so that crossing an
//             edge does not turn a small error into a jump)
//   error   = |X' - X| in mm and |u_hat - u_true| in projector px.
// Samples where u_hat cannot be formed (X behind the estimated projector or past the fold of
// its distortion), where the true model cannot unproject u_hat, or where the true ray misses
// the plane (parallel, or the plane behind the projector) are counted as `unmeasured`, never
// silently dropped.
//
// Table and building faces are told apart geometrically, independently of materials or of how
// the calibration was made: a triangle whose three vertices lie within
// `table_height_tolerance_m` of z = 0 and whose counter-clockwise normal has z above
// `table_normal_min_z` is table; every other triangle is building.
//
// Frames: table frame (metres, +z up); the model frame is the glTF model's own frame converted
// to z-up (docs/frames.md). Failure: INVALID_ARGUMENT for bad options, an estimate naming a
// unit the site does not have, or a scene without triangles of positive area.
// Cost: one ray cast per sample and projector (Embree), plus one unprojection per lit pair.
#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "common/camera/camera_model.h"
#include "common/geometry/rigid3.h"
#include "sim/transport/world.h"

namespace sandtable::sim {

// What the metric reads of a unit's exported calibration (whatever made it).
struct EstimatedRegistration {
  NodeId unit_id = kInvalidNodeId;
  CameraModel projector;                           // intrinsics incl. distortion
  Rigid3d table_from_projector;                    // the node's estimate
  Rigid3d table_from_model = Rigid3d::Identity();  // the node's estimate
};

struct RegistrationMetricOptions {
  int num_samples = 40000;  // candidate surface points (area-weighted over all triangles)
  uint64_t seed = 1;
  double max_incidence_deg = 84.0;
  double table_height_tolerance_m = 1e-4;
  double table_normal_min_z = 0.999;
  // Where the model truly stands (identity: the world's scene is the glTF as written).
  Rigid3d true_table_from_model = Rigid3d::Identity();
  bool keep_samples = true;  // fill RegistrationReport::samples
  Status Check() const;
};

enum class SurfaceClass { kTable, kBuilding };

// One (point, projector) pair.
struct RegistrationSample {
  NodeId unit_id = kInvalidNodeId;
  int triangle = -1;
  SurfaceClass surface = SurfaceClass::kTable;
  Eigen::Vector3d point_in_table_m = Eigen::Vector3d::Zero();    // X (truth)
  Eigen::Vector3d hit_in_table_m = Eigen::Vector3d::Zero();      // X'
  Eigen::Vector2d true_pixel_px = Eigen::Vector2d::Zero();       // u_true
  Eigen::Vector2d estimated_pixel_px = Eigen::Vector2d::Zero();  // u_hat
  double error_mm = 0.0;
  double error_px = 0.0;
};

struct ErrorStats {
  int count = 0;
  double rms_mm = 0.0, p99_mm = 0.0, max_mm = 0.0, mean_mm = 0.0;
  double rms_px = 0.0, p99_px = 0.0, max_px = 0.0;
  // From the errors of `samples` (all pairs given); count = 0 gives zeros.
  static ErrorStats From(const std::vector<double>& errors_mm,
                         const std::vector<double>& errors_px);
};

struct RegistrationErrors {
  ErrorStats all, table, buildings;
  int unmeasured = 0;
};

struct RegistrationReport {
  int num_candidates = 0;       // points sampled on the surfaces
  int num_lit_points = 0;       // of which at least one projector lights at incidence < max
  int num_table_points = 0;     // lit points on table faces
  int num_building_points = 0;  // lit points on building faces
  RegistrationErrors site;      // all (point, projector) pairs pooled
  std::map<NodeId, RegistrationErrors> per_unit;  // every estimated unit
  std::vector<RegistrationSample> samples;        // when options.keep_samples
};

// Classification of one triangle (see the header comment).
SurfaceClass ClassifyTriangle(const Scene& scene, int triangle,
                              const RegistrationMetricOptions& options);

// The metric at one surface point X (on the plane through X with unit normal
// `plane_normal_in_table`) for one projector: nullopt when unmeasurable (see above).
// Lighting is not checked here.
std::optional<RegistrationSample> RegistrationErrorAt(const ProjectorSpec& truth,
                                                      const EstimatedRegistration& estimate,
                                                      const Rigid3d& true_table_from_model,
                                                      const Eigen::Vector3d& point_in_table_m,
                                                      const Eigen::Vector3d& plane_normal_in_table);

// The q-quantile of `values` (nearest rank: the smallest value with at least q of the values at
// or below); 0 for none. Every percentile the lab reports.
double Quantile(std::vector<double> values, double q);

// The metric over the site for every estimate (site units without an estimate are skipped).
Expected<RegistrationReport> MeasureRegistration(
    const World& world, const std::vector<EstimatedRegistration>& estimates,
    const RegistrationMetricOptions& options = {});

}  // namespace sandtable::sim

namespace sandtable::sim {

// The model's estimated placement against the truth. The nodes' table frame is their own (the
// table-frame rule of docs/frames.md), so it is first related to the true table frame through
// what the nodes measured: for every unit, projector pixels on a grid (every grid_step_px) are
// cast through the ESTIMATED projector onto the estimated table plane z = 0 and through the
// TRUE projector onto the true surface; pixels whose true hit lies on a table face give point
// pairs, and a rigid fit (Umeyama) of all pairs gives true_table_from_estimated_table. Then
//   offset_mm  = |true_from_est * table_from_model_est * c - true_table_from_model * c|
//                at the model's centre c (model frame), and
//   offset_deg = the angle of the rotation between the two placements.
struct ModelPlacementError {
  double offset_mm = 0.0;
  double offset_deg = 0.0;
  double frame_fit_rms_mm = 0.0;  // residual of the table-frame fit
  int pairs = 0;
  Rigid3d true_table_from_estimated_table;
};
// Errors: DEGENERATE when fewer than 10 pixel pairs land on the table.
Expected<ModelPlacementError> MeasureModelPlacement(
    const World& world, const std::vector<EstimatedRegistration>& estimates,
    const Rigid3d& true_table_from_model, const Eigen::Vector3d& model_centre_in_model_m,
    int grid_step_px = 32);

}  // namespace sandtable::sim
