// Site and unit configuration files (common/cli/config_file.h): what each key becomes for each
// program, relative paths from the file's folder, the command line winning over the files and
// the unit's file over the site's, and every malformed file refused naming the file and key.
#include "common/cli/config_file.h"

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

namespace sandtable::cli {
namespace {

namespace fs = std::filesystem;
using Words = std::vector<std::string>;

class ConfigFileTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() /
           ("sandtable_config_file_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "etc");
  }
  void TearDown() override { fs::remove_all(dir_); }
  fs::path Write(const std::string& name, const std::string& text) {
    const fs::path p = dir_ / "etc" / name;
    std::ofstream(p) << text;
    return p;
  }
  fs::path dir_;
};

constexpr char kSite[] = R"({
  "format": "sandtable.site_config", "version": 1,
  "coordinator": {"host": "10.0.0.1", "requests_port": 7000, "events_port": 7001},
  "curve_keys": "site.keys",
  "status": {"listen": "0.0.0.0:8080", "token_file": "/etc/sandtable/status.token"},
  "heartbeat_ms": 50, "misses": 7, "model": "../models/city.glb", "expect_units": 3,
  "node_flags": {"render-max-fps": 24.5, "blend": "on", "workers": 2},
  "coordinator_flags": {"annotations": "/var/lib/sandtable/annotations.db"}
})";

TEST_F(ConfigFileTest, SiteFileSetsEachProgramsFlags) {
  const fs::path site = Write("site.json", kSite);
  const std::string etc = (dir_ / "etc").string();
  Expected<Words> node = SiteConfigFlags(site, ConfigProgram::kNode);
  ASSERT_TRUE(node.ok()) << node.status().ToString();
  EXPECT_EQ(*node, (Words{"--coordinator", "tcp://10.0.0.1:7000,tcp://10.0.0.1:7001",
                          "--curve-keys", etc + "/site.keys", "--heartbeat-ms", "50", "--model",
                          (dir_ / "models" / "city.glb").string(), "--expect-units", "3", "--blend",
                          "on", "--render-max-fps", "24.5", "--workers", "2"}));
  Expected<Words> coordinator = SiteConfigFlags(site, ConfigProgram::kCoordinator);
  ASSERT_TRUE(coordinator.ok()) << coordinator.status().ToString();
  EXPECT_EQ(*coordinator,
            (Words{"--requests", "tcp://*:7000", "--events", "tcp://*:7001", "--curve-keys",
                   etc + "/site.keys", "--heartbeat-ms", "50", "--scene",
                   (dir_ / "models" / "city.glb").string(), "--status", "0.0.0.0:8080",
                   "--status-token-file", "/etc/sandtable/status.token", "--misses", "7",
                   "--annotations", "/var/lib/sandtable/annotations.db"}));
}

// A site whose nodes find the coordinator by its beacon (docs/deploy.md): the coordinator section
// gives only where it listens; the nodes discover it.
TEST_F(ConfigFileTest, ADiscoverySiteGivesTheCoordinatorItsPortsAndTheNodesNoAddress) {
  const fs::path site = Write("site.json", R"({
    "format": "sandtable.site_config", "version": 1,
    "discovery": {"port": 5670, "site": "hall-b"},
    "coordinator": {"listen": "*", "requests_port": 7000, "events_port": 7001}
  })");
  Expected<Words> node = SiteConfigFlags(site, ConfigProgram::kNode);
  ASSERT_TRUE(node.ok()) << node.status().ToString();
  EXPECT_EQ(*node, (Words{"--coordinator", "discover", "--discovery-port", "5670", "--site-name",
                          "hall-b"}));
  Expected<Words> coordinator = SiteConfigFlags(site, ConfigProgram::kCoordinator);
  ASSERT_TRUE(coordinator.ok()) << coordinator.status().ToString();
  EXPECT_EQ(*coordinator, (Words{"--requests", "tcp://*:7000", "--events", "tcp://*:7001",
                                 "--beacon", "5670", "--site-name", "hall-b"}));
}

// A site that accepts new units (docs/deploy.md, "Accepting a new unit"): the coordinator listens
// for their requests; a node's key file becomes --enroll, so a unit without it yet asks for it.
TEST_F(ConfigFileTest, AnEnrollPortOpensTheCoordinatorsDeskAndLetsANodeAskForTheKey) {
  const fs::path site = Write("site.json", R"({
    "format": "sandtable.site_config", "version": 1,
    "discovery": {"port": 5670, "enroll_port": 7002},
    "coordinator": {"listen": "10.0.0.1", "requests_port": 7000, "events_port": 7001},
    "curve_keys": "site.keys"
  })");
  const std::string keys = (dir_ / "etc" / "site.keys").string();
  Expected<Words> node = SiteConfigFlags(site, ConfigProgram::kNode);
  ASSERT_TRUE(node.ok()) << node.status().ToString();
  EXPECT_EQ(*node,
            (Words{"--enroll", keys, "--coordinator", "discover", "--discovery-port", "5670"}));
  Expected<Words> coordinator = SiteConfigFlags(site, ConfigProgram::kCoordinator);
  ASSERT_TRUE(coordinator.ok()) << coordinator.status().ToString();
  EXPECT_EQ(*coordinator,
            (Words{"--requests", "tcp://10.0.0.1:7000", "--events", "tcp://10.0.0.1:7001",
                   "--curve-keys", keys, "--enroll", "tcp://10.0.0.1:7002", "--beacon", "5670"}));
  const fs::path no_keys = Write("no_keys.json", R"({
    "format": "sandtable.site_config", "version": 1,
    "discovery": {"enroll_port": 7002},
    "coordinator": {"requests_port": 7000, "events_port": 7001}
  })");
  Expected<Words> refused = SiteConfigFlags(no_keys, ConfigProgram::kCoordinator);
  ASSERT_FALSE(refused.ok());
  EXPECT_NE(refused.status().message().find("discovery.enroll_port"), std::string::npos)
      << refused.status().message();
}

TEST_F(ConfigFileTest, CommandLineWinsOverTheUnitFileOverTheSiteFile) {
  const fs::path site = Write("site.json", kSite);
  const fs::path unit = Write("unit.json", R"({
    "format": "sandtable.unit_config", "version": 1, "id": 3, "factory": "unit-3.factory.json",
    "camera": "video:0", "bind": "tcp://*:7100", "node_flags": {"workers": 4, "black-match": true}
  })");
  const Words args{"--site-config",     site.string(), "--unit-config",   unit.string(),
                   "--heartbeat-ms=20", "--camera",    "replay:/data/cam"};
  Expected<Words> expanded = ExpandConfigFiles(args, ConfigProgram::kNode);
  ASSERT_TRUE(expanded.ok()) << expanded.status().ToString();
  auto count = [&](const std::string& flag) {
    return std::count(expanded->begin(), expanded->end(), flag);
  };
  auto value = [&](const std::string& flag) {
    auto it = std::find(expanded->begin(), expanded->end(), flag);
    return it == expanded->end() || it + 1 == expanded->end() ? std::string() : *(it + 1);
  };
  // The command line's --heartbeat-ms=20 and --camera stay; the files' are left out.
  EXPECT_EQ(count("--heartbeat-ms"), 0);
  EXPECT_EQ(count("--camera"), 1);
  EXPECT_EQ(value("--camera"), "replay:/data/cam");
  // The unit's --workers 4 over the site's 2.
  EXPECT_EQ(count("--workers"), 1);
  EXPECT_EQ(value("--workers"), "4");
  EXPECT_EQ(count("--black-match"), 1);
  EXPECT_EQ(value("--id"), "3");
  EXPECT_EQ(value("--factory"), (dir_ / "etc" / "unit-3.factory.json").string());
  // The command line itself comes last, whole.
  ASSERT_GE(expanded->size(), args.size());
  EXPECT_EQ(Words(expanded->end() - static_cast<long>(args.size()), expanded->end()), args);
  // No file: the arguments as they are.
  Expected<Words> plain = ExpandConfigFiles({"--id", "1"}, ConfigProgram::kNode);
  ASSERT_TRUE(plain.ok());
  EXPECT_EQ(*plain, (Words{"--id", "1"}));
}

TEST_F(ConfigFileTest, MalformedFilesAreRefusedNamingFileAndKey) {
  struct Case {
    std::string text;
    std::string names;
  };
  const std::vector<Case> cases = {
      {"not json", "not JSON"},
      {"[1, 2]", "not a JSON object"},
      {R"({"version": 1})", "\"format\""},
      {R"({"format": "sandtable.unit_config", "version": 1})", "\"format\""},
      {R"({"format": "sandtable.site_config"})", "\"version\""},
      {R"({"format": "sandtable.site_config", "version": 2})", "newer sandtable"},
      {R"({"format": "sandtable.site_config", "version": 0})", "\"version\""},
      {R"({"format": "sandtable.site_config", "version": 1, "heartbeat": 5})", "\"heartbeat\""},
      {R"({"format": "sandtable.site_config", "version": 1, "heartbeat_ms": "fast"})",
       "\"heartbeat_ms\""},
      {R"({"format": "sandtable.site_config", "version": 1, "coordinator": {"host": "a"}})",
       "\"coordinator.requests_port\""},
      {R"({"format": "sandtable.site_config", "version": 1,
           "coordinator": {"requests_port": 7000, "events_port": 7001}})",
       "\"coordinator.host\""},
      {R"({"format": "sandtable.site_config", "version": 1,
           "coordinator": {"host": "a", "requests_port": 7000, "events_port": 70000}})",
       "1..65535"},
      {R"({"format": "sandtable.site_config", "version": 1, "curve_keys": ""})", "\"curve_keys\""},
      {R"({"format": "sandtable.site_config", "version": 1, "node_flags": {"--id": 3}})",
       "node_flags.--id"},
      {R"({"format": "sandtable.site_config", "version": 1, "node_flags": {"id": [3]}})",
       "node_flags.id"},
      {R"({"format": "sandtable.site_config", "version": 1,
           "node_flags": {"unit-config": "x.json"}})",
       "cannot name another"},
  };
  for (const Case& c : cases) {
    const fs::path site = Write("bad.json", c.text);
    Expected<Words> flags =
        ExpandConfigFiles({"--site-config", site.string()}, ConfigProgram::kNode);
    ASSERT_FALSE(flags.ok()) << c.text;
    EXPECT_NE(flags.status().message().find(site.string()), std::string::npos)
        << flags.status().message();
    EXPECT_NE(flags.status().message().find(c.names), std::string::npos)
        << c.text << " -> " << flags.status().message();
  }
  Expected<Words> missing =
      ExpandConfigFiles({"--site-config", (dir_ / "none.json").string()}, ConfigProgram::kNode);
  ASSERT_FALSE(missing.ok());
  EXPECT_EQ(missing.status().code(), StatusCode::kNotFound);
  const fs::path unit = Write("unit.json", R"({"format": "sandtable.unit_config", "version": 1})");
  Expected<Words> coordinator_unit =
      ExpandConfigFiles({"--unit-config", unit.string()}, ConfigProgram::kCoordinator);
  ASSERT_FALSE(coordinator_unit.ok());
  EXPECT_NE(coordinator_unit.status().message().find("only sandtable-node"), std::string::npos);
}

}  // namespace
}  // namespace sandtable::cli
