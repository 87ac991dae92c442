#include "common/scene/procedural_scene.h"

#include <algorithm>
#include <cmath>
#include <numbers>
#include <random>

#include "common/scene/mesh_builder.h"

namespace sandtable {

namespace {

using Rng = SceneRng;

Building RandomBuilding(Rng* rng, const Eigen::Vector2d& centre, double max_footprint_m) {
  Building b;
  b.centre_in_table_m = centre;
  b.shape = static_cast<BuildingShape>(rng->Index(4));
  b.yaw_rad = rng->Uniform(0.0, std::numbers::pi);
  const double max_side = max_footprint_m;
  switch (b.shape) {
    case BuildingShape::kTower:
      b.width_m = rng->Uniform(0.05, std::min(0.09, max_side));
      b.depth_m = rng->Uniform(0.05, std::min(0.09, max_side));
      b.height_m = rng->Uniform(0.18, 0.30);
      break;
    case BuildingShape::kGabled:
      b.width_m = rng->Uniform(0.08, max_side);
      b.depth_m = rng->Uniform(0.06, std::min(0.14, max_side));
      b.height_m = rng->Uniform(0.05, 0.14);
      break;
    default:
      b.width_m = rng->Uniform(0.07, max_side);
      b.depth_m = rng->Uniform(0.07, max_side);
      b.height_m = rng->Uniform(0.05, 0.25);
      break;
  }
  return b;
}

}  // namespace

Expected<ScenePreset> ParseScenePreset(std::string_view name) {
  if (name == "sandtable") return ScenePreset::kSandtable;
  if (name == "city") return ScenePreset::kCity;
  if (name == "flat") return ScenePreset::kFlat;
  return InvalidArgumentError("unknown scene preset '" + std::string(name) +
                              "' (use sandtable, city or flat)");
}

std::string_view ScenePresetName(ScenePreset preset) {
  switch (preset) {
    case ScenePreset::kSandtable:
      return "sandtable";
    case ScenePreset::kCity:
      return "city";
    case ScenePreset::kFlat:
      return "flat";
  }
  return "?";
}

Status ProceduralSceneOptions::Check() const {
  if (num_buildings < -1 || num_buildings > 200) {
    return InvalidArgumentError("num_buildings = " + std::to_string(num_buildings) +
                                " must be -1 (default) or in [0, 200]");
  }
  for (double albedo : {table_albedo, building_albedo}) {
    if (!(albedo >= 0.0 && albedo <= 1.0)) {
      return InvalidArgumentError("albedo " + std::to_string(albedo) + " must be in [0, 1]");
    }
  }
  for (int i : remove_buildings) {
    if (i < 0) return InvalidArgumentError("remove_buildings: index " + std::to_string(i) + " < 0");
  }
  for (const auto& [i, offset] : move_buildings) {
    if (i < 0) return InvalidArgumentError("move_buildings: index " + std::to_string(i) + " < 0");
    if (!offset.allFinite() || offset.norm() > 1.0) {
      return InvalidArgumentError("move_buildings: building " + std::to_string(i) +
                                  " offset must be finite and at most 1 m");
    }
  }
  return OkStatus();
}

Scene MakeBoxMesh(const Eigen::Vector3d& bottom_centre_in_table_m, const Eigen::Vector3d& size_m,
                  double yaw_rad, int material) {
  MeshBuilder mesh(material);
  const Eigen::Vector3d h = 0.5 * size_m;
  AddLocalBox(&mesh, bottom_centre_in_table_m.head<2>(), yaw_rad, -h.x(), h.x(), -h.y(), h.y(),
              bottom_centre_in_table_m.z(), bottom_centre_in_table_m.z() + size_m.z(),
              /*bottom=*/true);
  return mesh.Take();
}

Scene MakeBuildingMesh(const Building& b, int material) {
  MeshBuilder mesh(material);
  const Eigen::Vector2d& c = b.centre_in_table_m;
  const double hw = 0.5 * b.width_m, hd = 0.5 * b.depth_m;
  switch (b.shape) {
    case BuildingShape::kBox:
      AddLocalBox(&mesh, c, b.yaw_rad, -hw, hw, -hd, hd, 0.0, b.height_m, false);
      break;
    case BuildingShape::kLShape:
      // Two wings sharing the corner (-x, -y): a full-width wing and a full-depth wing.
      AddLocalBox(&mesh, c, b.yaw_rad, -hw, hw, -hd, -hd + 0.45 * b.depth_m, 0.0, b.height_m,
                  false);
      AddLocalBox(&mesh, c, b.yaw_rad, -hw, -hw + 0.45 * b.width_m, -hd, hd, 0.0, 0.7 * b.height_m,
                  false);
      break;
    case BuildingShape::kGabled: {
      const double wall = 0.6 * b.height_m;
      AddLocalBox(&mesh, c, b.yaw_rad, -hw, hw, -hd, hd, 0.0, wall, false);
      // Roof prism, ridge along local x at the full height.
      auto p = [&](double x, double y, double z) { return Local(c, b.yaw_rad, x, y, z); };
      const Eigen::Vector3d interior = p(0, 0, wall + 0.3 * (b.height_m - wall));
      mesh.Quad(p(-hw, -hd, wall), p(hw, -hd, wall), p(hw, 0, b.height_m), p(-hw, 0, b.height_m),
                interior);
      mesh.Quad(p(-hw, hd, wall), p(hw, hd, wall), p(hw, 0, b.height_m), p(-hw, 0, b.height_m),
                interior);
      mesh.Triangle(p(-hw, -hd, wall), p(-hw, hd, wall), p(-hw, 0, b.height_m), interior);
      mesh.Triangle(p(hw, -hd, wall), p(hw, hd, wall), p(hw, 0, b.height_m), interior);
      break;
    }
    case BuildingShape::kTower:
      // A shaft and a narrower top stage.
      AddLocalBox(&mesh, c, b.yaw_rad, -hw, hw, -hd, hd, 0.0, 0.8 * b.height_m, false);
      AddLocalBox(&mesh, c, b.yaw_rad, -0.6 * hw, 0.6 * hw, -0.6 * hd, 0.6 * hd, 0.8 * b.height_m,
                  b.height_m, false);
      break;
  }
  return mesh.Take();
}

Scene MakeDiscMesh(double radius_m, int segments, int material) {
  MeshBuilder mesh(material);
  const Eigen::Vector3d below(0, 0, -1);  // the top faces +z
  for (int i = 0; i < segments; ++i) {
    const double a0 = 2 * std::numbers::pi * i / segments;
    const double a1 = 2 * std::numbers::pi * (i + 1) / segments;
    mesh.Triangle(Eigen::Vector3d::Zero(),
                  Eigen::Vector3d(radius_m * std::cos(a0), radius_m * std::sin(a0), 0),
                  Eigen::Vector3d(radius_m * std::cos(a1), radius_m * std::sin(a1), 0), below);
  }
  return mesh.Take();
}

Scene MakeRectangleMesh(const Eigen::Vector2d& size_m, int material) {
  MeshBuilder mesh(material);
  const double hx = 0.5 * size_m.x(), hy = 0.5 * size_m.y();
  mesh.Quad({-hx, -hy, 0}, {hx, -hy, 0}, {hx, hy, 0}, {-hx, hy, 0}, Eigen::Vector3d(0, 0, -1));
  return mesh.Take();
}

Expected<ProceduralScene> MakeProceduralScene(const ProceduralSceneOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  ProceduralScene out;
  Rng rng(options.seed);
  Material table{
      "table", {options.table_albedo, options.table_albedo, options.table_albedo, 1.0}, -1};
  Material building{
      "building",
      {options.building_albedo, options.building_albedo, options.building_albedo, 1.0},
      -1};
  out.scene.materials = {table, building};

  switch (options.preset) {
    case ScenePreset::kSandtable: {
      out.table_is_disc = true;
      out.table_radius_m = 0.5 * kSandtableTableDiameter_m;
      out.scene.Append(MakeDiscMesh(out.table_radius_m, 96, 0));
      const int wanted = options.num_buildings < 0 ? 14 : options.num_buildings;
      const double display_radius_m = 0.5 * kSandtableDisplayDiameter_m;
      constexpr double kGap_m = 0.03;
      for (int attempt = 0; attempt < 2000 && static_cast<int>(out.buildings.size()) < wanted;
           ++attempt) {
        const double r = display_radius_m * std::sqrt(rng.Uniform(0.0, 1.0));
        const double a = rng.Uniform(0.0, 2 * std::numbers::pi);
        const Eigen::Vector2d centre(r * std::cos(a), r * std::sin(a));
        Building b = RandomBuilding(&rng, centre, 0.2);
        if (centre.norm() + b.FootprintRadius_m() > display_radius_m) continue;
        bool clear = true;
        for (const Building& o : out.buildings) {
          if ((o.centre_in_table_m - centre).norm() <
              o.FootprintRadius_m() + b.FootprintRadius_m() + kGap_m) {
            clear = false;
            break;
          }
        }
        if (clear) out.buildings.push_back(b);
      }
      break;
    }
    case ScenePreset::kCity: {
      out.table_is_disc = false;
      out.table_size_m = {3.0, 2.0};
      out.scene.Append(MakeRectangleMesh(out.table_size_m, 0));
      constexpr double kBlock_m = 0.3, kStreet_m = 0.1;
      const double pitch = kBlock_m + kStreet_m;
      const int nx = static_cast<int>((out.table_size_m.x() - kStreet_m) / pitch);
      const int ny = static_cast<int>((out.table_size_m.y() - kStreet_m) / pitch);
      for (int j = 0; j < ny; ++j) {
        for (int i = 0; i < nx; ++i) {
          if (rng.Uniform(0.0, 1.0) > 0.7) continue;
          const Eigen::Vector2d centre((i - 0.5 * (nx - 1)) * pitch, (j - 0.5 * (ny - 1)) * pitch);
          Building b = RandomBuilding(&rng, centre, 0.2);
          b.yaw_rad = 0.5 * std::numbers::pi * rng.Index(2);  // aligned with the streets
          out.buildings.push_back(b);
        }
      }
      break;
    }
    case ScenePreset::kFlat:
      out.table_is_disc = false;
      out.table_size_m = {2.0, 1.5};
      out.scene.Append(MakeRectangleMesh(out.table_size_m, 0));
      break;
  }
  const int layout_count = static_cast<int>(out.buildings.size());
  auto out_of_range = [&](int i) {
    return InvalidArgumentError("building " + std::to_string(i) +
                                " does not exist (the layout has " + std::to_string(layout_count) +
                                ")");
  };
  for (int i : options.remove_buildings) {
    if (i >= layout_count) return out_of_range(i);
  }
  for (const auto& [i, offset] : options.move_buildings) {
    if (i >= layout_count) return out_of_range(i);
    out.buildings[i].centre_in_table_m += offset;
  }
  std::vector<Building> built;
  for (int i = 0; i < layout_count; ++i) {
    if (std::find(options.remove_buildings.begin(), options.remove_buildings.end(), i) !=
        options.remove_buildings.end()) {
      continue;
    }
    built.push_back(out.buildings[i]);
    out.scene.Append(MakeBuildingMesh(out.buildings[i], 1));
  }
  out.buildings = std::move(built);
  return out;
}

}  // namespace sandtable
