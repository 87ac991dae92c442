// BlendService between two real NodeRuntimes (a real CoordinatorServer, loopback TCP, stepped
// on this thread): a neighbour's field that never came is asked for again. On a loaded site
// the coordinator drops a unit for a moment (its heartbeats late); a share sent meanwhile is
// lost, and without asking again the node waited for that field for ever (CI: sandtable-3
// blended unit 0 with one neighbour of two).
#include <gtest/gtest.h>

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <functional>
#include <memory>
#include <set>
#include <vector>

#include <nlohmann/json.hpp>

#include <opencv2/imgcodecs.hpp>

#include "common/io/mpcdi.h"
#include "common/io/mpcdi_builder.h"
#include "common/scene/procedural_scene.h"
#include "coordinator/membership/coordinator_server.h"
#include "node/blend/blend_service.h"
#include "node/net/node_runtime.h"
#include "sim/site/site_presets.h"
#include "tests/node/net/node_site_test_util.h"

namespace sandtable::node {
namespace {

using std::chrono::milliseconds;

constexpr milliseconds kHeartbeat{50};
constexpr milliseconds kAskAgain{100};
// Casting a 1024 x 768 projector onto the table plane takes ~1 s here; generous for CI.
constexpr milliseconds kBlendDeadline{60000};

coordinator::CoordinatorOptions CoordinatorFor() {
  // No unit is dropped while a worker casts.
  return test_site::SiteCoordinatorOptions(kHeartbeat, /*misses_allowed=*/40);
}

NodeOptions NodeFor(NodeId id, const coordinator::CoordinatorServer& c) {
  return test_site::SiteNodeOptions(id, c, kHeartbeat, milliseconds(4000));
}

using test_site::StepUntil;

UnitCalibration TrueCalibration(const sim::Site& site, NodeId unit) {
  UnitCalibration c;
  c.unit_id = unit;
  c.camera = site.units.at(unit).camera->model;
  c.projector = site.units.at(unit).projector.model;
  c.table_from_projector = site.units.at(unit).projector.table_from_projector;
  return c;
}

struct Unit {
  std::unique_ptr<NodeRuntime> runtime;
  std::unique_ptr<BlendService> blend;
  std::vector<nlohmann::json> lines;
};

std::unique_ptr<Unit> MakeUnit(NodeId id, const coordinator::CoordinatorServer& c) {
  auto unit = std::make_unique<Unit>();
  unit->runtime = std::make_unique<NodeRuntime>(NodeFor(id, c));
  BlendServiceOptions options;
  options.ask_again = kAskAgain;
  options.peer_silence = milliseconds(4000);
  Unit* u = unit.get();
  unit->blend = std::make_unique<BlendService>(
      nullptr, nullptr, options,
      [u](const report::ReportLine& line) { u->lines.push_back(report::ToJson(line)); });
  unit->runtime->AddService(unit->blend.get());
  return unit;
}

// The last blend line names `peer` among the neighbours whose field it holds.
bool Holds(const Unit& unit, NodeId peer) {
  for (auto it = unit.lines.rbegin(); it != unit.lines.rend(); ++it) {
    if (!it->contains("neighbours")) continue;
    for (const nlohmann::json& n : (*it)["neighbours"]) {
      if (n.get<NodeId>() == peer) return true;
    }
    return false;
  }
  return false;
}

TEST(BlendServiceTest, AsksAgainForAFieldThatDidNotCome) {
  Expected<sim::Site> site = sim::MakeSitePreset("sandtable-3");
  ASSERT_TRUE(site.ok()) << site.status().ToString();
  coordinator::CoordinatorServer coordinator(CoordinatorFor());
  ASSERT_TRUE(coordinator.Start().ok());
  std::unique_ptr<Unit> a = MakeUnit(0, coordinator);
  std::unique_ptr<Unit> b = MakeUnit(1, coordinator);
  ASSERT_TRUE(a->runtime->Start().ok());
  // Unit 0 calibrates alone: it overlaps unit 1, which is not there, so its ask is lost.
  a->blend->SetCalibration(TrueCalibration(*site, 0), 1, std::set<NodeId>{1}, *a->runtime);
  ASSERT_TRUE(StepUntil(
      coordinator, {a->runtime.get()}, [&] { return !a->lines.empty(); }, kBlendDeadline));
  EXPECT_EQ(a->lines.back()["waiting_for"], nlohmann::json::array({1}));
  // Unit 1 joins and calibrates; by its round it overlaps nothing, so it shares its field with
  // no one unless asked. Only unit 0 asking again gets unit 1's field to it.
  ASSERT_TRUE(b->runtime->Start().ok());
  b->blend->SetCalibration(TrueCalibration(*site, 1), 1, std::set<NodeId>{}, *b->runtime);
  ASSERT_TRUE(StepUntil(
      coordinator, {a->runtime.get(), b->runtime.get()},
      // Unit 1 comes to hold unit 0's field too: the ask carried it.
      [&] { return Holds(*a, 1) && Holds(*b, 0); }, kBlendDeadline))
      << (a->lines.empty() ? std::string("no line") : a->lines.back().dump()) << "\n"
      << (b->lines.empty() ? std::string("no line") : b->lines.back().dump());
  EXPECT_TRUE(a->lines.back()["waiting_for"].empty()) << a->lines.back().dump();
}

// The runner takes each unit's mask as a PNG (BlendAlpha.png) into the site's MPCDI export. A
// PNG whose header states another size, garbage behind a right header, or a message with both
// raw values and a PNG is refused and counted; the good one lands in the file byte for byte.
TEST(BlendServiceTest, TakesAnAlphaMapAsPngAndRefusesBadOnes) {
  Expected<sim::Site> site = sim::MakeSitePreset("sandtable-3");
  ASSERT_TRUE(site.ok()) << site.status().ToString();
  coordinator::CoordinatorServer coordinator(CoordinatorFor());
  ASSERT_TRUE(coordinator.Start().ok());
  std::unique_ptr<Unit> runner = MakeUnit(0, coordinator);
  ASSERT_TRUE(runner->runtime->Start().ok());
  const UnitCalibration one = TrueCalibration(*site, 1);
  Expected<MpcdiSite> mpcdi = BuildMpcdiSite(
      {MpcdiUnit{"", one, std::nullopt}},
      std::make_shared<const Scene>(MakeRectangleMesh(Eigen::Vector2d(3.0, 3.0), 0)));
  ASSERT_TRUE(mpcdi.ok()) << mpcdi.status().ToString();
  const std::string path = ::testing::TempDir() + "/blend_alpha_png.mpcdi";
  std::filesystem::remove(path);
  runner->blend->SetSiteMpcdi(std::make_shared<const MpcdiSite>(*mpcdi), path);

  const int w = one.projector.width_px, h = one.projector.height_px;
  cv::Mat mask(h, w, CV_8UC1);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) mask.at<uint8_t>(y, x) = static_cast<uint8_t>((x + 3 * y) % 256);
  }
  std::vector<uchar> png;
  ASSERT_TRUE(cv::imencode(".png", mask, png));
  auto send = [&](int width_px, int height_px, std::string values, std::string png_bytes) {
    net::Incoming in;
    in.envelope.set_sender_id(1);
    wire::BlendAlpha* a = in.envelope.mutable_blend_alpha();
    a->set_projector_id(1);
    a->set_width_px(static_cast<uint32_t>(width_px));
    a->set_height_px(static_cast<uint32_t>(height_px));
    a->set_values(std::move(values));
    a->set_png(std::move(png_bytes));
    runner->blend->OnPeerMessage(std::move(in), *runner->runtime);
  };
  const std::string good(png.begin(), png.end());
  send(w + 1, h, "", good);  // the header states another size
  send(w, h, std::string(static_cast<size_t>(w) * h, '\1'), good);  // both forms
  std::string garbage = good.substr(0, 40);  // the right header, then no image
  garbage.resize(good.size(), '\x7f');
  send(w, h, "", garbage);
  ASSERT_TRUE(StepUntil(
      coordinator, {runner->runtime.get()}, [&] { return runner->blend->bad_messages() == 3; },
      kBlendDeadline))
      << runner->blend->bad_messages();
  EXPECT_FALSE(std::filesystem::exists(path));
  send(w, h, "", good);
  ASSERT_TRUE(StepUntil(
      coordinator, {runner->runtime.get()}, [&] { return std::filesystem::exists(path); },
      kBlendDeadline));
  EXPECT_EQ(runner->blend->bad_messages(), 3u);
  Expected<MpcdiSite> written = ReadMpcdi(path);
  ASSERT_TRUE(written.ok()) << written.status().ToString();
  ASSERT_EQ(written->regions.size(), 1u);
  ASSERT_TRUE(written->regions[0].alpha.has_value());
  const MpcdiBlendMap& alpha = *written->regions[0].alpha;
  ASSERT_EQ(alpha.width_px, w);
  ASSERT_EQ(alpha.height_px, h);
  EXPECT_TRUE(std::equal(alpha.values.begin(), alpha.values.end(), mask.data));
}

}  // namespace
}  // namespace sandtable::node
