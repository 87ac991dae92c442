// The cluster self-calibration run in one process against a sim::World, for tests and sweeps:
// the same node-side steps the distributed service runs (pre-pass, pattern plan, decode to the
// projector grid, tracks, local geometry, the cluster solve), with the world's devices called
// directly instead of over sockets; then the lab's registration metric on the result.
#pragma once

#include <cstdint>
#include <map>
#include <vector>

#include "common/base/status.h"
#include "common/scene/scene.h"
#include "node/calibration/cluster_solver.h"
#include "node/calibration/planar_solver.h"
#include "node/calibration/site_solve.h"
#include "node/calibration/structured_light_plan.h"
#include "sim/lab/registration_metric.h"
#include "sim/site/factory_calibration.h"
#include "sim/site/site.h"

namespace sandtable::testing {

struct SimCalibrationOptions {
  node::PatternPlanOptions plan;
  ProjectorGridOptions grid;
  node::ClusterSolveOptions solve;
  sim::FactoryCalibrationError factory_error;
  uint64_t seed = 1;
  bool noise = true;
  bool use_model = true;
  // Where the model file places the scene: model_from_table (the lab's seeded unknown
  // placement); the metric gets its inverse as the true table_from_model.
  Rigid3d model_from_table = Rigid3d::Identity();
  // The model the nodes get, before model_from_table moves it: nullptr = the scene itself
  // (else a scene that differs from the physical one: the change report's test).
  const Scene* model = nullptr;
  int metric_samples = 20000;
  // The planar path (node/calibration/planar_solver.h): the Gray frames of each plan only,
  // decoded to cells, solved by SolvePlanarCluster.
  bool planar_path = false;
  bool planar_gray_cells = false;  // with the planar path: Gray frames only, decoded to cells
  node::PlanarSolveOptions planar;
  // When set: the observations the solve was given (the nodes' tracks and factory models).
  node::ClusterObservations* observations_out = nullptr;
  Status Check() const;
};

struct SimCalibrationResult {
  node::ClusterSolution solution;
  std::map<NodeId, int> frames_per_projector;
  std::map<NodeId, double> projector_px_per_camera_px;
  int colours = 0;
  double decode_cpu_s = 0.0;  // all cameras, all decodes (thread CPU)
  int tracks = 0;
  sim::RegistrationReport metric;
  double model_offset_mm = 0.0, model_offset_deg = 0.0;
  // The metric with the TRUE model placement (expressed in the nodes' table frame) in place
  // of the found one: the calibration's own share of the error.
  sim::RegistrationReport metric_true_model;
  bool measured_with_true_placement = false;  // the nodes found no placement
};

Expected<SimCalibrationResult> RunSimCalibration(const sim::Site& site, const Scene& scene,
                                                 const SimCalibrationOptions& options);

}  // namespace sandtable::testing
