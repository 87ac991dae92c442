#include "common/scene/random_scene.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "common/scene/mesh_builder.h"

namespace sandtable {

namespace {

constexpr double kPi = std::numbers::pi;

// Independent streams of one seed: the table, the terrain and the structures each draw from
// their own, so a change to one does not move the others.
constexpr uint64_t kTableStream = 0x7461626c65ULL;      // "table"
constexpr uint64_t kTerrainStream = 0x7465727261ULL;    // "terra"
constexpr uint64_t kStructureStream = 0x6275696c64ULL;  // "build"

struct Hill {
  Eigen::Vector2d centre_m;
  double amplitude_m, sigma_m;
};

// Flat in one seed of four; else two to six hills of 1-6 cm.
std::vector<Hill> Hills(uint64_t seed, const RandomTable& table) {
  SceneRng rng(seed ^ kTerrainStream);
  std::vector<Hill> hills;
  if (rng.Chance(0.25)) return hills;
  const int count = 2 + rng.Index(5);
  const Eigen::Vector2d half = table.is_disc ? Eigen::Vector2d::Constant(0.5 * table.diameter_m)
                                             : Eigen::Vector2d(0.5 * table.size_m);
  while (static_cast<int>(hills.size()) < count) {
    const Eigen::Vector2d c(rng.Uniform(-half.x(), half.x()), rng.Uniform(-half.y(), half.y()));
    const double amplitude = rng.Uniform(0.01, 0.06), sigma = rng.Uniform(0.08, 0.3);
    if (table.Contains(c)) hills.push_back({c, amplitude, sigma});
  }
  return hills;
}

double DistanceInsideRim_m(const RandomTable& table, const Eigen::Vector2d& xy) {
  if (table.is_disc) return 0.5 * table.diameter_m - xy.norm();
  return std::min(0.5 * table.size_m.x() - std::abs(xy.x()),
                  0.5 * table.size_m.y() - std::abs(xy.y()));
}

double Height(const std::vector<Hill>& hills, const RandomTable& table, const Eigen::Vector2d& xy,
              double taper_m) {
  const double inside = DistanceInsideRim_m(table, xy);
  if (inside <= 0.0 || hills.empty()) return 0.0;
  double z = 0.0;
  for (const Hill& h : hills) {
    z += h.amplitude_m * std::exp(-(xy - h.centre_m).squaredNorm() / (2 * h.sigma_m * h.sigma_m));
  }
  const double t = std::min(1.0, inside / taper_m);
  return z * t * t * (3 - 2 * t);  // smoothstep: no crease where the taper starts
}

// The table's surface: a height field over a grid (a rectangle, or a square mapped onto the
// disc), or the flat table of the presets.
Scene TerrainMesh(const std::vector<Hill>& hills, const RandomTable& table,
                  const RandomSceneOptions& options) {
  if (hills.empty()) {
    return table.is_disc ? MakeDiscMesh(0.5 * table.diameter_m, 96, 0)
                         : MakeRectangleMesh(table.size_m, 0);
  }
  MeshBuilder mesh(0);
  const Eigen::Vector2d extent =
      table.is_disc ? Eigen::Vector2d::Constant(table.diameter_m) : table.size_m;
  const int nx = std::max(2, static_cast<int>(std::ceil(extent.x() / options.terrain_cell_m)));
  const int ny = std::max(2, static_cast<int>(std::ceil(extent.y() / options.terrain_cell_m)));
  auto vertex = [&](int i, int j) {
    // (a, b) in [-1, 1]^2; the disc uses the elliptical grid map, which takes the square's
    // border onto the circle and keeps every cell a proper quad.
    const double a = -1.0 + 2.0 * i / nx, b = -1.0 + 2.0 * j / ny;
    Eigen::Vector2d xy;
    if (table.is_disc) {
      const double r = 0.5 * table.diameter_m;
      xy = r * Eigen::Vector2d(a * std::sqrt(1 - 0.5 * b * b), b * std::sqrt(1 - 0.5 * a * a));
    } else {
      xy = 0.5 * Eigen::Vector2d(a * table.size_m.x(), b * table.size_m.y());
    }
    return Eigen::Vector3d(xy.x(), xy.y(), Height(hills, table, xy, options.taper_m));
  };
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      const Eigen::Vector3d p00 = vertex(i, j), p10 = vertex(i + 1, j);
      const Eigen::Vector3d p11 = vertex(i + 1, j + 1), p01 = vertex(i, j + 1);
      const Eigen::Vector3d below = 0.25 * (p00 + p10 + p11 + p01) - Eigen::Vector3d(0, 0, 1);
      mesh.Triangle(p00, p10, p11, below);
      mesh.Triangle(p00, p11, p01, below);
    }
  }
  return mesh.Take();
}

// The corners and centre of a structure's footprint, and points between, in the table frame.
std::vector<Eigen::Vector2d> FootprintSamples(const RandomStructure& s) {
  std::vector<Eigen::Vector2d> out;
  constexpr int kSteps = 6;
  for (int j = 0; j <= kSteps; ++j) {
    for (int i = 0; i <= kSteps; ++i) {
      const double x = (i / double(kSteps) - 0.5) * s.width_m;
      const double y = (j / double(kSteps) - 0.5) * s.depth_m;
      out.push_back(Local(s.centre_in_table_m, s.yaw_rad, x, y, 0.0).head<2>());
    }
  }
  return out;
}

// A prism of `sides` sides of circumradius r from z0 to z1, capped on top.
void AddPrism(MeshBuilder* mesh, const Eigen::Vector2d& c, int sides, double r, double z0,
              double z1) {
  const Eigen::Vector3d interior(c.x(), c.y(), 0.5 * (z0 + z1));
  const Eigen::Vector3d top(c.x(), c.y(), z1);
  for (int k = 0; k < sides; ++k) {
    const double a0 = 2 * kPi * k / sides, a1 = 2 * kPi * (k + 1) / sides;
    const Eigen::Vector2d q0 = c + r * Eigen::Vector2d(std::cos(a0), std::sin(a0));
    const Eigen::Vector2d q1 = c + r * Eigen::Vector2d(std::cos(a1), std::sin(a1));
    mesh->Quad({q0.x(), q0.y(), z0}, {q1.x(), q1.y(), z0}, {q1.x(), q1.y(), z1},
               {q0.x(), q0.y(), z1}, interior);
    mesh->Triangle(top, {q0.x(), q0.y(), z1}, {q1.x(), q1.y(), z1}, interior);
  }
}

Scene StructureMesh(const RandomStructure& s, SceneRng* rng) {
  MeshBuilder mesh(1);
  const Eigen::Vector2d& c = s.centre_in_table_m;
  const double hw = 0.5 * s.width_m, hd = 0.5 * s.depth_m;
  const double z0 = s.base_z_m, z1 = s.base_z_m + s.height_m;
  auto p = [&](double x, double y, double z) { return Local(c, s.yaw_rad, x, y, z); };
  switch (s.kind) {
    case RandomStructureKind::kBox:
    case RandomStructureKind::kLShape:
    case RandomStructureKind::kGabled: {
      Building b;
      b.shape = s.kind == RandomStructureKind::kBox      ? BuildingShape::kBox
                : s.kind == RandomStructureKind::kLShape ? BuildingShape::kLShape
                                                         : BuildingShape::kGabled;
      b.centre_in_table_m = c;
      b.yaw_rad = s.yaw_rad;
      b.width_m = s.width_m;
      b.depth_m = s.depth_m;
      b.height_m = s.height_m;
      return MovedScene(MakeBuildingMesh(b, 1),
                        Rigid3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(0, 0, z0)));
    }
    case RandomStructureKind::kPyramidRoof: {
      const double wall = z0 + 0.65 * s.height_m;
      AddLocalBox(&mesh, c, s.yaw_rad, -hw, hw, -hd, hd, z0, wall, false);
      const Eigen::Vector3d apex = p(0, 0, z1), interior = p(0, 0, 0.5 * (wall + z1));
      mesh.Triangle(p(-hw, -hd, wall), p(hw, -hd, wall), apex, interior);
      mesh.Triangle(p(hw, -hd, wall), p(hw, hd, wall), apex, interior);
      mesh.Triangle(p(hw, hd, wall), p(-hw, hd, wall), apex, interior);
      mesh.Triangle(p(-hw, hd, wall), p(-hw, -hd, wall), apex, interior);
      break;
    }
    case RandomStructureKind::kTower:
      AddPrism(&mesh, c, 12 + rng->Index(13), hw, z0, z1);
      break;
    case RandomStructureKind::kBridge: {
      // Two piers at the ends of the span (local x) and a deck on them, open underneath.
      const double deck_bottom = z1 - 0.015, pier = 0.03;
      AddLocalBox(&mesh, c, s.yaw_rad, -hw, -hw + pier, -hd, hd, z0, deck_bottom, false);
      AddLocalBox(&mesh, c, s.yaw_rad, hw - pier, hw, -hd, hd, z0, deck_bottom, false);
      AddLocalBox(&mesh, c, s.yaw_rad, -hw, hw, -hd, hd, deck_bottom, z1, true);
      break;
    }
    case RandomStructureKind::kOverhang: {
      // A lower storey inset on +x and +y under an upper storey of the full footprint.
      const double split = z0 + 0.55 * s.height_m;
      const double inset_x = 0.3 * s.width_m, inset_y = 0.25 * s.depth_m;
      AddLocalBox(&mesh, c, s.yaw_rad, -hw, hw - inset_x, -hd, hd - inset_y, z0, split, false);
      AddLocalBox(&mesh, c, s.yaw_rad, -hw, hw, -hd, hd, split, z1, true);
      break;
    }
    case RandomStructureKind::kCourtyard: {
      const double t = std::min(0.04, 0.25 * std::min(s.width_m, s.depth_m));
      AddLocalBox(&mesh, c, s.yaw_rad, -hw, hw, -hd, -hd + t, z0, z1, false);
      AddLocalBox(&mesh, c, s.yaw_rad, -hw, hw, hd - t, hd, z0, z1, false);
      AddLocalBox(&mesh, c, s.yaw_rad, -hw, -hw + t, -hd + t, hd - t, z0, z1, false);
      AddLocalBox(&mesh, c, s.yaw_rad, hw - t, hw, -hd + t, hd - t, z0, z1, false);
      break;
    }
    case RandomStructureKind::kAntenna: {
      const double roof = z0 + 0.45 * s.height_m, mast = rng->Uniform(0.0015, 0.003);
      AddLocalBox(&mesh, c, s.yaw_rad, -hw, hw, -hd, hd, z0, roof, false);
      AddLocalBox(&mesh, c, s.yaw_rad, -mast, mast, -mast, mast, roof, z1, false);
      break;
    }
  }
  return mesh.Take();
}

// Footprint and visible height of a structure of `kind`, before it is placed: a tower is round
// (radius, then height), every other kind draws width, depth and height from its ranges, m.
void DrawShape(SceneRng* rng, RandomStructure* s) {
  if (s->kind == RandomStructureKind::kTower) {
    const double r = rng->Uniform(0.025, 0.05);
    s->width_m = s->depth_m = 2 * r;
    s->height_m = rng->Uniform(0.15, 0.30);
    return;
  }
  struct Ranges {
    double width[2], depth[2], height[2];
  };
  const Ranges ranges =
      s->kind == RandomStructureKind::kBridge      ? Ranges{{0.2, 0.4}, {0.05, 0.08}, {0.06, 0.12}}
      : s->kind == RandomStructureKind::kCourtyard ? Ranges{{0.15, 0.3}, {0.15, 0.3}, {0.04, 0.12}}
      : s->kind == RandomStructureKind::kAntenna   ? Ranges{{0.06, 0.1}, {0.06, 0.1}, {0.15, 0.25}}
                                                   : Ranges{{0.07, 0.2}, {0.07, 0.2}, {0.05, 0.25}};
  s->width_m = rng->Uniform(ranges.width[0], ranges.width[1]);
  s->depth_m = rng->Uniform(ranges.depth[0], ranges.depth[1]);
  s->height_m = rng->Uniform(ranges.height[0], ranges.height[1]);
}

}  // namespace

bool RandomTable::Contains(const Eigen::Vector2d& xy, double margin_m) const {
  return DistanceInsideRim_m(*this, xy) >= margin_m;
}

double RandomTable::Area_m2() const {
  return is_disc ? 0.25 * kPi * diameter_m * diameter_m : size_m.x() * size_m.y();
}

RandomTable RandomTableForSeed(uint64_t seed) {
  SceneRng rng(seed ^ kTableStream);
  RandomTable table;
  table.is_disc = rng.Chance(1.0 / 3.0);
  if (table.is_disc) {
    table.diameter_m = rng.Uniform(1.2, 2.0);
  } else {
    table.size_m = {rng.Uniform(1.2, 3.0), rng.Uniform(0.8, 2.0)};
  }
  return table;
}

std::string RandomStructureName(RandomStructureKind kind) {
  static const char* const kNames[] = {"box",    "l-shape",  "gabled",    "pyramid-roof", "tower",
                                       "bridge", "overhang", "courtyard", "antenna"};
  return kNames[static_cast<int>(kind)];
}

Status RandomSceneOptions::Check() const {
  if (!(terrain_cell_m >= 0.005 && terrain_cell_m <= 0.2)) {
    return InvalidArgumentError("random scene: terrain_cell_m must be in [0.005, 0.2] m");
  }
  if (!(taper_m > 0.0 && taper_m <= 0.5)) {
    return InvalidArgumentError("random scene: taper_m must be in (0, 0.5] m");
  }
  return OkStatus();
}

double RandomTerrainHeight_m(uint64_t seed, const RandomTable& table, const Eigen::Vector2d& xy,
                             double taper_m) {
  return Height(Hills(seed, table), table, xy, taper_m);
}

Expected<RandomScene> MakeRandomScene(const RandomSceneOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  RandomScene out;
  out.table = RandomTableForSeed(options.seed);
  const std::vector<Hill> hills = Hills(options.seed, out.table);
  for (const Hill& h : hills) out.terrain_max_height_m += h.amplitude_m;
  ProceduralScene& ps = out.scene;
  ps.table_is_disc = out.table.is_disc;
  ps.table_radius_m = out.table.is_disc ? 0.5 * out.table.diameter_m : 0.0;
  ps.table_size_m = out.table.is_disc ? Eigen::Vector2d::Zero() : out.table.size_m;
  SceneRng rng(options.seed ^ kStructureStream);
  const double albedo = rng.Uniform(0.6, 0.85), building_albedo = rng.Uniform(0.85, 0.95);
  ps.scene.materials = {
      Material{"table", {albedo, albedo, albedo, 1.0}, -1},
      Material{"building", {building_albedo, building_albedo, building_albedo, 1.0}, -1}};
  ps.scene.Append(TerrainMesh(hills, out.table, options));

  // Structures: 4 to 8 per square metre (4 at least, 25 at most), apart by 3 cm, 5 cm inside
  // the rim; every kind at least once where the count allows (the first nine are one of each).
  const int wanted =
      std::clamp(static_cast<int>(std::lround(out.table.Area_m2() * rng.Uniform(4.0, 8.0))), 4, 25);
  constexpr int kKinds = 9;
  constexpr double kGap_m = 0.03, kMargin_m = 0.05;
  const Eigen::Vector2d half = out.table.is_disc
                                   ? Eigen::Vector2d::Constant(0.5 * out.table.diameter_m)
                                   : Eigen::Vector2d(0.5 * out.table.size_m);
  for (int attempt = 0; attempt < 4000 && static_cast<int>(out.structures.size()) < wanted;
       ++attempt) {
    RandomStructure s;
    const int n = static_cast<int>(out.structures.size());
    s.kind = static_cast<RandomStructureKind>(n < kKinds ? (n + options.seed) % kKinds
                                                         : rng.Index(kKinds));
    DrawShape(&rng, &s);
    s.centre_in_table_m = {rng.Uniform(-half.x(), half.x()), rng.Uniform(-half.y(), half.y())};
    s.yaw_rad = rng.Uniform(0.0, kPi);
    if (!out.table.Contains(s.centre_in_table_m, s.FootprintRadius_m() + kMargin_m)) continue;
    bool clear = true;
    for (const RandomStructure& o : out.structures) {
      if ((o.centre_in_table_m - s.centre_in_table_m).norm() <
          o.FootprintRadius_m() + s.FootprintRadius_m() + kGap_m) {
        clear = false;
        break;
      }
    }
    if (!clear) continue;
    double low = 1e9, high = -1e9;
    for (const Eigen::Vector2d& xy : FootprintSamples(s)) {
      const double z = Height(hills, out.table, xy, options.taper_m);
      low = std::min(low, z);
      high = std::max(high, z);
    }
    // The walls go 2 mm below the lowest ground under them (none shows a gap on a slope).
    s.base_z_m = std::max(0.0, low - 0.002);
    s.height_m += high - s.base_z_m;
    out.structures.push_back(s);
  }
  for (const RandomStructure& s : out.structures) {
    ps.scene.Append(StructureMesh(s, &rng));
    Building b;
    b.centre_in_table_m = s.centre_in_table_m;
    b.yaw_rad = s.yaw_rad;
    b.width_m = s.width_m;
    b.depth_m = s.depth_m;
    b.height_m = s.base_z_m + s.height_m;
    ps.buildings.push_back(b);
  }
  return out;
}

std::optional<uint64_t> ParseRandomSeedName(const std::string& text) {
  constexpr std::string_view kPrefix = "random:";
  if (text.size() <= kPrefix.size() || text.compare(0, kPrefix.size(), kPrefix) != 0) {
    return std::nullopt;
  }
  const std::string digits = text.substr(kPrefix.size());
  if (digits.size() > 18 || digits.find_first_not_of("0123456789") != std::string::npos) {
    return std::nullopt;
  }
  return std::stoull(digits);
}

}  // namespace sandtable
