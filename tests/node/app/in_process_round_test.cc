// A whole self-calibration round in one process: a real CoordinatorServer, a real WorldServer
// (the simulated site's projectors and cameras) and three NodeApps, each on its own thread over
// real loopback sockets; no child processes. The same with one unit's links dropping a share of
// what it sends. An operator's ask to calibrate one unit again, then the site (the coordinator's
// recalibrate_request). sandtable-3 at half resolution, so that it fits every CI run.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <thread>
#include <variant>
#include <vector>

#include <gtest/gtest.h>

#include "common/scene/gltf_loader.h"
#include "coordinator/calibration/recalibration_service.h"
#include "coordinator/membership/coordinator_server.h"
#include "net/channel.h"
#include "node/app/node_app.h"
#include "proto/message_counters.h"
#include "sim/app/world_server.h"
#include "sim/lab/lab_inputs.h"
#include "sim/lab/registration_metric.h"
#include "sim/transport/world.h"
#include "tests/net/test_wait.h"
#include "tests/node/net/node_site_test_util.h"

namespace sandtable::node {
namespace {

namespace fs = std::filesystem;
using std::chrono::milliseconds;

constexpr milliseconds kHeartbeat{100};
// sandtable-3 at half resolution (a round in ~10 s on two cores).
constexpr double kScale = 0.5;
// A round of sandtable-3 at half resolution takes ~10 s on two cores; lossy links add resends.
constexpr auto kRoundDeadline = std::chrono::seconds(240);
// The solve's fit of a unit's projector (decoded correspondences, px): the round worked.
constexpr double kMaxProjectorRms_px = 0.5;
// A unit calibrated again registers to the model as a first round does (sandtable-3 at half
// resolution: about 0.5 mm rms against the world's truth); a join that rests on one neighbour
// camera alone is tens of millimetres off.
constexpr double kMaxRecalibratedRms_mm = 1.5;

class InProcessSite {
 public:
  explicit InProcessSite(const fs::path& dir) : dir_(dir) {}
  ~InProcessSite() { Stop(); }

  // Prepares sandtable-3 (every unit's device timing `timing`, sim/site/device_timing.h; "":
  // the preset's ideal devices), starts the coordinator and the world.
  void Start(const std::string& timing = "") {
    fs::remove_all(dir_);
    fs::create_directories(dir_);
    Expected<sim::LabInputs> inputs =
        sim::PrepareLabInputs("sandtable-3", "sandtable", /*seed=*/1, dir_.string(), "",
                              /*resolution_scale=*/kScale, timing);
    ASSERT_TRUE(inputs.ok()) << inputs.status().ToString();
    inputs_ = std::move(*inputs);
    Expected<Scene> scene = LoadGltfScene(inputs_.scene_path);
    ASSERT_TRUE(scene.ok()) << scene.status().ToString();
    Expected<std::unique_ptr<sim::World>> world = sim::World::Create(inputs_.site, *scene);
    ASSERT_TRUE(world.ok()) << world.status().ToString();
    world_ = std::make_unique<sim::WorldServer>(std::move(*world), sim::WorldServerOptions{});
    ASSERT_TRUE(world_->Start().ok());
    coordinator_ = std::make_unique<coordinator::CoordinatorServer>(
        test_site::SiteCoordinatorOptions(kHeartbeat, /*misses_allowed=*/50));
    coordinator_->AddService(&recalibration_);
    ASSERT_TRUE(coordinator_->Start().ok());
    threads_.emplace_back([this] { (void)world_->Run(stop_); });
    threads_.emplace_back([this] { (void)coordinator_->Run(stop_); });
  }

  // Starts every unit's NodeApp; `faults` on unit `faulty` (none: kInvalidNodeId).
  void StartNodes(NodeId faulty = kInvalidNodeId, net::ChannelFaults faults = {}) {
    for (const sim::UnitSpec& unit : inputs_.site.units) {
      NodeConfig c;
      c.id = unit.id;
      c.coordinator_requests = coordinator_->request_endpoint();
      c.coordinator_events = coordinator_->event_endpoint();
      c.heartbeat_ms = static_cast<int>(kHeartbeat.count());
      c.world = world_->endpoint();
      c.factory_path = inputs_.factory_paths.at(unit.id);
      c.model_path = inputs_.model_path;
      c.export_dir = (dir_ / "calibration").string();
      c.render = RenderMode::kOff;
      c.blend = false;
      c.expected_units = static_cast<int>(inputs_.site.units.size());
      if (unit.id == faulty) c.faults = faults;
      Expected<std::unique_ptr<NodeApp>> app =
          NodeApp::Create(c, [this](const report::ReportLine& line) {
            std::lock_guard<std::mutex> lock(mutex_);
            if (const auto* l = std::get_if<report::Calibrated>(&line)) calibrated_[l->id] = *l;
            if (const auto* l = std::get_if<report::CalibrationFailed>(&line)) {
              failed_[l->id] = l->reason;
            }
            if (const auto* l = std::get_if<report::Messages>(&line)) messages_[l->id] = *l;
          });
      ASSERT_TRUE(app.ok()) << app.status().ToString();
      NodeApp* raw = app->get();
      apps_.push_back(std::move(*app));
      threads_.emplace_back([this, raw] {
        const int code = raw->Run(stop_);
        std::lock_guard<std::mutex> lock(mutex_);
        exits_.push_back(code);
      });
    }
  }

  // Waits until every unit reported a calibration or a failure.
  bool WaitForRound() {
    const auto until = std::chrono::steady_clock::now() + kRoundDeadline;
    while (std::chrono::steady_clock::now() < until) {
      {
        std::lock_guard<std::mutex> lock(mutex_);
        if (calibrated_.size() + failed_.size() >= inputs_.site.units.size()) return true;
      }
      std::this_thread::sleep_for(milliseconds(50));
    }
    return false;
  }

  // Waits until the units' latest calibrations satisfy `done`.
  bool WaitForCalibrated(
      const std::function<bool(const std::map<NodeId, report::Calibrated>&)>& done) {
    return net::testing::WaitFor([&] { return done(calibrated()); },
                                 std::chrono::duration_cast<milliseconds>(kRoundDeadline));
  }

  // An operator's recalibrate_request (the whole site, or `unit`): the coordinator's reply.
  std::optional<wire::RecalibrateReply> AskRecalibration(bool all_units, NodeId unit) {
    auto dealer = net::Socket::Create(&context_, net::SocketType::kDealer);
    if (!dealer.ok() || !(*dealer)->Connect(coordinator_->request_endpoint()).ok()) return {};
    net::Channel channel(std::move(*dealer), kConsoleSenderId, 1, &operator_counters_);
    wire::Envelope request;
    request.mutable_recalibrate_request()->set_all_units(all_units);
    request.mutable_recalibrate_request()->set_node_id(unit);
    if (!channel.Send(std::move(request)).ok()) return {};
    std::optional<net::Incoming> in = net::testing::ReceiveWithin(&channel, milliseconds(5000));
    if (!in || !in->envelope.has_recalibrate_reply()) return {};
    return in->envelope.recalibrate_reply();
  }

  void Stop() {
    stop_ = true;
    for (std::thread& t : threads_) {
      if (t.joinable()) t.join();
    }
    threads_.clear();
    apps_.clear();
  }

  std::map<NodeId, report::Calibrated> calibrated() {
    std::lock_guard<std::mutex> lock(mutex_);
    return calibrated_;
  }
  // Each NodeApp's exit status (after Stop).
  std::vector<int> exits() {
    std::lock_guard<std::mutex> lock(mutex_);
    return exits_;
  }
  // Each node's exit line (after Stop).
  std::map<NodeId, report::Messages> messages() {
    std::lock_guard<std::mutex> lock(mutex_);
    return messages_;
  }
  std::map<NodeId, std::string> failed() {
    std::lock_guard<std::mutex> lock(mutex_);
    return failed_;
  }
  const sim::LabInputs& inputs() const { return inputs_; }
  sim::World& world() { return world_->world(); }

 private:
  fs::path dir_;
  sim::LabInputs inputs_;
  std::atomic<bool> stop_{false};
  std::unique_ptr<sim::WorldServer> world_;
  std::unique_ptr<coordinator::CoordinatorServer> coordinator_;
  coordinator::RecalibrationService recalibration_{milliseconds(200)};
  zmq::context_t context_;
  proto::MessageCounters operator_counters_;
  std::vector<std::unique_ptr<NodeApp>> apps_;
  std::vector<std::thread> threads_;
  std::mutex mutex_;
  std::map<NodeId, report::Calibrated> calibrated_;
  std::map<NodeId, std::string> failed_;
  std::map<NodeId, report::Messages> messages_;
  std::vector<int> exits_;
};

// Every unit calibrated by one round, its file written, its projector fitted.
void ExpectOneRoundCalibratedAll(InProcessSite& site) {
  ASSERT_TRUE(site.WaitForRound()) << "no result from every unit within the deadline";
  EXPECT_TRUE(site.failed().empty()) << site.failed().begin()->second;
  const std::map<NodeId, report::Calibrated> calibrated = site.calibrated();
  ASSERT_EQ(calibrated.size(), site.inputs().site.units.size());
  const uint64_t round = calibrated.begin()->second.round;
  EXPECT_NE(round, 0u);
  for (const auto& [id, line] : calibrated) {
    SCOPED_TRACE("unit " + std::to_string(id));
    EXPECT_EQ(line.round, round);  // one round calibrated them all
    EXPECT_TRUE(fs::exists(line.json));
    Expected<UnitCalibration> unit = LoadUnitCalibration(line.json);
    ASSERT_TRUE(unit.ok()) << unit.status().ToString();
    EXPECT_TRUE(unit->table_from_projector.has_value());
    EXPECT_LT(unit->projector_rms_px, kMaxProjectorRms_px);
  }
}

TEST(InProcessRoundTest, ThreeNodesCalibrateInOneProcess) {
  InProcessSite site(fs::temp_directory_path() / ("in_process_round_" + std::to_string(getpid())));
  ASSERT_NO_FATAL_FAILURE(site.Start());
  ASSERT_NO_FATAL_FAILURE(site.StartNodes());
  ExpectOneRoundCalibratedAll(site);
  site.Stop();
  EXPECT_EQ(site.exits(), std::vector<int>(site.inputs().site.units.size(), 0));
}

TEST(InProcessRoundTest, ARoundOverLossyLinksStillCalibratesEveryUnit) {
  InProcessSite site(fs::temp_directory_path() /
                     ("in_process_lossy_round_" + std::to_string(getpid())));
  ASSERT_NO_FATAL_FAILURE(site.Start());
  net::ChannelFaults faults;
  faults.drop_share = 0.1;  // a tenth of what unit 1 sends never arrives
  faults.seed = 7;
  ASSERT_NO_FATAL_FAILURE(site.StartNodes(/*faulty=*/1, faults));
  ExpectOneRoundCalibratedAll(site);
  site.Stop();
  const std::map<NodeId, report::Messages> messages = site.messages();
  ASSERT_TRUE(messages.count(1));
  EXPECT_GT(messages.at(1).faults_dropped, 0u);  // the links did lose messages
  EXPECT_EQ(messages.at(0).faults_dropped, 0u);
}

}  // namespace
}  // namespace sandtable::node

namespace sandtable::node {
namespace {

// The units' calibrations as their files say now.
std::map<NodeId, UnitCalibration> Calibrations(const std::map<NodeId, report::Calibrated>& lines) {
  std::map<NodeId, UnitCalibration> out;
  for (const auto& [id, line] : lines) {
    Expected<UnitCalibration> unit = LoadUnitCalibration(line.json);
    EXPECT_TRUE(unit.ok()) << unit.status().ToString();
    if (unit.ok() && unit->table_from_projector && unit->table_from_model) out[id] = *unit;
  }
  return out;
}

// Unit `id`'s registration error (rms mm over the model's surfaces) against the world's truth.
double RegistrationRmsMm(sim::World& world, const sim::LabInputs& inputs,
                         const UnitCalibration& unit, NodeId id) {
  sim::EstimatedRegistration e;
  e.unit_id = id;
  e.projector = unit.projector;
  e.table_from_projector = *unit.table_from_projector;
  e.table_from_model = *unit.table_from_model;
  sim::RegistrationMetricOptions options;
  options.num_samples = 10000;
  options.true_table_from_model = inputs.model_from_table.Inverse();
  Expected<sim::RegistrationReport> r = sim::MeasureRegistration(world, {e}, options);
  EXPECT_TRUE(r.ok()) << r.status().ToString();
  return r.ok() ? r->per_unit.at(id).all.rms_mm : 1e9;
}

TEST(InProcessRoundTest, AnOperatorsAskCalibratesOneUnitAgainThenTheSite) {
  InProcessSite site(fs::temp_directory_path() /
                     ("in_process_recalibration_" + std::to_string(getpid())));
  ASSERT_NO_FATAL_FAILURE(site.Start());
  ASSERT_NO_FATAL_FAILURE(site.StartNodes());
  ExpectOneRoundCalibratedAll(site);
  const std::map<NodeId, report::Calibrated> first = site.calibrated();
  ASSERT_EQ(first.size(), 3u);
  const std::map<NodeId, UnitCalibration> first_units = Calibrations(first);
  ASSERT_EQ(first_units.size(), 3u);

  // Unit 1 again: a join round against units 0 and 2, which keep their round.
  std::optional<wire::RecalibrateReply> reply = site.AskRecalibration(false, 1);
  ASSERT_TRUE(reply.has_value());
  ASSERT_TRUE(reply->accepted()) << reply->reason();
  ASSERT_TRUE(site.WaitForCalibrated([&](const std::map<NodeId, report::Calibrated>& c) {
    return c.at(1).round != first.at(1).round;
  })) << "unit 1 was not calibrated again";
  const std::map<NodeId, report::Calibrated> second = site.calibrated();
  EXPECT_EQ(second.at(0).round, first.at(0).round);
  EXPECT_EQ(second.at(2).round, first.at(2).round);
  EXPECT_TRUE(site.failed().empty()) << site.failed().begin()->second;
  const std::map<NodeId, UnitCalibration> second_units = Calibrations(second);
  ASSERT_EQ(second_units.count(1), 1u);
  EXPECT_LT(second_units.at(1).projector_rms_px, kMaxProjectorRms_px);

  // The whole site again: one new round places every unit.
  reply = site.AskRecalibration(true, 0);
  ASSERT_TRUE(reply.has_value());
  ASSERT_TRUE(reply->accepted()) << reply->reason();
  ASSERT_TRUE(site.WaitForCalibrated([&](const std::map<NodeId, report::Calibrated>& c) {
    const uint64_t round = c.at(0).round;
    return round != second.at(0).round && c.at(1).round == round && c.at(2).round == round;
  })) << "the site was not calibrated again by one round";
  EXPECT_TRUE(site.failed().empty()) << site.failed().begin()->second;
  const std::map<NodeId, UnitCalibration> third_units = Calibrations(site.calibrated());
  ASSERT_EQ(third_units.size(), 3u);
  for (const auto& [id, unit] : third_units) {
    SCOPED_TRACE("unit " + std::to_string(id));
    EXPECT_LT(unit.projector_rms_px, kMaxProjectorRms_px);
  }
  site.Stop();
  EXPECT_EQ(site.exits(), std::vector<int>(site.inputs().site.units.size(), 0));

  // Against the world's truth (the world idle now): unit 1 registered by each round.
  const double by_first = RegistrationRmsMm(site.world(), site.inputs(), first_units.at(1), 1);
  const double by_join = RegistrationRmsMm(site.world(), site.inputs(), second_units.at(1), 1);
  const double by_site = RegistrationRmsMm(site.world(), site.inputs(), third_units.at(1), 1);
  std::cout << "unit 1 registration rms: first round " << by_first << " mm, its own join round "
            << by_join << " mm, the site's second round " << by_site << " mm\n";
  EXPECT_LT(by_join, kMaxRecalibratedRms_mm);
  EXPECT_LT(by_site, kMaxRecalibratedRms_mm);
}

// Real devices' timing (sim/site/device_timing.h "real": projectors two refreshes late, 30 fps
// cameras with a two-frame queue, 5 % repeated and 2 % lost frames): the cameras measure their
// latency at their own projector's flash, throw away the stale and repeated reads, and the
// round registers every unit as on ideal devices.
TEST(InProcessRoundTest, ARoundOnRealDeviceTimingReadsOnlyFreshFrames) {
  InProcessSite site(fs::temp_directory_path() / ("in_process_timing_" + std::to_string(getpid())));
  ASSERT_NO_FATAL_FAILURE(site.Start("real"));
  ASSERT_NO_FATAL_FAILURE(site.StartNodes());
  ExpectOneRoundCalibratedAll(site);
  const std::map<NodeId, report::Calibrated> lines = site.calibrated();
  uint64_t stale = 0, repeated = 0;
  for (const auto& [id, line] : lines) {
    SCOPED_TRACE("unit " + std::to_string(id));
    EXPECT_GE(line.capture_latency_ms, 0.0);  // its flash was seen and measured
    EXPECT_GT(line.captures, 0u);
    stale += line.captures_stale;
    repeated += line.captures_repeated;
  }
  EXPECT_GT(stale, 0u);     // the queues did hand old frames, and they were read again
  EXPECT_GT(repeated, 0u);  // so were the driver's repeats
  const std::map<NodeId, UnitCalibration> units = Calibrations(lines);
  ASSERT_EQ(units.size(), 3u);
  site.Stop();
  for (const auto& [id, unit] : units) {
    const double rms = RegistrationRmsMm(site.world(), site.inputs(), unit, id);
    std::cout << "real device timing: unit " << id << " registration rms " << rms << " mm\n";
    EXPECT_LT(rms, kMaxRecalibratedRms_mm) << "unit " << id;
  }
}

}  // namespace
}  // namespace sandtable::node
