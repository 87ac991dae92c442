#include "common/scene/random_scene.h"

#include <cmath>
#include <set>

#include <gtest/gtest.h>

namespace sandtable {
namespace {

constexpr double kFloatTolerance_m = 1e-5;  // float32 storage of positions

TEST(RandomScene, EverySeedHoldsTheTableTheSiteUsesAndStructuresOnTheTerrain) {
  std::set<RandomStructureKind> kinds;
  int with_terrain = 0, discs = 0;
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    RandomSceneOptions options;
    options.seed = seed;
    Expected<RandomScene> made = MakeRandomScene(options);
    ASSERT_TRUE(made.ok()) << made.status().ToString();
    const RandomTable table = RandomTableForSeed(seed);
    EXPECT_EQ(made->table.is_disc, table.is_disc);
    EXPECT_EQ(made->scene.table_is_disc, table.is_disc);
    discs += table.is_disc;
    with_terrain += made->terrain_max_height_m > 0.0;
    EXPECT_GE(made->structures.size(), 4u) << "seed " << seed;
    EXPECT_EQ(made->structures.size(), made->scene.buildings.size());
    for (const RandomStructure& s : made->structures) {
      kinds.insert(s.kind);
      EXPECT_TRUE(table.Contains(s.centre_in_table_m, s.FootprintRadius_m()));
      // The walls reach the ground: the base is at or below the terrain at the centre.
      EXPECT_LE(s.base_z_m,
                RandomTerrainHeight_m(seed, table, s.centre_in_table_m, options.taper_m) +
                    kFloatTolerance_m);
    }
    // Every vertex on or above the table's rim level and within the table's reach.
    const Eigen::AlignedBox3d bounds = made->scene.scene.Bounds();
    EXPECT_GE(bounds.min().z(), -kFloatTolerance_m);
    EXPECT_LE(bounds.max().z(), 0.6);
    const double half_x = table.is_disc ? 0.5 * table.diameter_m : 0.5 * table.size_m.x();
    EXPECT_LE(bounds.max().x(), half_x + kFloatTolerance_m);
    EXPECT_GE(bounds.min().x(), -half_x - kFloatTolerance_m);
    // Outward winding: a closed terrain is not a solid, but every structure's roof faces up.
    int down_facing_high = 0;
    for (int t = 0; t < made->scene.scene.NumTriangles(); ++t) {
      if (made->scene.scene.triangle_material[t] != 0) continue;
      if (made->scene.scene.FaceNormal(t).z() < 0.0) ++down_facing_high;
    }
    EXPECT_EQ(down_facing_high, 0) << "seed " << seed << ": terrain faces down";
  }
  EXPECT_EQ(kinds.size(), 9u) << "every kind of structure in 20 seeds";
  EXPECT_GE(with_terrain, 10);
  EXPECT_GE(discs, 3);
}

TEST(RandomScene, TheTerrainMeshFollowsItsHeightFunction) {
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    RandomSceneOptions options;
    options.seed = seed;
    Expected<RandomScene> made = MakeRandomScene(options);
    ASSERT_TRUE(made.ok());
    if (made->terrain_max_height_m == 0.0) continue;
    const Scene& scene = made->scene.scene;
    for (int t = 0; t < scene.NumTriangles(); t += 97) {
      if (scene.triangle_material[t] != 0) continue;
      const Eigen::Vector3f v = scene.positions_in_table_m[scene.triangles[t][0]];
      const double z =
          RandomTerrainHeight_m(seed, made->table, v.head<2>().cast<double>(), options.taper_m);
      EXPECT_NEAR(v.z(), z, kFloatTolerance_m);
    }
    return;  // one terrain seed suffices
  }
  FAIL() << "no seed of 1-20 has terrain";
}

TEST(RandomScene, SeedNames) {
  EXPECT_EQ(ParseRandomSeedName("random:12"), std::optional<uint64_t>(12));
  EXPECT_EQ(ParseRandomSeedName("random:"), std::nullopt);
  EXPECT_EQ(ParseRandomSeedName("random:1x"), std::nullopt);
  EXPECT_EQ(ParseRandomSeedName("city"), std::nullopt);
  EXPECT_EQ(ParseRandomSeedName("random:1234567890123456789"), std::nullopt);
  RandomSceneOptions bad;
  bad.terrain_cell_m = 0.0;
  EXPECT_FALSE(MakeRandomScene(bad).ok());
}

}  // namespace
}  // namespace sandtable
