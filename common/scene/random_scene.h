// Random scenes for the lab's random sites (`--scene random:SEED`): a table of a shape and size
// drawn from the seed, its surface a terrain of hills or flat, and on it structures a real sand
// table holds: boxes, L-shapes, gabled and pyramid roofs, many-sided towers, bridges on piers,
// overhanging upper floors, courtyard buildings and thin antennas.
//
// Frame: table frame, metres, the table's rim at z = 0 and +z up; the terrain rises from the rim
// (heights >= 0, tapering to 0 within taper_m of the rim). Every structure stands on the
// terrain: its walls reach down to the lowest terrain point under its footprint, so no gap shows.
// Deterministic for a seed (SceneRng, common/scene/mesh_builder.h). Materials: 0 table/terrain,
// 1 structures.
// RandomTableForSeed(seed) is the table both the random scene and the random site (sim/site/
// random_site.h) of one seed use, so `--site random:S --scene random:S` agree.
#pragma once

#include <cmath>
#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/base/status.h"
#include "common/scene/procedural_scene.h"

namespace sandtable {

struct RandomTable {
  bool is_disc = false;
  double diameter_m = 0.0;                           // disc
  Eigen::Vector2d size_m = Eigen::Vector2d::Zero();  // rectangle (x, y), centred
  bool Contains(const Eigen::Vector2d& xy_in_table_m, double margin_m = 0.0) const;
  double Area_m2() const;
};

// Rectangles 1.2-3.0 m x 0.8-2.0 m (two in three seeds) or discs of 1.2-2.0 m.
RandomTable RandomTableForSeed(uint64_t seed);

enum class RandomStructureKind {
  kBox,
  kLShape,
  kGabled,
  kPyramidRoof,
  kTower,  // a prism of 12-24 sides
  kBridge,
  kOverhang,
  kCourtyard,
  kAntenna,  // a thin mast (3-6 mm) on a box
};
std::string RandomStructureName(RandomStructureKind kind);

struct RandomStructure {
  RandomStructureKind kind = RandomStructureKind::kBox;
  Eigen::Vector2d centre_in_table_m = Eigen::Vector2d::Zero();
  double yaw_rad = 0.0;
  double width_m = 0.1, depth_m = 0.1;  // footprint, local x and y
  double height_m = 0.1;                // above base_z_m, roof and mast included
  double base_z_m = 0.0;                // the lowest terrain point under the footprint
  double FootprintRadius_m() const { return 0.5 * std::hypot(width_m, depth_m); }
};

struct RandomScene {
  ProceduralScene scene;  // buildings: each structure's footprint as a box
  RandomTable table;
  std::vector<RandomStructure> structures;
  double terrain_max_height_m = 0.0;  // 0: a flat table
};

struct RandomSceneOptions {
  uint64_t seed = 1;
  double terrain_cell_m = 0.02;  // spacing of the terrain's vertices
  double taper_m = 0.08;         // the terrain reaches 0 at the rim over this width
  Status Check() const;
};

// Terrain height at a point of the table (0 off the table), as the scene's mesh samples it.
double RandomTerrainHeight_m(uint64_t seed, const RandomTable& table,
                             const Eigen::Vector2d& xy_in_table_m, double taper_m);

Expected<RandomScene> MakeRandomScene(const RandomSceneOptions& options);

// "random:SEED" -> SEED (a decimal number of at most 18 digits); nullopt for other text.
std::optional<uint64_t> ParseRandomSeedName(const std::string& text);

}  // namespace sandtable
