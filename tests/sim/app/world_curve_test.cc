// The world's CURVE option: a world served with the site key answers only clients holding it.
// A client without CURVE and a client with another key pair get nothing (no reply, the refusal
// counted); a client with the site key, and a node's WorldLink given the site key, are served.
// In-process server (WorldServer on its own thread) and real sockets; waits with deadlines.
#include <atomic>
#include <chrono>
#include <thread>

#include <gtest/gtest.h>

#include "common/scene/procedural_scene.h"
#include "net/channel.h"
#include "net/curve.h"
#include "node/devices/world_link.h"
#include "sim/app/world_server.h"
#include "sim/site/site_presets.h"
#include "sim/transport/world.h"
#include "tests/net/test_wait.h"

namespace sandtable::sim {
namespace {

using std::chrono::milliseconds;

constexpr milliseconds kReplyDeadline{30000};
// How long a refused client is given to (wrongly) get an answer; the keyed client is
// answered first, so this only needs to cover a refused handshake.
constexpr milliseconds kRefusalWindow{1500};
constexpr milliseconds kLinkConnectTimeout{1500};

wire::Envelope WhiteFrame(uint32_t projector) {
  wire::Envelope e;
  auto* r = e.mutable_set_frame_request();
  r->set_projector_id(projector);
  r->set_width_px(1280);
  r->set_height_px(800);
  r->set_encoding(wire::PIXEL_ENCODING_GRAY8);
  r->set_pixels(std::string(1280 * 800, static_cast<char>(255)));
  return e;
}

class Client {
 public:
  Client(zmq::context_t* context, const std::string& endpoint, uint32_t id,
         const net::CurveSettings& curve) {
    net::SocketOptions options;
    options.curve = curve;
    auto socket = net::Socket::Create(context, net::SocketType::kDealer, options);
    EXPECT_TRUE(socket.ok()) << socket.status().ToString();
    EXPECT_TRUE((*socket)->Connect(endpoint).ok());
    channel_ = std::make_unique<net::Channel>(std::move(*socket), id, 1, &counters_);
  }
  bool Send(wire::Envelope e) { return channel_->Send(std::move(e)).ok(); }
  std::optional<wire::Envelope> Receive(milliseconds within) {
    std::optional<net::Incoming> in = net::testing::ReceiveWithin(channel_.get(), within);
    if (!in) return std::nullopt;
    return in->envelope;
  }

 private:
  proto::MessageCounters counters_;
  std::unique_ptr<net::Channel> channel_;
};

class WorldCurveTest : public ::testing::Test {
 protected:
  void SetUp() override {
    site_keys_ = *net::GenerateCurveKeyPair();
    ProceduralSceneOptions scene_options;
    scene_options.preset = ScenePreset::kFlat;
    Expected<std::unique_ptr<World>> world =
        World::Create(*MakeSitePreset("flat-4"), MakeProceduralScene(scene_options)->scene);
    ASSERT_TRUE(world.ok()) << world.status().ToString();
    WorldServerOptions options;
    options.curve = site_keys_;
    options.noise = false;
    server_ = std::make_unique<WorldServer>(std::move(*world), options);
    ASSERT_TRUE(server_->Start().ok());
    thread_ = std::thread([this] { ran_ = server_->Run(stop_); });
  }
  void TearDown() override {
    stop_ = true;
    if (thread_.joinable()) thread_.join();
    EXPECT_TRUE(ran_.ok()) << ran_.ToString();
    server_.reset();
  }

  net::CurveKeyPair site_keys_;
  std::unique_ptr<WorldServer> server_;
  std::atomic<bool> stop_{false};
  Status ran_;
  std::thread thread_;
};

TEST_F(WorldCurveTest, OnlyClientsWithTheSiteKeyAreServed) {
  zmq::context_t context;
  const std::string endpoint = server_->endpoint();
  const net::CurveKeyPair intruder = *net::GenerateCurveKeyPair();
  net::CurveSettings wrong = net::ClientCurve(intruder);
  wrong.server_key_z85 = site_keys_.public_key_z85;  // knows the server, is not authorized
  Client unkeyed(&context, endpoint, 1, net::CurveSettings{});
  Client wrong_key(&context, endpoint, 2, wrong);
  Client keyed(&context, endpoint, 3, net::ClientCurve(site_keys_));
  ::testing::internal::CaptureStderr();
  // A refused client's send may already fail (its connection was dropped): either way it
  // must never get an answer.
  (void)unkeyed.Send(WhiteFrame(0));
  (void)wrong_key.Send(WhiteFrame(1));
  const bool keyed_sent = keyed.Send(WhiteFrame(2));

  std::optional<wire::Envelope> reply = keyed.Receive(kReplyDeadline);
  const bool unkeyed_answered = unkeyed.Receive(kRefusalWindow).has_value();
  const bool wrong_key_answered = wrong_key.Receive(kRefusalWindow).has_value();
  const bool zap_refused =
      net::testing::WaitFor([&] { return server_->curve_refused() >= 1; }, kReplyDeadline);
  const bool handshakes_failed =
      net::testing::WaitFor([&] { return server_->failed_handshakes() >= 2; }, kReplyDeadline);
  const std::string log = ::testing::internal::GetCapturedStderr();
  ASSERT_TRUE(keyed_sent);
  ASSERT_TRUE(reply && reply->has_set_frame_reply());
  EXPECT_TRUE(reply->set_frame_reply().ok()) << reply->set_frame_reply().message();
  EXPECT_FALSE(unkeyed_answered);
  EXPECT_FALSE(wrong_key_answered);
  EXPECT_TRUE(zap_refused);
  EXPECT_TRUE(handshakes_failed) << server_->failed_handshakes();
  EXPECT_NE(log.find("key not authorized"), std::string::npos) << log;
  // Only the keyed client's frame reached the world.
  EXPECT_EQ(server_->stats().frames_set, 1u);
  EXPECT_EQ(server_->curve_accepted(), 1u);
}

TEST_F(WorldCurveTest, NodeWorldLinkUsesTheSiteKey) {
  node::WorldLinkOptions options;
  options.endpoint = server_->endpoint();
  options.node_id = 0;
  options.connect_timeout = kLinkConnectTimeout;
  options.curve = site_keys_;
  Expected<std::shared_ptr<node::WorldLink>> link = node::WorldLink::Connect(options);
  ASSERT_TRUE(link.ok()) << link.status().ToString();
  Expected<wire::Envelope> reply = (*link)->Ask(WhiteFrame(0), wire::Envelope::kSetFrameReply);
  ASSERT_TRUE(reply.ok()) << reply.status().ToString();
  EXPECT_TRUE(reply->set_frame_reply().ok());

  // Without the key: never connected, a clear UNAVAILABLE naming CURVE, nothing served.
  ::testing::internal::CaptureStderr();
  node::WorldLinkOptions plain = options;
  plain.node_id = 1;
  plain.curve.reset();
  Expected<std::shared_ptr<node::WorldLink>> unkeyed = node::WorldLink::Connect(plain);
  ASSERT_TRUE(unkeyed.ok());
  Expected<wire::Envelope> refused = (*unkeyed)->Ask(WhiteFrame(1), wire::Envelope::kSetFrameReply);
  ::testing::internal::GetCapturedStderr();
  ASSERT_FALSE(refused.ok());
  EXPECT_EQ(refused.status().code(), StatusCode::kUnavailable);
  EXPECT_NE(refused.status().message().find("CURVE"), std::string::npos)
      << refused.status().ToString();
  EXPECT_EQ(server_->stats().frames_set, 1u);
}

}  // namespace
}  // namespace sandtable::sim
