// The factory files of make-site --factory-dir are unit calibration files: a node loads the
// file the world wrote for it with LoadUnitCalibration (issue 9, "a node starts from the
// factory file the world wrote for it").
#include <cstdlib>
#include <filesystem>
#include <fstream>

#include <unistd.h>

#include <gtest/gtest.h>

#include "common/io/unit_calibration_file.h"
#include "sim/site/factory_calibration.h"
#include "sim/site/site_json.h"
#include "sim/site/site_presets.h"

namespace sandtable::sim {
namespace {

namespace fs = std::filesystem;

// Numbers are written in shortest round-trip form: the node reads exactly what the world wrote.
constexpr double kExact_px = 0.0;
constexpr double kTranslationTolerance_m = 1e-15;
constexpr double kRotationTolerance_rad = 1e-7;  // acos near 1 (see rigid3_test)

class FactoryFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("sandtable_factory_" + std::to_string(::getpid()));
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path dir_;
};

void ExpectSame(const FactoryCalibration& written, const UnitCalibration& read) {
  EXPECT_EQ(read.unit_id, written.unit_id);
  EXPECT_EQ(read.source, kSourceFactory);
  EXPECT_EQ(read.camera.width_px, written.camera.width_px);
  EXPECT_NEAR((read.camera.K() - written.camera.K()).norm(), 0.0, kExact_px);
  EXPECT_NEAR((read.projector.K() - written.projector.K()).norm(), 0.0, kExact_px);
  EXPECT_EQ(read.projector.distortion.k1, written.projector.distortion.k1);
  EXPECT_LT(
      (read.projector_from_camera.translation - written.projector_from_camera.translation).norm(),
      kTranslationTolerance_m);
  EXPECT_LT(RotationAngleBetween_rad(read.projector_from_camera, written.projector_from_camera),
            kRotationTolerance_rad);
  EXPECT_FALSE(read.table_from_projector.has_value());  // the factory does not know the site
}

TEST_F(FactoryFileTest, FactoryCalibrationToJsonLoadsWithLoadUnitCalibration) {
  const Site site = *MakeSitePreset("sandtable-3");
  for (const UnitSpec& unit : site.units) {
    Expected<FactoryCalibration> factory =
        MakeFactoryCalibration(unit, FactoryCalibrationError{}, 4);
    ASSERT_TRUE(factory.ok()) << factory.status().ToString();
    const nlohmann::json j = FactoryCalibrationToJson(*factory);
    EXPECT_EQ(j.at("format"), kUnitCalibrationFormat);
    EXPECT_EQ(j.at("version"), kUnitCalibrationVersion);
    const fs::path path = dir_ / ("unit-" + std::to_string(unit.id) + ".factory.json");
    std::ofstream(path) << j.dump(2) << "\n";  // as make-site writes it
    Expected<UnitCalibration> read = LoadUnitCalibration(path.string());
    ASSERT_TRUE(read.ok()) << read.status().ToString();
    ExpectSame(*factory, *read);
  }
}

#ifdef SANDTABLE_WORLD_BIN
TEST_F(FactoryFileTest, MakeSiteFactoryDirFilesLoadWithLoadUnitCalibration) {
  const std::string command = std::string(SANDTABLE_WORLD_BIN) +
                              " make-site --preset sandtable-3 --seed 4 --factory-dir " +
                              (dir_ / "factory").string() + " -o " + (dir_ / "site.json").string() +
                              " > " + (dir_ / "out.txt").string() + " 2>&1";
  ASSERT_EQ(std::system(command.c_str()), 0) << command;
  Expected<Site> site = LoadSiteFile((dir_ / "site.json").string());
  ASSERT_TRUE(site.ok()) << site.status().ToString();
  for (const UnitSpec& unit : site->units) {
    const fs::path path = dir_ / "factory" / ("unit-" + std::to_string(unit.id) + ".factory.json");
    Expected<UnitCalibration> read = LoadUnitCalibration(path.string());
    ASSERT_TRUE(read.ok()) << read.status().ToString();
    // The same seed gives the same factory calibration.
    ExpectSame(*MakeFactoryCalibration(unit, FactoryCalibrationError{}, 4), *read);
  }
}
#endif

}  // namespace
}  // namespace sandtable::sim
