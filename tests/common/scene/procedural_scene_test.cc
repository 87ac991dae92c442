#include "common/scene/procedural_scene.h"

#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>

#include <gtest/gtest.h>

#include "common/scene/gltf_loader.h"
#include "common/scene/gltf_writer.h"

namespace sandtable::sim {
namespace {

constexpr double kFloatTolerance_m = 1e-6;  // float32 storage of positions

std::string TempPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("sandtable_" + std::to_string(::getpid()) + "_" + name))
      .string();
}

TEST(ProceduralScene, SandtableAtTr09017Scale) {
  ProceduralSceneOptions options;
  options.seed = 7;
  Expected<ProceduralScene> made = MakeProceduralScene(options);
  ASSERT_TRUE(made.ok()) << made.status().ToString();
  EXPECT_TRUE(made->table_is_disc);
  EXPECT_NEAR(2 * made->table_radius_m, 1.524, 1e-9);
  ASSERT_EQ(made->buildings.size(), 14u);
  bool shapes[4] = {false, false, false, false};
  for (const Building& b : made->buildings) {
    EXPECT_GE(b.height_m, 0.05);
    EXPECT_LE(b.height_m, 0.30);
    EXPECT_LE(b.centre_in_table_m.norm() + b.FootprintRadius_m(),
              0.5 * kSandtableDisplayDiameter_m + 1e-12);
    shapes[static_cast<int>(b.shape)] = true;
  }
  EXPECT_GE(shapes[0] + shapes[1] + shapes[2] + shapes[3], 3) << "varied shapes";
  const Eigen::AlignedBox3d box = made->scene.Bounds();
  EXPECT_NEAR(box.min().z(), 0.0, kFloatTolerance_m);
  EXPECT_LE(box.max().z(), 0.30 + kFloatTolerance_m);
  EXPECT_GE(box.max().z(), 0.05);
  // Every triangle has a valid material; building triangles are material 1.
  for (int m : made->scene.triangle_material) EXPECT_TRUE(m == 0 || m == 1);
}

TEST(ProceduralScene, DeterministicForSeed) {
  ProceduralSceneOptions options;
  options.preset = ScenePreset::kCity;
  options.seed = 42;
  Expected<ProceduralScene> a = MakeProceduralScene(options);
  Expected<ProceduralScene> b = MakeProceduralScene(options);
  options.seed = 43;
  Expected<ProceduralScene> c = MakeProceduralScene(options);
  ASSERT_TRUE(a.ok() && b.ok() && c.ok());
  EXPECT_EQ(a->scene.positions_in_table_m, b->scene.positions_in_table_m);
  EXPECT_NE(a->scene.positions_in_table_m, c->scene.positions_in_table_m);
}

TEST(ProceduralScene, BoxIsClosedAndOutward) {
  const Scene box = MakeBoxMesh({0.1, 0.2, 0.0}, {0.2, 0.1, 0.3}, 0.3, 0);
  ASSERT_EQ(box.NumTriangles(), 12);
  // Divergence theorem: the volume from outward faces is w d h.
  double volume_m3 = 0.0;
  for (const Eigen::Vector3i& t : box.triangles) {
    volume_m3 += box.positions_in_table_m[t[0]].cast<double>().dot(
                     box.positions_in_table_m[t[1]].cast<double>().cross(
                         box.positions_in_table_m[t[2]].cast<double>())) /
                 6.0;
  }
  EXPECT_NEAR(volume_m3, 0.2 * 0.1 * 0.3, 1e-8);
}

TEST(ProceduralScene, GabledRoofFacesUp) {
  Building b;
  b.shape = BuildingShape::kGabled;
  b.width_m = 0.2;
  b.depth_m = 0.1;
  b.height_m = 0.1;
  const Scene mesh = MakeBuildingMesh(b, 1);
  // Open at the bottom (it stands on the table), so check outwardness on the roof only:
  // every roof triangle (above the walls) has a normal with +z component.
  for (int t = 0; t < mesh.NumTriangles(); ++t) {
    const Eigen::Vector3i& tri = mesh.triangles[t];
    const double z =
        (mesh.positions_in_table_m[tri[0]].z() + mesh.positions_in_table_m[tri[1]].z() +
         mesh.positions_in_table_m[tri[2]].z()) /
        3.0;
    if (z > 0.06 + 1e-6 && std::abs(mesh.FaceNormal(t).x()) < 0.5) {
      EXPECT_GT(mesh.FaceNormal(t).z(), 0.0) << "roof triangle " << t;
    }
  }
  EXPECT_NEAR(mesh.Bounds().max().z(), 0.1, kFloatTolerance_m);
}

TEST(ProceduralScene, RoundTripsThroughGltf) {
  for (const std::string ext : {".gltf", ".glb"}) {
    ProceduralSceneOptions options;
    options.seed = 3;
    Expected<ProceduralScene> made = MakeProceduralScene(options);
    ASSERT_TRUE(made.ok());
    const std::string path = TempPath("roundtrip" + ext);
    ASSERT_TRUE(WriteGltfScene(made->scene, path).ok());
    Expected<Scene> loaded = LoadGltfScene(path);
    std::remove(path.c_str());
    ASSERT_TRUE(loaded.ok()) << loaded.status().ToString();
    ASSERT_EQ(loaded->NumTriangles(), made->scene.NumTriangles());
    ASSERT_EQ(loaded->materials.size(), 2u);
    // The writer groups triangles by material; compare as sets of corner positions per material.
    double max_error_m = 0.0;
    std::vector<Eigen::Vector3f> a, b;
    for (int t = 0; t < made->scene.NumTriangles(); ++t) {
      for (int k = 0; k < 3; ++k)
        a.push_back(made->scene.positions_in_table_m[made->scene.triangles[t][k]]);
    }
    for (int t = 0; t < loaded->NumTriangles(); ++t) {
      for (int k = 0; k < 3; ++k)
        b.push_back(loaded->positions_in_table_m[loaded->triangles[t][k]]);
    }
    auto less = [](const Eigen::Vector3f& p, const Eigen::Vector3f& q) {
      return std::lexicographical_compare(p.data(), p.data() + 3, q.data(), q.data() + 3);
    };
    std::sort(a.begin(), a.end(), less);
    std::sort(b.begin(), b.end(), less);
    for (size_t i = 0; i < a.size(); ++i)
      max_error_m = std::max(max_error_m, double((a[i] - b[i]).norm()));
    EXPECT_LT(max_error_m, kFloatTolerance_m) << ext;
    EXPECT_NEAR(loaded->materials[1].base_color_factor.x(), options.building_albedo, 1e-6);
  }
}

TEST(ProceduralScene, BadOptionsAndPresetNames) {
  EXPECT_FALSE(ParseScenePreset("moon").ok());
  EXPECT_EQ(*ParseScenePreset("flat"), ScenePreset::kFlat);
  ProceduralSceneOptions options;
  options.table_albedo = 1.5;
  EXPECT_FALSE(MakeProceduralScene(options).ok());
}

}  // namespace
}  // namespace sandtable::sim

namespace sandtable {
namespace {

// The physical scene changed against the layout: one building left out, one moved; every
// other building where the seed put it; bad indices and offsets refused.
TEST(ProceduralScene, RemovesAndMovesBuildingsOfTheLayout) {
  const Expected<ProceduralScene> layout = MakeProceduralScene({});
  ASSERT_TRUE(layout.ok());
  ProceduralSceneOptions changed;
  changed.remove_buildings = {2};
  const Eigen::Vector2d offset(0.006, 0.008);
  changed.move_buildings = {{5, offset}};
  const Expected<ProceduralScene> built = MakeProceduralScene(changed);
  ASSERT_TRUE(built.ok()) << built.status().ToString();
  ASSERT_EQ(built->buildings.size(), layout->buildings.size() - 1);
  for (size_t i = 0, j = 0; i < layout->buildings.size(); ++i) {
    if (i == 2) continue;
    const Eigen::Vector2d expected =
        layout->buildings[i].centre_in_table_m + (i == 5 ? offset : Eigen::Vector2d::Zero());
    EXPECT_LT((built->buildings[j].centre_in_table_m - expected).norm(), 1e-12) << "building " << i;
    ++j;
  }
  EXPECT_LT(built->scene.NumTriangles(), layout->scene.NumTriangles());

  ProceduralSceneOptions bad;
  bad.remove_buildings = {99};
  EXPECT_EQ(MakeProceduralScene(bad).status().code(), StatusCode::kInvalidArgument);
  bad.remove_buildings = {-1};
  EXPECT_EQ(MakeProceduralScene(bad).status().code(), StatusCode::kInvalidArgument);
  bad.remove_buildings.clear();
  bad.move_buildings = {{1, Eigen::Vector2d(std::nan(""), 0.0)}};
  EXPECT_EQ(MakeProceduralScene(bad).status().code(), StatusCode::kInvalidArgument);
}

}  // namespace
}  // namespace sandtable
