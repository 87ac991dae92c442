// sandtable-node doctor (node/app/doctor_command.h) against the simulated world's unit 0 of
// sandtable-3 (half resolution) and a real coordinator: a unit set up right is ready; a factory
// file of another camera size, a key file others may read and a coordinator that is not there
// each fail, saying what to do.
#include "node/app/doctor_command.h"

#include <atomic>
#include <filesystem>
#include <fstream>
#include <memory>
#include <thread>

#include <gtest/gtest.h>

#include "common/io/unit_calibration_file.h"
#include "common/scene/gltf_loader.h"
#include "coordinator/membership/coordinator_server.h"
#include "net/curve.h"
#include "sim/app/world_server.h"
#include "sim/lab/lab_inputs.h"
#include "sim/transport/world.h"

namespace sandtable::node {
namespace {

namespace fs = std::filesystem;

class DoctorTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("doctor_test_" + std::to_string(getpid()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    Expected<sim::LabInputs> inputs =
        sim::PrepareLabInputs("sandtable-3", "sandtable", /*seed=*/1, dir_.string(), "",
                              /*resolution_scale=*/0.5);
    ASSERT_TRUE(inputs.ok()) << inputs.status().ToString();
    inputs_ = std::move(*inputs);
    Expected<Scene> scene = LoadGltfScene(inputs_.scene_path);
    ASSERT_TRUE(scene.ok()) << scene.status().ToString();
    Expected<std::unique_ptr<sim::World>> world = sim::World::Create(inputs_.site, *scene);
    ASSERT_TRUE(world.ok()) << world.status().ToString();
    world_ = std::make_unique<sim::WorldServer>(std::move(*world), sim::WorldServerOptions{});
    ASSERT_TRUE(world_->Start().ok());
    coordinator_ =
        std::make_unique<coordinator::CoordinatorServer>(coordinator::CoordinatorOptions{});
    ASSERT_TRUE(coordinator_->Start().ok());
    threads_.emplace_back([this] { (void)world_->Run(stop_); });
    threads_.emplace_back([this] { (void)coordinator_->Run(stop_); });
  }
  void TearDown() override {
    stop_ = true;
    for (std::thread& t : threads_) t.join();
    fs::remove_all(dir_);
  }

  // Unit 0 of the world, as its node would be started.
  NodeConfig Unit0() const {
    NodeConfig c;
    c.id = 0;
    c.world = world_->endpoint();
    c.factory_path = inputs_.factory_paths.at(0);
    c.coordinator_requests = coordinator_->request_endpoint();
    c.coordinator_events = coordinator_->event_endpoint();
    return c;
  }

  static const DoctorCheck& Named(const std::vector<DoctorCheck>& checks, const std::string& name) {
    static const DoctorCheck none{"(none)", CheckVerdict::kSkipped, "", ""};
    for (const DoctorCheck& c : checks) {
      if (c.name == name) return c;
    }
    ADD_FAILURE() << "no check named " << name;
    return none;
  }

  DoctorOptions Quick() const {
    DoctorOptions o;
    o.latency_flashes = 3;
    return o;
  }

  fs::path dir_;
  sim::LabInputs inputs_;
  std::atomic<bool> stop_{false};
  std::unique_ptr<sim::WorldServer> world_;
  std::unique_ptr<coordinator::CoordinatorServer> coordinator_;
  std::vector<std::thread> threads_;
};

TEST_F(DoctorTest, AUnitSetUpRightIsReady) {
  const std::vector<DoctorCheck> checks = RunDoctorChecks(Unit0(), Quick());
  const std::string text = FormatChecklist(checks);
  for (const char* name :
       {"factory file", "display", "camera", "light", "latency", "exposure", "coordinator"}) {
    EXPECT_EQ(Named(checks, name).verdict, CheckVerdict::kOk) << name << "\n" << text;
  }
  // No key file: unencrypted, a warning that does not stop the unit.
  EXPECT_EQ(Named(checks, "key file").verdict, CheckVerdict::kWarn) << text;
  EXPECT_TRUE(Ready(checks)) << text;
  EXPECT_NE(text.find("ready: yes"), std::string::npos) << text;
  EXPECT_NE(Named(checks, "display").detail.find("as the factory file"), std::string::npos);
}

TEST_F(DoctorTest, AnotherCamerasFactoryFileFailsNamingBothSizes) {
  Expected<UnitCalibration> factory = LoadUnitCalibration(inputs_.factory_paths.at(0));
  ASSERT_TRUE(factory.ok()) << factory.status().ToString();
  const int real_width = factory->camera.width_px;
  factory->camera.width_px += 64;
  factory->camera.cx_px += 32;
  const fs::path other = dir_ / "other-unit.json";
  ASSERT_TRUE(SaveUnitCalibration(*factory, other.string()).ok());
  NodeConfig c = Unit0();
  c.factory_path = other.string();
  const std::vector<DoctorCheck> checks = RunDoctorChecks(c, Quick());
  const std::string text = FormatChecklist(checks);
  const DoctorCheck& camera = Named(checks, "camera");
  EXPECT_EQ(camera.verdict, CheckVerdict::kFail) << text;
  EXPECT_NE(camera.detail.find(std::to_string(real_width) + "x"), std::string::npos) << text;
  EXPECT_NE(camera.detail.find(std::to_string(real_width + 64) + "x"), std::string::npos) << text;
  EXPECT_FALSE(camera.todo.empty());
  // What needs the camera is skipped, saying so; the coordinator is still checked.
  EXPECT_EQ(Named(checks, "light").verdict, CheckVerdict::kSkipped) << text;
  EXPECT_EQ(Named(checks, "latency").verdict, CheckVerdict::kSkipped) << text;
  EXPECT_EQ(Named(checks, "coordinator").verdict, CheckVerdict::kOk) << text;
  EXPECT_FALSE(Ready(checks));
  EXPECT_NE(text.find("ready: no (1 of 8 checks failed)"), std::string::npos) << text;
}

TEST_F(DoctorTest, AKeyFileOthersMayReadAndAnAbsentCoordinatorFail) {
  Expected<net::CurveKeyPair> keys = net::GenerateCurveKeyPair();
  ASSERT_TRUE(keys.ok());
  const fs::path key_file = dir_ / "site.key";
  ASSERT_TRUE(net::WriteCurveKeyFile(key_file.string(), *keys).ok());
  fs::permissions(key_file, fs::perms::group_read | fs::perms::others_read, fs::perm_options::add);
  NodeConfig c = Unit0();
  c.curve_keys_path = key_file.string();
  c.coordinator_requests = "tcp://127.0.0.1:1";  // nobody listens there
  c.coordinator_events = "tcp://127.0.0.1:2";
  DoctorOptions o = Quick();
  o.coordinator_timeout = std::chrono::milliseconds(300);
  const std::vector<DoctorCheck> checks = RunDoctorChecks(c, o);
  const std::string text = FormatChecklist(checks);
  const DoctorCheck& key = Named(checks, "key file");
  EXPECT_EQ(key.verdict, CheckVerdict::kFail) << text;
  EXPECT_NE(key.todo.find("chmod 600"), std::string::npos) << text;
  const DoctorCheck& coordinator = Named(checks, "coordinator");
  EXPECT_EQ(coordinator.verdict, CheckVerdict::kFail) << text;
  EXPECT_NE(coordinator.detail.find("did not answer within 300 ms"), std::string::npos) << text;
  EXPECT_EQ(Named(checks, "camera").verdict, CheckVerdict::kOk) << text;
  EXPECT_NE(text.find("ready: no (2 of 8 checks failed)"), std::string::npos) << text;
}

TEST(DoctorFormatTest, FailuresSayWhatToDo) {
  const std::vector<DoctorCheck> checks = {
      {"camera", CheckVerdict::kFail, "video:0: not found", "connect the camera"},
      {"display", CheckVerdict::kOk, "window:0, 1920x1080", ""}};
  const std::string text = FormatChecklist(checks);
  EXPECT_NE(text.find("[FAIL] camera   video:0: not found\n"), std::string::npos) << text;
  EXPECT_NE(text.find("-> connect the camera\n"), std::string::npos) << text;
  EXPECT_NE(text.find("[ok]   display  window:0, 1920x1080\n"), std::string::npos) << text;
  EXPECT_NE(text.find("ready: no (1 of 2 checks failed)"), std::string::npos) << text;
  EXPECT_FALSE(Ready(checks));
}

}  // namespace
}  // namespace sandtable::node
