// sandtable-world against hostile inputs and a full disk: a directory, FIFO or /dev/zero as the
// site or scene, a PNG frame whose header claims 40000x40000 px, a render past kMaxViewPixels,
// a thin scene whose top view would need ~1e10 rows, a site with a 1e19 m translation or 2000
// units, and make-scene / make-site / render writing onto a full disk (RLIMIT_FSIZE, SIGXFSZ
// ignored). Every bad input exits 2 with one line naming the file, flag or limit, at once;
// a failed write exits 1, prints no "wrote" and leaves the previous file.
#include <signal.h>
#include <sys/resource.h>
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "common/cli/command_line.h"
#include "common/scene/gltf_writer.h"
#include "common/scene/procedural_scene.h"
#include "sim/app/world_commands.h"
#include "sim/site/site_json.h"
#include "sim/site/site_presets.h"
#include "sim/transport/view.h"
#include "tests/coordinator/membership/child_process.h"
#include "tests/testing/full_disk.h"

namespace sandtable::sim {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

// A refusal comes before any work: far under this even on a loaded 2-core machine.
constexpr std::chrono::milliseconds kRefusalDeadline{30000};

using test_support::FullDisk;

class WorldInputsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("sandtable_world_inputs_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }
  static std::string Get(const std::string& path) {
    std::ifstream in(path, std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(in), {});
  }
  // A flat-4 site and the flat scene, written.
  void WriteFlatWorld() {
    ASSERT_TRUE(WriteSiteFile(*MakeSitePreset("flat-4"), Path("site.json")).ok());
    ProceduralSceneOptions options;
    options.preset = ScenePreset::kFlat;
    ASSERT_TRUE(WriteGltfScene(MakeProceduralScene(options)->scene, Path("scene.glb")).ok());
  }
  int World(std::vector<std::string> args, std::string* output) const {
    return testing::RunProgram(SANDTABLE_WORLD_BIN, std::move(args), kRefusalDeadline, output);
  }
  void ExpectUsage(const std::vector<std::string>& args, const std::string& part) const {
    std::string output;
    EXPECT_EQ(World(args, &output), cli::kExitUsage) << output;
    EXPECT_NE(output.find(part), std::string::npos) << output;
    EXPECT_EQ(output.find("internal error"), std::string::npos) << output;
  }

  fs::path dir_;
};

TEST_F(WorldInputsTest, NotAFileAsSiteOrSceneExitsTwo) {
  WriteFlatWorld();
  const std::string fifo = Path("fifo");
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  for (const std::string& bad : {dir_.string(), fifo, std::string("/dev/zero")}) {
    ExpectUsage({"render", "--site", bad, "--scene", Path("scene.glb"), "--view", "top", "-o",
                 Path("out.png")},
                bad);
    ExpectUsage({"render", "--site", Path("site.json"), "--scene", bad, "--view", "top", "-o",
                 Path("out.png")},
                bad);
  }
}

TEST_F(WorldInputsTest, HugePngFrameIsRefusedByItsHeader) {
  WriteFlatWorld();
  std::string png = "\x89PNG\r\n\x1a\n" + std::string("\0\0\0\x0dIHDR", 8);
  for (uint32_t v : {40000u, 40000u}) {
    for (int shift = 24; shift >= 0; shift -= 8) png += static_cast<char>((v >> shift) & 0xff);
  }
  png += std::string("\x08\x00\x00\x00\x00\x00\x00\x00\x00", 9);
  std::ofstream(Path("huge.png"), std::ios::binary) << png;
  const std::string id = std::to_string(MakeSitePreset("flat-4")->units[0].id);
  ExpectUsage({"render", "--site", Path("site.json"), "--scene", Path("scene.glb"), "--view", "top",
               "--frame", id + "=" + Path("huge.png"), "-o", Path("out.png")},
              "kMaxImageSide_px");
}

TEST_F(WorldInputsTest, RenderPastTheRasterLimitsExitsTwo) {
  WriteFlatWorld();
  ExpectUsage({"render", "--site", Path("site.json"), "--scene", Path("scene.glb"), "--view", "top",
               "--width", "8192", "--height", "8192", "-o", Path("out.png")},
              "kMaxViewPixels");
  ExpectUsage({"render", "--site", Path("site.json"), "--scene", Path("scene.glb"), "--view", "top",
               "--width", "16384", "-o", Path("out.png")},
              "--width");
  EXPECT_FALSE(fs::exists(Path("out.png")));
}

TEST_F(WorldInputsTest, ThinSceneTopViewIsRefusedNotAllocated) {
  // A strip 1 um wide and 10 m long: at 1024 px across, its top view would need 1e10 rows.
  Scene thin;
  thin.positions_in_table_m = {{0, -5, 0}, {1e-6f, -5, 0}, {0, 5, 0}};
  thin.triangles = {{0, 1, 2}};
  thin.triangle_material = {0};
  thin.materials = {Material{}};
  const Expected<View> view = View::TopOver(thin.Bounds(), 1024, 0);
  ASSERT_FALSE(view.ok());
  EXPECT_NE(view.status().message().find("kMaxViewSide_px"), std::string::npos)
      << view.status().ToString();
  // And a flat extent (all x equal) is refused, not divided by.
  Scene line = thin;
  line.positions_in_table_m[1].x() = 0;
  EXPECT_FALSE(View::TopOver(line.Bounds(), 1024, 0).ok());
  // Through the program.
  ASSERT_TRUE(WriteSiteFile(*MakeSitePreset("flat-4"), Path("site.json")).ok());
  ASSERT_TRUE(WriteGltfScene(thin, Path("thin.glb")).ok());
  ExpectUsage({"render", "--site", Path("site.json"), "--scene", Path("thin.glb"), "--view", "top",
               "-o", Path("out.png")},
              "kMaxViewSide_px");
}

TEST_F(WorldInputsTest, AbsurdSitesExitTwo) {
  WriteFlatWorld();
  json site = SiteToJson(*MakeSitePreset("flat-4"));
  site["units"][0]["projector"]["table_from_projector"]["translation_m"][1] = 1e19;
  std::ofstream(Path("far.json")) << site.dump();
  ExpectUsage({"render", "--site", Path("far.json"), "--scene", Path("scene.glb"), "--view", "top",
               "-o", Path("out.png")},
              "kMaxSiteCoordinate_m");
  site = SiteToJson(*MakeSitePreset("flat-4"));
  json units = json::array();
  for (int i = 0; i < 2000; ++i) {
    json unit = site["units"][0];
    unit["id"] = i;
    units.push_back(unit);
  }
  site["units"] = units;
  std::ofstream(Path("many.json")) << site.dump();
  ExpectUsage({"render", "--site", Path("many.json"), "--scene", Path("scene.glb"), "--view", "top",
               "-o", Path("out.png")},
              "kMaxSiteUnits");
}

TEST_F(WorldInputsTest, FullDiskKeepsPreviousOutputsAndNeverSaysWrote) {
  MakeSceneArgs scene_args;
  scene_args.preset = "flat";
  scene_args.output = Path("scene.glb");
  std::ostringstream out, err;
  ASSERT_EQ(MakeSceneCommand(scene_args, out, err), cli::kExitOk) << err.str();
  const std::string scene_before = Get(scene_args.output);
  ASSERT_GT(scene_before.size(), 0u);
  MakeSiteArgs site_args;
  site_args.preset = "flat-4";
  site_args.output = Path("site.json");
  site_args.factory_dir = Path("factory");
  ASSERT_EQ(MakeSiteCommand(site_args, out, err), cli::kExitOk) << err.str();
  const std::string site_before = Get(site_args.output);
  RenderArgs render_args;
  render_args.site = site_args.output;
  render_args.scene = scene_args.output;
  render_args.view = "top";
  render_args.width_px = 64;
  render_args.white = true;
  render_args.output = Path("top.png");
  ASSERT_EQ(RenderCommand(render_args, out, err), cli::kExitOk) << err.str();
  const std::string png_before = Get(render_args.output);

  {
    const FullDisk full(32);  // less than a PNG signature and IHDR
    std::ostringstream scene_out, scene_err, site_out, site_err, render_out, render_err;
    scene_args.seed = 7;
    EXPECT_EQ(MakeSceneCommand(scene_args, scene_out, scene_err), cli::kExitFailure);
    EXPECT_EQ(scene_out.str().find("wrote"), std::string::npos) << scene_out.str();
    EXPECT_NE(scene_err.str().find(scene_args.output), std::string::npos) << scene_err.str();
    EXPECT_EQ(MakeSiteCommand(site_args, site_out, site_err), cli::kExitFailure);
    EXPECT_EQ(site_out.str().find("wrote"), std::string::npos) << site_out.str();
    render_args.width_px = 96;
    EXPECT_EQ(RenderCommand(render_args, render_out, render_err), cli::kExitFailure);
    EXPECT_EQ(render_out.str().find("wrote"), std::string::npos) << render_out.str();
  }
  EXPECT_EQ(Get(scene_args.output), scene_before);
  EXPECT_EQ(Get(site_args.output), site_before);
  EXPECT_EQ(Get(render_args.output), png_before);
  // No temporary file is left behind.
  std::set<std::string> names;
  for (const auto& entry : fs::directory_iterator(dir_)) names.insert(entry.path().filename());
  EXPECT_EQ(names, (std::set<std::string>{"factory", "scene.glb", "site.json", "top.png"}));
}

}  // namespace
}  // namespace sandtable::sim
