// The cluster self-calibration end to end in one process against the simulated world
// (tests/testing/self_calibration_sim.h): sandtable-3 with factory errors and noise, the model
// at an unknown placement, one of its buildings missing from the table and one moved by 1 cm;
// the registration metric of the lab on the result.
#include <cmath>
#include <iostream>
#include <map>
#include <vector>

#include <gtest/gtest.h>

#include "common/scene/procedural_scene.h"
#include "node/calibration/cluster_bundle.h"
#include "node/calibration/cluster_solver.h"
#include "sim/site/site_presets.h"
#include "tests/testing/self_calibration_sim.h"

namespace sandtable {
namespace {

// The acceptance figures (docs/calibration.md gives the measured values).
constexpr double kMaxRms_mm = 0.3;
constexpr double kMaxRms_px = 0.25;
constexpr double kMaxError_mm = 1.5;
constexpr double kModelOffset_mm = 0.3;
constexpr double kModelOffset_deg = 0.05;
constexpr double kMoveTolerance_mm = 1.0;
// A unit's initial pose this far off (rotation about its own centre) loses most tracks.
constexpr double kOffDeg = 0.3;
// This far off, a resection from the other units' points (posed by a solve that lacked this
// unit's camera) brings it back to within these of its solved pose; solving again from there
// brings its tracks in.
constexpr double kFarOffDeg = 3.0;
constexpr double kResectedWithinDeg = 0.5;
constexpr double kResectedWithin_mm = 10.0;
// Tighter than sandtable-3's scan scale error (~0.1 %).
constexpr double kTightScaleCorrection = 1e-4;

// A placement that needs the model scaled further from 1 than max_scale_correction is not
// this model in metres: refused with the reason, the model not placed (before, the placement
// was kept with only its scale dropped, and a false match on a random terrain site put the
// buildings 0.8 m off). sandtable-3's scan is 0.1 % off, over the 0.01 % allowed here.
TEST(ClusterSelfCalibration, RefusesAPlacementWhoseScaleIsTooFarFromOne) {
  Expected<sim::Site> site = sim::MakeSitePreset("sandtable-3");
  ASSERT_TRUE(site.ok());
  Expected<ProceduralScene> scene = MakeProceduralScene({});
  ASSERT_TRUE(scene.ok());
  testing::SimCalibrationOptions options;
  options.seed = 1;
  options.solve.max_scale_correction = kTightScaleCorrection;
  Expected<testing::SimCalibrationResult> r =
      testing::RunSimCalibration(*site, scene->scene, options);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  EXPECT_FALSE(r->solution.model.has_value());
  bool said = false;
  for (const std::string& note : r->solution.notes) {
    said |= note.find("not this model in metres") != std::string::npos;
  }
  EXPECT_TRUE(said);
  EXPECT_EQ(r->solution.scale_correction, 1.0);
}

TEST(ClusterSelfCalibration, Sandtable3ReachesTheAcceptanceFigures) {
  Expected<sim::Site> site = sim::MakeSitePreset("sandtable-3");
  ASSERT_TRUE(site.ok());
  Expected<ProceduralScene> model = MakeProceduralScene({});
  ASSERT_TRUE(model.ok());
  // The table as built: building 2 left out, building 5 moved by 1 cm.
  constexpr int kMissing = 2, kMoved = 5;
  const Eigen::Vector2d move_in_table_m(0.006, 0.008);
  ProceduralSceneOptions physical_options;
  physical_options.remove_buildings = {kMissing};
  physical_options.move_buildings = {{kMoved, move_in_table_m}};
  Expected<ProceduralScene> scene = MakeProceduralScene(physical_options);
  ASSERT_TRUE(scene.ok());
  testing::SimCalibrationOptions options;
  options.seed = 1;
  options.model_from_table =
      Rigid3d(Eigen::AngleAxisd(7.0 * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
              Eigen::Vector3d(0.03, -0.02, 0.0));
  options.model = &model->scene;
  node::ClusterObservations observations;
  options.observations_out = &observations;
  Expected<testing::SimCalibrationResult> r =
      testing::RunSimCalibration(*site, scene->scene, options);
  ASSERT_TRUE(r.ok()) << r.status().ToString();
  ASSERT_EQ(r->solution.calibrations.size(), 3u);
  ASSERT_TRUE(r->solution.model.has_value());
  const auto& m = r->metric.site;
  EXPECT_LT(m.table.rms_mm, kMaxRms_mm);
  EXPECT_LT(m.buildings.rms_mm, kMaxRms_mm);
  EXPECT_LT(m.table.rms_px, kMaxRms_px);
  EXPECT_LT(m.buildings.rms_px, kMaxRms_px);
  EXPECT_LT(m.table.max_mm, kMaxError_mm);
  EXPECT_LT(m.buildings.max_mm, kMaxError_mm);
  EXPECT_LT(r->model_offset_mm, kModelOffset_mm);
  EXPECT_LT(r->model_offset_deg, kModelOffset_deg);
  EXPECT_FALSE(r->solution.planar);

  // The change report, per building of the model (its frame: the move turned by the yaw).
  ASSERT_TRUE(r->solution.changes.has_value());
  const node::ModelChangeReport& changes = *r->solution.changes;
  ASSERT_EQ(changes.parts.size(), model->buildings.size());
  const Eigen::Vector2d move_in_model_m =
      options.model_from_table.RotationMatrix().topLeftCorner<2, 2>() * move_in_table_m;
  for (const node::PartChange& c : changes.parts) {
    if (c.part == kMissing) {
      EXPECT_EQ(c.state, node::PartState::kMissing);
    } else if (c.part == kMoved) {
      EXPECT_EQ(c.state, node::PartState::kMoved);
      EXPECT_NEAR(c.moved_by_m.norm() * 1e3, 10.0, kMoveTolerance_mm);
      EXPECT_LT((c.moved_by_m - move_in_model_m).norm() * 1e3, kMoveTolerance_mm)
          << "found " << c.moved_by_m.transpose() * 1e3 << " mm";
    } else {
      EXPECT_EQ(c.state, node::PartState::kPresent) << "building " << c.part;
    }
  }
  EXPECT_TRUE(changes.extras.empty());

  // A unit whose initial pose is a few pixels off (a long chain of pairwise poses: grid-12)
  // loses most of its tracks to the triangulation check, and the solve barely sees it; solved
  // again from the first solve's poses, it gets them back (SolveCluster does this when a unit is
  // starved).
  std::map<NodeId, Rigid3d> poses;
  for (const auto& [id, c] : r->solution.calibrations) {
    ASSERT_TRUE(c.table_from_projector.has_value());
    poses[id] = c.table_from_projector->Inverse();
  }
  const int at_solution = node::TracksThatTriangulate(observations, poses);
  EXPECT_GT(at_solution, r->solution.bundle.tracks_used * 9 / 10);
  constexpr NodeId kOff = 2;
  std::map<NodeId, Rigid3d> off = poses;
  off[kOff] =
      Rigid3d(
          Eigen::AngleAxisd(kOffDeg * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix(),
          Eigen::Vector3d::Zero()) *
      poses[kOff];
  EXPECT_LT(node::TracksThatTriangulate(observations, off), at_solution * 9 / 10);
  const NodeId root = observations.units.begin()->first;
  Expected<node::BundleResult> first =
      node::AdjustCluster(observations, off, root, node::ClusterSolveOptions{}.bundle);
  ASSERT_TRUE(first.ok()) << first.status().ToString();
  Expected<node::BundleResult> second = node::AdjustCluster(
      observations, first->projector_from_world, root, node::ClusterSolveOptions{}.bundle);
  ASSERT_TRUE(second.ok()) << second.status().ToString();
  const int seen_first = first->report.units[kOff].projector_observations;
  const int seen_second = second->report.units[kOff].projector_observations;
  std::cout << "unit " << kOff << " started " << kOffDeg << " deg off: " << seen_first
            << " projector observations, " << seen_second << " solved again from there ("
            << at_solution << " tracks triangulate at the solution)\n";
  EXPECT_GT(seen_second, 2 * seen_first);
  EXPECT_GT(second->report.tracks_used, first->report.tracks_used);

  // Started far off (grid-32's far units), re-solving does not bring the tracks in; the unit's
  // projector resected from the other units' points does come back to its solved pose.
  std::map<NodeId, Rigid3d> far = poses;
  far[kOff] =
      Rigid3d(
          Eigen::AngleAxisd(kFarOffDeg * M_PI / 180.0, Eigen::Vector3d::UnitY()).toRotationMatrix(),
          Eigen::Vector3d::Zero()) *
      poses[kOff];
  node::ClusterSolveOptions solve;
  // With three units, the one far off also costs the others the points its camera saw (~1 000
  // observations each, against its ~400): starved at half the median, not a quarter.
  solve.bundle_starved_share = 0.5;
  Expected<node::BundleResult> far_solve =
      node::AdjustCluster(observations, far, root, solve.bundle);
  ASSERT_TRUE(far_solve.ok()) << far_solve.status().ToString();
  std::map<NodeId, Rigid3d> resected = far_solve->projector_from_world;
  const std::vector<NodeId> moved =
      node::ResectStarvedUnits(observations, *far_solve, solve, &resected);
  ASSERT_EQ(moved, std::vector<NodeId>{kOff})
      << far_solve->report.units[kOff].projector_observations << " observations";
  const Rigid3d error = resected[kOff] * poses[kOff].Inverse();
  const double angle_deg = Eigen::AngleAxisd(error.RotationMatrix()).angle() * 180.0 / M_PI;
  const double shift_mm =
      (resected[kOff].Inverse().translation - poses[kOff].Inverse().translation).norm() * 1e3;
  std::cout << "unit " << kOff << " started " << kFarOffDeg
            << " deg off: " << far_solve->report.units[kOff].projector_observations
            << " observations; resected to " << angle_deg << " deg, " << shift_mm
            << " mm of its solved pose\n";
  EXPECT_LT(angle_deg, kResectedWithinDeg);
  EXPECT_LT(shift_mm, kResectedWithin_mm);
  Expected<node::BundleResult> after =
      node::AdjustCluster(observations, resected, root, solve.bundle);
  ASSERT_TRUE(after.ok()) << after.status().ToString();
  std::cout << "solved again from the resected pose: "
            << after->report.units[kOff].projector_observations << " observations\n";
  EXPECT_GT(after->report.units[kOff].projector_observations,
            2 * far_solve->report.units[kOff].projector_observations);
  EXPECT_GT(after->report.tracks_used, far_solve->report.tracks_used);
}

}  // namespace
}  // namespace sandtable
