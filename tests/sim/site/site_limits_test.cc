// Hostile site files: not a file (directory, FIFO, /dev/zero), empty, absurd geometry (a 1e19 m
// or NaN translation), 2000 units, huge projector and camera resolutions. Each is refused with
// a message naming the file, field or limit, quickly.
#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>

#include <gtest/gtest.h>

#include "sim/site/site_json.h"
#include "sim/site/site_presets.h"

namespace sandtable::sim {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr double kMaxRefusalTime_s = 5.0;

class SiteLimitsTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("sandtable_site_limits_" + std::to_string(getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::create_directories(dir_);
    site_ = SiteToJson(*MakeSitePreset("sandtable-3"));
  }
  void TearDown() override { fs::remove_all(dir_); }
  std::string Write(const std::string& name, const std::string& text) const {
    const std::string path = (dir_ / name).string();
    std::ofstream(path) << text;
    return path;
  }
  // Loads the text as a site file; the error (or OK) with its time.
  Status Load(const std::string& text, double* seconds = nullptr) const {
    const std::string path = Write("site.json", text);
    const auto start = std::chrono::steady_clock::now();
    const Status status = LoadSiteFile(path).status();
    if (seconds) {
      *seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    }
    return status;
  }
  void ExpectRefused(const json& site, const std::string& part) const {
    double seconds = 0;
    const Status status = Load(site.dump(), &seconds);
    ASSERT_FALSE(status.ok()) << part;
    EXPECT_NE(status.message().find(part), std::string::npos) << status.ToString();
    EXPECT_NE(status.message().find("site.json"), std::string::npos) << status.ToString();
    EXPECT_LT(seconds, kMaxRefusalTime_s);
  }

  fs::path dir_;
  json site_;
};

TEST_F(SiteLimitsTest, ThePresetLoads) { EXPECT_TRUE(Load(site_.dump()).ok()); }

TEST_F(SiteLimitsTest, NotAFileIsRefusedByName) {
  const std::string fifo = (dir_ / "fifo.json").string();
  ASSERT_EQ(::mkfifo(fifo.c_str(), 0600), 0);
  for (const std::string& path : {dir_.string(), fifo, std::string("/dev/zero")}) {
    const auto start = std::chrono::steady_clock::now();
    const Status status = LoadSiteFile(path).status();
    ASSERT_FALSE(status.ok()) << path;
    EXPECT_EQ(status.code(), StatusCode::kIoError);
    EXPECT_NE(status.message().find(path), std::string::npos) << status.ToString();
    EXPECT_NE(status.message().find("regular file"), std::string::npos) << status.ToString();
    EXPECT_LT(std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count(),
              kMaxRefusalTime_s);
  }
  const Status empty = Load("");
  EXPECT_NE(empty.message().find("empty file"), std::string::npos) << empty.ToString();
}

TEST_F(SiteLimitsTest, AbsurdTranslationsAreRefused) {
  for (double bad : {1e19, -1e5, std::numeric_limits<double>::max()}) {
    json site = site_;
    site["units"][0]["projector"]["table_from_projector"]["translation_m"][0] = bad;
    ExpectRefused(site, "kMaxSiteCoordinate_m");
    site = site_;
    site["units"][2]["camera"]["projector_from_camera"]["translation_m"][2] = bad;
    ExpectRefused(site, "kMaxSiteCoordinate_m");
  }
  // NaN and infinity are not JSON numbers: written as text they fail to parse, by name.
  json site = site_;
  std::string text = site.dump();
  const std::string key = "\"translation_m\":[";
  text.insert(text.find(key) + key.size(), "1e400,");
  const Status status = Load(text);
  EXPECT_FALSE(status.ok());
}

TEST_F(SiteLimitsTest, TooManyUnitsAreRefusedBeforeReadingThem) {
  json site = site_;
  json units = json::array();
  for (int i = 0; i < 2000; ++i) {
    json unit = site_["units"][i % 3];
    unit["id"] = i;
    units.push_back(unit);
  }
  site["units"] = units;
  ExpectRefused(site, "kMaxSiteUnits");
}

TEST_F(SiteLimitsTest, HugeResolutionsAreRefused) {
  json site = site_;
  site["units"][0]["projector"]["width_px"] = 65536;
  ExpectRefused(site, "kMaxSiteImageSide_px");
  site = site_;
  site["units"][1]["camera"]["width_px"] = 8000;
  site["units"][1]["camera"]["height_px"] = 8000;
  ExpectRefused(site, "kMaxSiteImagePixels");
}

TEST_F(SiteLimitsTest, SiteCheckAppliesTheLimitsToSitesMadeInCode) {
  Site site = *MakeSitePreset("sandtable-3");
  site.units[0].projector.table_from_projector.translation.x() = 1e19;
  EXPECT_NE(site.Check().message().find("kMaxSiteCoordinate_m"), std::string::npos);
  site = *MakeSitePreset("grid-32");
  const std::vector<UnitSpec> units = site.units;
  while (site.units.size() <= kMaxSiteUnits) {
    UnitSpec unit = units[site.units.size() % units.size()];
    unit.id = static_cast<NodeId>(site.units.size());
    site.units.push_back(unit);
  }
  EXPECT_NE(site.Check().message().find("kMaxSiteUnits"), std::string::npos);
}

}  // namespace
}  // namespace sandtable::sim
