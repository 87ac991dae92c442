// Procedural scenes for the simulated world: a table with white building models.
//
// Presets (all in the table frame, metres, the table top at z = 0, facing +z):
//   sandtable: TR09-017 scale. A 5 ft (1.524 m) diameter disc; buildings inside the central 4 ft
//              (1.219 m) display area; 5 to 30 cm tall; boxes, L-shapes, gabled roofs, towers.
//   city:      a 3.0 m x 2.0 m rectangle with a street grid, one building per block (70 % of
//              blocks), same shapes and heights; for the ceiling-grid sites.
//   flat:      a 2.0 m x 1.5 m rectangle, no buildings.
// Deterministic for a seed: the generator uses std::mt19937_64 (fully specified by the standard)
// and its own uniform mapping, so a seed gives the same scene on every platform.
// Every solid is closed, with counter-clockwise (outward) winding.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "common/base/status.h"
#include "common/scene/scene.h"

namespace sandtable {

enum class ScenePreset { kSandtable, kCity, kFlat };
Expected<ScenePreset> ParseScenePreset(std::string_view name);
std::string_view ScenePresetName(ScenePreset preset);

enum class BuildingShape { kBox, kLShape, kGabled, kTower };

struct Building {
  BuildingShape shape = BuildingShape::kBox;
  Eigen::Vector2d centre_in_table_m = Eigen::Vector2d::Zero();
  double yaw_rad = 0.0;   // rotation about +z
  double width_m = 0.1;   // along the building's local x
  double depth_m = 0.1;   // along local y
  double height_m = 0.1;  // total height including any roof
  double FootprintRadius_m() const { return 0.5 * std::hypot(width_m, depth_m); }
};

struct ProceduralSceneOptions {
  ScenePreset preset = ScenePreset::kSandtable;
  uint64_t seed = 1;
  int num_buildings = -1;        // sandtable only; -1 = preset default (14)
  double table_albedo = 0.8;     // grey level of the table top (linear)
  double building_albedo = 0.9;  // grey level of the buildings (linear)
  // The physical scene changed against the layout (to test the nodes' change report): the
  // buildings with these indices (into the layout's order) are left out, these moved by an
  // offset in x, y (metres). The layout, and so every other building, stays the seed's.
  std::vector<int> remove_buildings;
  std::vector<std::pair<int, Eigen::Vector2d>> move_buildings;
  Status Check() const;
};

struct ProceduralScene {
  Scene scene;
  std::vector<Building> buildings;  // as built: removed ones left out, moved ones moved
  bool table_is_disc = true;
  double table_radius_m = 0.0;                             // disc only
  Eigen::Vector2d table_size_m = Eigen::Vector2d::Zero();  // rectangle only (x, y)
};

Expected<ProceduralScene> MakeProceduralScene(const ProceduralSceneOptions& options);

// Building blocks (material index `material` on every triangle; the caller owns `materials`).
// A box standing on z = base_z_m: centre of its bottom face at (centre, base_z_m).
Scene MakeBoxMesh(const Eigen::Vector3d& bottom_centre_in_table_m, const Eigen::Vector3d& size_m,
                  double yaw_rad, int material);
Scene MakeBuildingMesh(const Building& building, int material);
Scene MakeDiscMesh(double radius_m, int segments, int material);
Scene MakeRectangleMesh(const Eigen::Vector2d& size_m, int material);

constexpr double kSandtableTableDiameter_m = 5 * 0.3048;    // 5 ft (TR09-017)
constexpr double kSandtableDisplayDiameter_m = 4 * 0.3048;  // 4 ft display area

}  // namespace sandtable
