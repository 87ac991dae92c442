#include "net/curve.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <set>

#include "net/channel.h"
#include "net/handshake_monitor.h"
#include "tests/net/test_wait.h"

namespace sandtable::net {
namespace {

using std::chrono::milliseconds;
constexpr milliseconds kDeadline{5000};
// How long an unauthorized client is given to (wrongly) get an answer. The authorized client
// is answered first, so this only needs to cover the refused handshake.
constexpr milliseconds kRefusalWindow{500};

TEST(CurveKeyFileTest, RoundTripsAndRejectsGarbage) {
  Expected<CurveKeyPair> keys = GenerateCurveKeyPair();
  ASSERT_TRUE(keys.ok());
  const std::string path = std::filesystem::temp_directory_path() / "sandtable_curve_test.key";
  ASSERT_TRUE(WriteCurveKeyFile(path, *keys).ok());
  Expected<CurveKeyPair> back = ReadCurveKeyFile(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->public_key_z85, keys->public_key_z85);
  EXPECT_EQ(back->secret_key_z85, keys->secret_key_z85);
  {
    std::FILE* f = std::fopen(path.c_str(), "w");
    std::fputs("public = short\n", f);
    std::fclose(f);
  }
  EXPECT_EQ(ReadCurveKeyFile(path).status().code(), StatusCode::kParseError);
  std::filesystem::remove(path);
  EXPECT_EQ(ReadCurveKeyFile(path).status().code(), StatusCode::kIoError);
}

// A CURVE server with the site key answers a client holding the site key, and refuses (no
// reply, ZAP refusal counted and logged) a client with another key pair and a client without
// CURVE.
TEST(CurveTest, OnlyClientsWithTheSiteKeyAreServed) {
  zmq::context_t context;
  const CurveKeyPair site = *GenerateCurveKeyPair();
  const CurveKeyPair intruder = *GenerateCurveKeyPair();
  ZapHandler zap(&context, {site.public_key_z85});
  ASSERT_TRUE(zap.Start().ok());

  proto::MessageCounters counters;
  SocketOptions server_options;
  server_options.curve = ServerCurve(site);
  auto router = Socket::Create(&context, SocketType::kRouter, server_options);
  ASSERT_TRUE(router.ok()) << router.status().ToString();
  HandshakeMonitor monitor;
  ASSERT_TRUE(monitor.Attach(&context, router->get(), "test router").ok());
  const std::string endpoint = *(*router)->Bind("tcp://127.0.0.1:*");
  Channel server(std::move(*router), 0, 1, &counters);
  ::testing::internal::CaptureStderr();

  auto make_client = [&](const CurveSettings& curve, uint32_t id) {
    SocketOptions options;
    options.curve = curve;
    auto dealer = Socket::Create(&context, SocketType::kDealer, options);
    EXPECT_TRUE(dealer.ok());
    EXPECT_TRUE((*dealer)->Connect(endpoint).ok());
    return std::make_unique<Channel>(std::move(*dealer), id, 1, &counters);
  };
  CurveSettings wrong = ClientCurve(intruder);
  wrong.server_key_z85 = site.public_key_z85;  // knows the server, but is not authorized
  auto keyed = make_client(ClientCurve(site), 1);
  auto wrong_key = make_client(wrong, 2);
  auto unkeyed = make_client(CurveSettings{}, 3);

  wire::Envelope ping;
  ping.mutable_heartbeat();
  for (auto* client : {keyed.get(), wrong_key.get(), unkeyed.get()}) {
    ASSERT_TRUE(client->Send(ping).ok());
  }
  std::optional<Incoming> in = testing::ReceiveWithin(&server, kDeadline);
  ASSERT_TRUE(in.has_value());
  EXPECT_EQ(in->envelope.sender_id(), 1u);
  ASSERT_TRUE(testing::WaitFor([&] { return zap.refused() >= 1; }, kDeadline));
  EXPECT_EQ(zap.accepted(), 1u);
  // Nothing else gets through.
  EXPECT_FALSE(testing::ReceiveWithin(&server, kRefusalWindow).has_value());
  // Both refusals are logged: the wrong key by ZAP and by the monitor (authentication), the
  // client without CURVE by the monitor alone (it never reaches ZAP).
  ASSERT_TRUE(testing::WaitFor([&] { return monitor.failed_handshakes() >= 2; }, kDeadline));
  monitor.Stop();
  zap.Stop();
  const std::string log = ::testing::internal::GetCapturedStderr();
  EXPECT_NE(log.find("security mechanism mismatch"), std::string::npos) << log;
  EXPECT_NE(log.find("key not authorized"), std::string::npos) << log;
  EXPECT_EQ(monitor.succeeded_handshakes(), 1u);
}

}  // namespace
}  // namespace sandtable::net
