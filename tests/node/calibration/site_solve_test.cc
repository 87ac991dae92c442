// SolveSite (node/calibration/site_solve.h), the one solve the runner and the in-process
// harness share: the planar path, its fall-back to the full path, and bad options refused.
#include <algorithm>
#include <string>

#include <gtest/gtest.h>

#include "common/scene/procedural_scene.h"
#include "node/calibration/site_solve.h"
#include "sim/site/site_presets.h"
#include "tests/testing/self_calibration_sim.h"

namespace sandtable {
namespace {

// The observations of flat-4 (four units over a flat table), as the runner would collect them.
node::ClusterObservations Flat4Observations() {
  Expected<sim::Site> site = sim::MakeSitePreset("flat-4");
  EXPECT_TRUE(site.ok());
  ProceduralSceneOptions flat;
  flat.preset = ScenePreset::kFlat;
  Expected<ProceduralScene> scene = MakeProceduralScene(flat);
  EXPECT_TRUE(scene.ok());
  node::ClusterObservations observations;
  testing::SimCalibrationOptions options;
  options.planar_path = true;
  options.metric_samples = 2000;
  options.observations_out = &observations;
  Expected<testing::SimCalibrationResult> r =
      testing::RunSimCalibration(*site, scene->scene, options);
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  return observations;
}

bool HasNote(const node::ClusterSolution& s, const std::string& part) {
  return std::any_of(s.notes.begin(), s.notes.end(),
                     [&](const std::string& n) { return n.find(part) != std::string::npos; });
}

TEST(SiteSolve, PlanarPathFallsBackToTheFullPathWhenItFails) {
  const node::ClusterObservations observations = Flat4Observations();
  ASSERT_EQ(observations.units.size(), 4u);
  const std::map<NodeId, node::LocalGeometry> local = node::LocalGeometries(observations);
  EXPECT_EQ(local.size(), 4u);
  const NodeId root = observations.units.begin()->first;
  node::SiteSolveOptions options;

  Expected<node::SiteSolveResult> planar =
      node::SolveSite(root, observations, local, nullptr, node::SitePath::kPlanar, options);
  ASSERT_TRUE(planar.ok()) << planar.status().ToString();
  EXPECT_EQ(planar->path, node::SitePath::kPlanar);
  EXPECT_FALSE(planar->fell_back);
  EXPECT_TRUE(planar->solution.planar);
  EXPECT_EQ(planar->solution.calibrations.size(), 4u);

  // No camera's plane can be fitted with more points than any camera saw: the planar solve
  // fails, and the full path solves from the same observations.
  options.planar.planarity.min_points = 1000000;
  Expected<node::SiteSolveResult> fallen =
      node::SolveSite(root, observations, local, nullptr, node::SitePath::kPlanar, options);
  ASSERT_TRUE(fallen.ok()) << fallen.status().ToString();
  EXPECT_TRUE(fallen->fell_back);
  EXPECT_EQ(fallen->path, node::SitePath::kFull);
  EXPECT_TRUE(HasNote(fallen->solution, "planar path failed"));
  EXPECT_EQ(fallen->solution.calibrations.size(), 4u);
}

TEST(SiteSolve, RefusesBadOptionsAndEmptyObservations) {
  node::SiteSolveOptions bad;
  bad.planar.min_shared_cells = 0;
  Expected<node::SiteSolveResult> refused =
      node::SolveSite(1, {}, {}, nullptr, node::SitePath::kPlanar, bad);
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kInvalidArgument);
  Expected<node::SiteSolveResult> empty =
      node::SolveSite(1, {}, {}, nullptr, node::SitePath::kPlanar, node::SiteSolveOptions{});
  EXPECT_FALSE(empty.ok());
}

}  // namespace
}  // namespace sandtable
