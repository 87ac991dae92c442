// The lab on sites and scenes it has never seen, written here rather than taken from the presets
// (issue 14, "Robustness of the lab itself"):
//   mixed-3 over terrain-bridge: a rectangular table; projectors of 1280x800, 1024x768 with a lens
//     shift, and one with strong barrel distortion; cameras of 16, 12 and 8 bits; the ground a
//     heightfield with a hill on it (not flat), a bridge whose deck hangs over the table (an
//     overhang) and a building.
//   pair-2 over cantilever-block: two projectors of 1280x800 and 800x500 (another throw), 10 and
//     8-bit cameras, another rectangle; an L-shaped building, a gabled one, a tower and a roof
//     slab that juts out past its walls (an overhang).
// Each runs to its end: status ok, every unit self-calibrated by structured light and registered
// to the truth within a bound, the show and the blend measured, report.md and report.html
// written, no process left. A site file and a glTF that are not valid are refused with exit 2
// and a message naming the file and the field.
#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <iterator>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "common/scene/gltf_writer.h"
#include "common/scene/procedural_scene.h"
#include "sim/site/site_json.h"
#include "sim/site/site_presets.h"
#include "tests/coordinator/membership/child_process.h"

namespace sandtable::sim {
namespace {

using nlohmann::json;
using std::chrono::milliseconds;
using testing::ChildProcess;

constexpr milliseconds kRunDeadline{300000};
// Registration of a site the lab has never seen, self-calibrated: sandtable-3 reaches 0.12 mm;
// these sites have fewer cameras per projector and harder optics. A wrong geometry is
// centimetres off.
constexpr double kRegistrationRms_mm = 3.0;

// A material per kind: the table (0) and the buildings (1).
Scene WithMaterials(Scene scene) {
  Material table;
  table.name = "table";
  table.base_color_factor = {0.8, 0.8, 0.8, 1.0};
  Material building;
  building.name = "building";
  building.base_color_factor = {0.9, 0.9, 0.9, 1.0};
  scene.materials = {table, building};
  return scene;
}

// The ground as a heightfield over a size_x x size_y rectangle centred on the origin, `step_m`
// apart, z = height(x, y); faces up (counter-clockwise seen from above).
Scene Heightfield(double size_x, double size_y, double step_m,
                  const std::function<double(double, double)>& height) {
  Scene s;
  const int nx = static_cast<int>(std::round(size_x / step_m));
  const int ny = static_cast<int>(std::round(size_y / step_m));
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) {
      const double x = -0.5 * size_x + size_x * i / nx;
      const double y = -0.5 * size_y + size_y * j / ny;
      s.positions_in_table_m.emplace_back(static_cast<float>(x), static_cast<float>(y),
                                          static_cast<float>(height(x, y)));
    }
  }
  auto at = [&](int i, int j) { return j * (nx + 1) + i; };
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      s.triangles.emplace_back(at(i, j), at(i + 1, j), at(i + 1, j + 1));
      s.triangles.emplace_back(at(i, j), at(i + 1, j + 1), at(i, j + 1));
      s.triangle_material.push_back(0);
      s.triangle_material.push_back(0);
    }
  }
  return s;
}

Scene TerrainBridge() {
  // A hill 60 mm high, a cosine bell 0.5 m across, on an otherwise flat ground of 1.6 x 1.2 m.
  Scene s = Heightfield(1.6, 1.2, 0.02, [](double x, double y) {
    const double r = std::hypot(x + 0.3, y - 0.15) / 0.25;
    return r < 1.0 ? 0.06 * 0.5 * (1.0 + std::cos(M_PI * r)) : 0.0;
  });
  // The bridge: two piers and a deck 100 mm above the table between them.
  s.Append(MakeBoxMesh({0.22, -0.25, 0.0}, {0.03, 0.09, 0.10}, 0.0, 1));
  s.Append(MakeBoxMesh({0.52, -0.25, 0.0}, {0.03, 0.09, 0.10}, 0.0, 1));
  s.Append(MakeBoxMesh({0.37, -0.25, 0.10}, {0.40, 0.10, 0.02}, 0.0, 1));
  s.Append(MakeBoxMesh({-0.35, -0.3, 0.0}, {0.14, 0.10, 0.16}, 0.4, 1));
  s.Append(MakeBoxMesh({0.35, 0.3, 0.0}, {0.10, 0.12, 0.12}, -0.2, 1));
  return WithMaterials(std::move(s));
}

Scene CantileverBlock() {
  Scene s = MakeRectangleMesh({1.4, 1.0}, 0);
  Building l;
  l.shape = BuildingShape::kLShape;
  l.centre_in_table_m = {-0.3, 0.2};
  l.width_m = 0.2;
  l.depth_m = 0.16;
  l.height_m = 0.12;
  s.Append(MakeBuildingMesh(l, 1));
  Building gabled = l;
  gabled.shape = BuildingShape::kGabled;
  gabled.centre_in_table_m = {0.25, 0.2};
  gabled.yaw_rad = 0.5;
  gabled.width_m = 0.14;
  gabled.height_m = 0.10;
  s.Append(MakeBuildingMesh(gabled, 1));
  Building tower = l;
  tower.shape = BuildingShape::kTower;
  tower.centre_in_table_m = {0.0, -0.1};
  tower.width_m = tower.depth_m = 0.08;
  tower.height_m = 0.25;
  s.Append(MakeBuildingMesh(tower, 1));
  // A block whose roof slab juts 60 mm past its walls on one side.
  s.Append(MakeBoxMesh({0.3, -0.25, 0.0}, {0.10, 0.10, 0.08}, 0.0, 1));
  s.Append(MakeBoxMesh({0.33, -0.25, 0.08}, {0.16, 0.12, 0.015}, 0.0, 1));
  return WithMaterials(std::move(s));
}

// A projector of the site file made width x height at the same field of view across, its image
// shifted up by `shift_v` of its height (a lens shift).
void Resize(json* projector, int width, int height, double shift_v) {
  json& p = *projector;
  const double scale = static_cast<double>(width) / p["width_px"].get<double>();
  p["fx_px"] = p["fy_px"] = p["fx_px"].get<double>() * scale;
  p["width_px"] = width;
  p["height_px"] = height;
  p["cx_px"] = 0.5 * (width - 1);
  p["cy_px"] = 0.5 * (height - 1) + shift_v * height;
}

class LabRobustnessTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = std::filesystem::temp_directory_path() /
           ("sandtable_lab_robust_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    std::filesystem::remove_all(dir_);
    std::filesystem::create_directories(dir_);
  }
  void TearDown() override {
    if (std::getenv("SANDTABLE_KEEP_LAB_DIR") == nullptr) std::filesystem::remove_all(dir_);
  }

  // sandtable-3 as JSON, to be edited into a site of the test's own.
  json Sandtable3() const {
    Expected<Site> site = MakeSitePreset("sandtable-3");
    EXPECT_TRUE(site.ok());
    const std::string path = (dir_ / "sandtable-3.json").string();
    EXPECT_TRUE(WriteSiteFile(*site, path).ok());
    std::ifstream in(path);
    return json::parse(in);
  }

  std::string Write(const json& j, const std::string& name) const {
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << j.dump(2);
    return path;
  }

  // The lab's output lines and exit code.
  struct Ran {
    int code = -1;
    std::string output;
  };
  Ran RunLab(const std::vector<std::string>& extra) const {
    std::vector<std::string> args = {SANDTABLE_LAB_BIN, "run", "--samples",  "6000",
                                     "--image-width",   "200", "--progress", "plain"};
    args.insert(args.end(), extra.begin(), extra.end());
    ChildProcess lab(args, testing::ChildOutput::kStdoutAndStderr);
    Ran ran;
    while (std::optional<std::string> line = lab.ReadLine(kRunDeadline)) ran.output += *line + "\n";
    ran.code = lab.Wait();
    return ran;
  }

  // The site (written as NAME.json, its "name" the site's) and the scene (SCENE.gltf) through
  // the lab, out to DIR/NAME.
  void ExpectRunsToItsEnd(const json& site, const Scene& scene, const std::string& scene_name,
                          size_t units) {
    const std::string name = site["name"].get<std::string>();
    const std::string site_path = Write(site, name + ".json");
    const std::string scene_path = (dir_ / (scene_name + ".gltf")).string();
    ASSERT_TRUE(WriteGltfScene(scene, scene_path).ok());
    const std::filesystem::path out = dir_ / name;
    const Ran ran = RunLab({"--site", site_path, "--scene", scene_path, "--out", out.string()});
    ASSERT_EQ(ran.code, 0) << ran.output;
    std::ifstream in(out / "report.json");
    const json report = json::parse(in, nullptr, false);
    ASSERT_FALSE(report.is_discarded());
    EXPECT_EQ(report["status"], "ok");
    const json& calibration = report["calibration"];
    EXPECT_EQ(calibration["source"], "structured_light");
    ASSERT_EQ(calibration["per_unit"].size(), units) << calibration["per_unit"].dump();
    for (const auto& [id, unit] : calibration["per_unit"].items()) {
      EXPECT_EQ(unit["source"], "structured_light") << "unit " << id;
    }
    EXPECT_LT(calibration["rms_mm"].get<double>(), kRegistrationRms_mm) << calibration.dump();
    // The show and the blend were measured on it.
    EXPECT_FALSE(report["render"].contains("error")) << report["render"].dump();
    EXPECT_TRUE(report["render"].contains("frame_ms_p50")) << report["render"].dump();
    EXPECT_TRUE(report["photometric"].contains("table")) << report["photometric"].dump();
    for (const char* file : {"report.md", "report.html", "top_white.png"}) {
      EXPECT_TRUE(std::filesystem::exists(out / file)) << file;
    }
  }

  std::filesystem::path dir_;
};

TEST_F(LabRobustnessTest, MixedOpticsOverTerrainAndABridge) {
  json site = Sandtable3();
  site["name"] = "mixed-3";
  site["table"] = {{"shape", "rectangle"}, {"size_m", {1.6, 1.2}}};
  Resize(&site["units"][1]["projector"], 1024, 768, 0.08);
  site["units"][2]["projector"]["distortion_k1_k2_p1_p2_k3"] = {0.12, -0.04, 0.0, 0.0, 0.0};
  site["units"][0]["camera"]["bit_depth"] = 16;
  site["units"][1]["camera"]["bit_depth"] = 12;
  ExpectRunsToItsEnd(site, TerrainBridge(), "terrain-bridge", 3);
}

TEST_F(LabRobustnessTest, TwoProjectorsOfOtherSizesOverACantilever) {
  json site = Sandtable3();
  site["name"] = "pair-2";
  site["table"] = {{"shape", "rectangle"}, {"size_m", {1.4, 1.0}}};
  json units = json::array({site["units"][0], site["units"][2]});
  units[1]["id"] = 1;
  units[1]["name"] = "unit-1";
  Resize(&units[1]["projector"], 800, 500, 0.0);
  units[0]["camera"]["bit_depth"] = 10;
  site["units"] = units;
  ExpectRunsToItsEnd(site, CantileverBlock(), "cantilever-block", 2);
}

TEST_F(LabRobustnessTest, RefusesAnInvalidSiteOrSceneNamingTheFileAndField) {
  json site = Sandtable3();
  site["units"][1]["camera"]["bit_depth"] = 40;
  const std::string bad_site = Write(site, "bad-site.json");
  Ran ran = RunLab({"--site", bad_site, "--scene", "sandtable", "--out", (dir_ / "a").string()});
  EXPECT_EQ(ran.code, 2) << ran.output;
  EXPECT_NE(ran.output.find("bad-site.json"), std::string::npos) << ran.output;
  EXPECT_NE(ran.output.find("bit_depth"), std::string::npos) << ran.output;
  // A glTF whose accessor points past its buffer.
  const std::string bad_scene = (dir_ / "bad-scene.gltf").string();
  std::ofstream(bad_scene)
      << R"({"asset":{"version":"2.0"},"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
    "meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],
    "accessors":[{"bufferView":0,"componentType":5126,"count":300,"type":"VEC3"}],
    "bufferViews":[{"buffer":0,"byteLength":36}],
    "buffers":[{"byteLength":36,"uri":"data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAACAPwAAAAAAAAAAAAAAAAAAgD8AAAAA"}]})";
  ran = RunLab({"--site", "sandtable-3", "--scene", bad_scene, "--out", (dir_ / "b").string()});
  EXPECT_EQ(ran.code, 2) << ran.output;
  EXPECT_NE(ran.output.find("bad-scene.gltf"), std::string::npos) << ran.output;
  EXPECT_NE(ran.output.find("accessor"), std::string::npos) << ran.output;
}

}  // namespace
}  // namespace sandtable::sim
