#include "net/curve.h"

#include <gtest/gtest.h>

#include <sys/stat.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <filesystem>
#include <set>
#include <string>

#include "common/base/file_io.h"

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
  EXPECT_EQ(ReadCurveKeyFile(path).status().code(), StatusCode::kNotFound);
}

std::string TempKeyPath(const std::string& name) {
  return (std::filesystem::temp_directory_path() /
          ("sandtable_curve_test_" + std::to_string(::getpid()) + "_" + name + ".key"))
      .string();
}

unsigned ModeOf(const std::string& path) {
  struct stat st {};
  EXPECT_EQ(::stat(path.c_str(), &st), 0) << path;
  return static_cast<unsigned>(st.st_mode & 07777);
}

std::string KeyText(const std::string& public_z85, const std::string& secret_z85) {
  return "public = " + public_z85 + "\nsecret = " + secret_z85 + "\n";
}

TEST(CurveKeyFileTest, WrittenOwnerOnly) {
  const std::string path = TempKeyPath("mode");
  ASSERT_TRUE(WriteCurveKeyFile(path, *GenerateCurveKeyPair()).ok());
  EXPECT_EQ(ModeOf(path), kCurveKeyFileMode);
  // Overwriting an existing, too open file also leaves it 0600.
  ASSERT_EQ(::chmod(path.c_str(), 0644), 0);
  ASSERT_TRUE(WriteCurveKeyFile(path, *GenerateCurveKeyPair()).ok());
  EXPECT_EQ(ModeOf(path), kCurveKeyFileMode);
  EXPECT_TRUE(ReadCurveKeyFile(path).ok());
  std::filesystem::remove(path);
}

TEST(CurveKeyFileTest, RefusesAFileOthersCanRead) {
  const std::string path = TempKeyPath("open");
  ASSERT_TRUE(WriteCurveKeyFile(path, *GenerateCurveKeyPair()).ok());
  for (unsigned mode : {0644u, 0640u, 0604u, 0620u, 0602u, 0660u}) {
    ASSERT_EQ(::chmod(path.c_str(), mode), 0);
    Expected<CurveKeyPair> keys = ReadCurveKeyFile(path);
    ASSERT_FALSE(keys.ok()) << std::oct << mode;
    EXPECT_EQ(keys.status().code(), StatusCode::kPermissionDenied);
    EXPECT_NE(keys.status().message().find(path), std::string::npos) << keys.status().ToString();
    EXPECT_NE(keys.status().message().find("chmod 600"), std::string::npos)
        << keys.status().ToString();
  }
  for (unsigned mode : {0600u, 0400u}) {
    ASSERT_EQ(::chmod(path.c_str(), mode), 0);
    EXPECT_TRUE(ReadCurveKeyFile(path).ok()) << std::oct << mode;
  }
  ::chmod(path.c_str(), 0600);
  std::filesystem::remove(path);
}

TEST(CurveKeyFileTest, RefusesHalvesOfTwoPairs) {
  const CurveKeyPair a = *GenerateCurveKeyPair();
  const CurveKeyPair b = *GenerateCurveKeyPair();
  const std::string path = TempKeyPath("mismatch");
  ASSERT_TRUE(WriteFileAtomically(path, KeyText(a.public_key_z85, b.secret_key_z85), 0600).ok());
  Expected<CurveKeyPair> keys = ReadCurveKeyFile(path);
  ASSERT_FALSE(keys.ok());
  EXPECT_EQ(keys.status().code(), StatusCode::kParseError);
  EXPECT_NE(keys.status().message().find(path), std::string::npos) << keys.status().ToString();
  EXPECT_NE(keys.status().message().find("not the one of the secret key"), std::string::npos)
      << keys.status().ToString();
  // The matching halves, in either order and with comments, load.
  ASSERT_TRUE(WriteFileAtomically(
                  path,
                  "# site\nsecret = " + b.secret_key_z85 + "\npublic = " + b.public_key_z85 + "\n",
                  0600)
                  .ok());
  Expected<CurveKeyPair> back = ReadCurveKeyFile(path);
  ASSERT_TRUE(back.ok()) << back.status().ToString();
  EXPECT_EQ(back->public_key_z85, b.public_key_z85);
  std::filesystem::remove(path);
}

TEST(CurveKeyFileTest, RefusesWhatIsNotAKeyFile) {
  const std::string path = TempKeyPath("junk");
  const CurveKeyPair a = *GenerateCurveKeyPair();
  struct Case {
    std::string text;
    StatusCode code;
  };
  const std::string not_z85(40, '"');  // '"' is not in the Z85 alphabet
  for (const Case& c : {Case{"public = short\n", StatusCode::kParseError},
                        Case{"public = " + a.public_key_z85 + "\n", StatusCode::kParseError},
                        Case{KeyText(not_z85, a.secret_key_z85), StatusCode::kParseError},
                        Case{KeyText(a.public_key_z85, not_z85), StatusCode::kParseError},
                        Case{"colour = " + a.public_key_z85 + "\n", StatusCode::kParseError},
                        Case{std::string(kMaxCurveKeyFileBytes + 1, '#'), StatusCode::kIoError}}) {
    ASSERT_TRUE(WriteFileAtomically(path, c.text, 0600).ok());
    Expected<CurveKeyPair> keys = ReadCurveKeyFile(path);
    ASSERT_FALSE(keys.ok()) << c.text.substr(0, 60);
    EXPECT_EQ(keys.status().code(), c.code) << keys.status().ToString();
    EXPECT_NE(keys.status().message().find(path), std::string::npos) << keys.status().ToString();
  }
  std::filesystem::remove(path);
  // Not regular files: refused before reading, never a hang or a read of /dev/zero.
  EXPECT_EQ(ReadCurveKeyFile("/dev/zero").status().code(), StatusCode::kIoError);
  EXPECT_EQ(ReadCurveKeyFile(std::filesystem::temp_directory_path().string()).status().code(),
            StatusCode::kIoError);
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
