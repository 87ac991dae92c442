// Finding the model on the scanned table: a scan of the procedural scene, moved by a known
// placement, is registered back; a scan of another scene is refused.
#include "node/calibration/model_registration.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "common/scene/procedural_scene.h"
#include "common/scene/random_scene.h"

namespace sandtable::node {
namespace {

constexpr double kPlacementTolerance_mm = 0.3;
constexpr double kAngleTolerance_deg = 0.05;
// A flat table placed by its outline: the outline's mask quantisation (4 mm cells, 12 mm points).
constexpr double kOutlinePlacement_mm = 1.0;
constexpr double kOutlineAngle_deg = 0.1;
// The plan's scale from a scan 2 % taller than its plan; the heights' scale over the plan's.
constexpr double kPlanScaleTolerance = 5e-4;
constexpr double kReliefScaleTolerance = 2e-3;
constexpr double kPi = 3.14159265358979323846;
// On terrain found through a tilted plane: the ICP's result from a coarse start on relief maps
// (2 cm cells), noise 0.3 mm.
constexpr double kTerrainPlacement_mm = 1.0;
constexpr double kTerrainAngle_deg = 0.1;

Scene SandtableScene(uint64_t seed) {
  ProceduralSceneOptions o;
  o.seed = seed;
  return MakeProceduralScene(o)->scene;
}

// A scan: surface samples of `scene` seen from above (z-facing or walls), in a disc of radius
// `radius_m` about `centre`, in the table frame x_table = table_from_model * x_model, with
// Gaussian noise of sigma_m per axis; of the walls (normal under 45 degrees from the table) one
// point in `wall_stride` (a camera looking down sees few).
std::vector<Eigen::Vector3d> Scan(const Scene& scene, const Rigid3d& table_from_model,
                                  const Eigen::Vector2d& centre, double radius_m, double sigma_m,
                                  uint64_t seed, int wall_stride = 1) {
  const ModelSurface surface = SampleModelSurface(scene, 0.004);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> n(0.0, sigma_m);
  std::vector<Eigen::Vector3d> out;
  int walls = 0;
  for (size_t i = 0; i < surface.points_m.size(); ++i) {
    const Eigen::Vector3d& p = surface.points_m[i];
    if ((p.head<2>() - centre).norm() > radius_m) continue;
    if (surface.normals[i].z() < -0.1) continue;  // faces down: never seen from above
    if (surface.normals[i].z() < 0.7 && (walls++ % wall_stride) != 0) continue;
    out.push_back(table_from_model * p + Eigen::Vector3d(n(rng), n(rng), n(rng)));
  }
  return out;
}

TEST(ModelRegistration, FindsAnUnknownPlacementWithoutAGuess) {
  const Scene scene = SandtableScene(1);
  // The table frame of a cluster is where its rule put it: any yaw, any offset in the plane.
  const Rigid3d table_from_model(
      Eigen::AngleAxisd(37.0 * kPi / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
      Eigen::Vector3d(0.71, 0.64, 0.0));
  const std::vector<Eigen::Vector3d> scan =
      Scan(scene, table_from_model, Eigen::Vector2d(0.05, -0.02), 0.55, 0.0003, 2);
  ModelRegistrationOptions options;
  options.estimate_scale = false;
  Expected<ModelRegistration> found = RegisterModel(scene, scan, options);
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  const Rigid3d error = table_from_model.Inverse() * found->table_from_model;
  EXPECT_LT(error.translation.norm() * 1e3, kPlacementTolerance_mm);
  EXPECT_LT(Eigen::AngleAxisd(error.rotation).angle() * 180.0 / kPi, kAngleTolerance_deg);
  EXPECT_GT(found->inliers, static_cast<int>(0.9 * found->points));
}

// A table covered by terrain (random:15, the lab's seed whose model was not found): the cluster's
// plane fit took a large slope of the terrain for the table, so its frame is tilted 1.9 degrees
// and lifted against the model's table, and heights over it are not the model's anywhere. The
// model is still found, tilt and all (before: "the model does not match", 42 % of the points).
TEST(ModelRegistration, FindsTheModelOnTerrainWhenTheScansPlaneIsNotTheTable) {
  RandomSceneOptions random;
  random.seed = 15;
  Expected<RandomScene> made = MakeRandomScene(random);
  ASSERT_TRUE(made.ok()) << made.status().ToString();
  ASSERT_GT(made->terrain_max_height_m, 0.0);
  const Scene& scene = made->scene.scene;
  const Eigen::Matrix3d turn =
      (Eigen::AngleAxisd(1.9 * kPi / 180.0, Eigen::Vector3d(0.6, 0.8, 0.0).normalized()) *
       Eigen::AngleAxisd(-12.4 * kPi / 180.0, Eigen::Vector3d::UnitZ()))
          .toRotationMatrix();
  const Rigid3d table_from_model(turn, Eigen::Vector3d(0.68, 0.50, -0.03));
  const Eigen::Vector3d centre = scene.Bounds().center();
  const std::vector<Eigen::Vector3d> scan =
      Scan(scene, table_from_model, centre.head<2>(), 1.0, 0.0003, 3, /*wall_stride=*/4);
  ModelRegistrationOptions options;
  options.estimate_scale = false;
  Expected<ModelRegistration> found = RegisterModel(scene, scan, options);
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  const Rigid3d error = table_from_model.Inverse() * found->table_from_model;
  EXPECT_LT(error.translation.norm() * 1e3, kTerrainPlacement_mm);
  EXPECT_LT(Eigen::AngleAxisd(error.rotation).angle() * 180.0 / kPi, kTerrainAngle_deg);
}

TEST(ModelRegistration, RecoversTheScanScale) {
  const Scene scene = SandtableScene(1);
  const Rigid3d table_from_model(
      Eigen::AngleAxisd(-80.0 * kPi / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
      Eigen::Vector3d(0.2, 0.9, 0.0));
  std::vector<Eigen::Vector3d> scan =
      Scan(scene, table_from_model, Eigen::Vector2d(0.0, 0.0), 0.6, 0.0003, 3);
  const double scale = 1.006;  // the mounts' baselines off by 0.6 %
  for (Eigen::Vector3d& p : scan) p *= scale;
  Expected<ModelRegistration> found = RegisterModel(scene, scan);
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  EXPECT_NEAR(found->scale, scale, 2e-4);
}

// A rig looking down from afar trades focal length against distance: its scan's heights read
// taller than its plan. With scale_from_plan the scale is the plan's, the heights' own reported
// beside it; with one scale, the buildings' roofs and the table (normals along z) set it and
// the plan stays off by the relief's error.
TEST(ModelRegistration, TakesThePlansScaleWhereTheReliefReadsTaller) {
  const Scene scene = SandtableScene(1);
  const Rigid3d table_from_model(
      Eigen::AngleAxisd(25.0 * kPi / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
      Eigen::Vector3d(-0.1, 0.3, 0.0));
  constexpr int kWallStride = 10;  // looking down: one wall point in ten
  std::vector<Eigen::Vector3d> scan =
      Scan(scene, table_from_model, Eigen::Vector2d(0.0, 0.0), 0.6, 0.0003, 4, kWallStride);
  const double plan_scale = 1.006;
  const double relief = 1.02;  // heights 2 % taller than the plan
  for (Eigen::Vector3d& p : scan) {
    p.z() *= relief;
    p *= plan_scale;
  }
  ModelRegistrationOptions options;
  options.scale_from_plan = true;
  Expected<ModelRegistration> found = RegisterModel(scene, scan, options);
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  EXPECT_NEAR(found->scale, plan_scale, kPlanScaleTolerance);
  EXPECT_NEAR(found->relief_scale, relief, kReliefScaleTolerance);
  // The placement in the plan: the model's origin lands where the scan puts it.
  const Eigen::Vector3d origin = found->table_from_model.translation * found->scale;
  EXPECT_LT((origin.head<2>() - plan_scale * table_from_model.translation.head<2>()).norm() * 1e3,
            kPlacementTolerance_mm);
}

TEST(ModelRegistration, RefusesAModelThatIsNotOnTheTable) {
  const Scene scene = SandtableScene(1);
  const Scene other = SandtableScene(99);  // another layout of buildings
  std::vector<Eigen::Vector3d> scan =
      Scan(other, Rigid3d::Identity(), Eigen::Vector2d(0, 0), 0.6, 0.0003, 4);
  // Keep the buildings only (a table alone matches any model).
  std::vector<Eigen::Vector3d> buildings;
  for (const Eigen::Vector3d& p : scan) {
    if (p.z() > 0.01) buildings.push_back(p);
  }
  ModelRegistrationOptions options;
  options.min_inlier_fraction = 0.8;
  options.icp_max_distance_m = 0.003;
  Expected<ModelRegistration> found = RegisterModel(scene, buildings, options);
  EXPECT_FALSE(found.ok());
  EXPECT_EQ(found.status().code(), StatusCode::kNotFound) << found.status().ToString();
}

// A flat table seen whole: placed by its outline (the rectangle's centroid and long axis), scale
// 1, the scan's points on the model's top. Seen in part, or a flat scan of a model with
// buildings: refused, not placed by accident (before, the free scale of the ICP diverged).
TEST(ModelRegistration, PlacesAFlatModelByItsOutlineOrRefuses) {
  ProceduralSceneOptions flat_options;
  flat_options.preset = ScenePreset::kFlat;
  const Scene flat = MakeProceduralScene(flat_options)->scene;
  const Rigid3d table_from_model(
      Eigen::AngleAxisd(4.0 * kPi / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix(),
      Eigen::Vector3d(0.03, -0.04, 0.0));
  // The flat preset's table top is sampled 3x coarser than the 4 mm of Scan(): a 12 mm grid,
  // like the pipeline's.
  const std::vector<Eigen::Vector3d> whole =
      Scan(flat, table_from_model, Eigen::Vector2d::Zero(), 5.0, 0.0003, 5);
  Expected<ModelRegistration> found = RegisterModel(flat, whole);
  ASSERT_TRUE(found.ok()) << found.status().ToString();
  EXPECT_TRUE(found->by_outline);
  EXPECT_EQ(found->scale, 1.0);
  const Rigid3d error = table_from_model.Inverse() * found->table_from_model;
  EXPECT_LT(error.translation.norm() * 1e3, kOutlinePlacement_mm);
  EXPECT_LT(Eigen::AngleAxisd(error.rotation).angle() * 180.0 / kPi, kOutlineAngle_deg);

  const std::vector<Eigen::Vector3d> part =
      Scan(flat, table_from_model, Eigen::Vector2d(0.3, 0.0), 0.5, 0.0003, 6);
  Expected<ModelRegistration> partial = RegisterModel(flat, part);
  EXPECT_EQ(partial.status().code(), StatusCode::kDegenerate) << partial.status().ToString();

  Expected<ModelRegistration> buildings = RegisterModel(SandtableScene(1), whole);
  EXPECT_EQ(buildings.status().code(), StatusCode::kDegenerate) << buildings.status().ToString();
}

}  // namespace
}  // namespace sandtable::node
