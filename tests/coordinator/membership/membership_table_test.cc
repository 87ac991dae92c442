#include "coordinator/membership/membership_table.h"

#include <gtest/gtest.h>

#include <cmath>
#include <string>

namespace sandtable::coordinator {
namespace {

using std::chrono::milliseconds;

const std::string kConn = "connection-1", kConn2 = "connection-2";

wire::Hello MakeHello(uint64_t incarnation, const std::string& endpoint) {
  wire::Hello hello;
  hello.set_incarnation(incarnation);
  hello.mutable_endpoints()->set_peer_router(endpoint);
  return hello;
}

TEST(MembershipTableTest, JoinHeartbeatExpireAndRejoinOnce) {
  MembershipOptions options;  // 100 ms x 5
  MembershipTable table(options);
  const Clock::time_point t = Clock::time_point{} + std::chrono::hours(1);
  EXPECT_EQ(table.OnHello(1, MakeHello(10, "tcp://a:1"), kConn, t, nullptr), HelloOutcome::kJoined);
  EXPECT_EQ(table.OnHello(2, MakeHello(20, "tcp://a:2"), kConn2, t, nullptr),
            HelloOutcome::kJoined);
  const uint64_t v = table.version();
  EXPECT_EQ(table.OnHello(1, MakeHello(10, "tcp://a:1"), kConn, t, nullptr),
            HelloOutcome::kRepeated);
  EXPECT_EQ(table.version(), v);

  // Node 1 keeps heartbeating, node 2 falls silent.
  for (int i = 1; i <= 6; ++i) {
    EXPECT_TRUE(table.OnHeartbeat(1, 10, kConn, t + milliseconds(100 * i)));
  }
  EXPECT_TRUE(table.ExpireSilent(t + options.Timeout()).empty());  // exactly at the limit
  const std::vector<NodeId> dead = table.ExpireSilent(t + options.Timeout() + milliseconds(1));
  ASSERT_EQ(dead.size(), 1u);
  EXPECT_EQ(dead[0], 2u);
  EXPECT_GT(table.version(), v);
  EXPECT_FALSE(
      table.OnHeartbeat(2, 20, kConn2, t + milliseconds(700)));  // unknown: must Hello again

  // Node 1 restarts (new incarnation, new port): one entry, new endpoint.
  EXPECT_FALSE(table.OnHeartbeat(1, 11, kConn, t + milliseconds(700)));
  EXPECT_EQ(table.OnHello(1, MakeHello(11, "tcp://a:9"), kConn, t + milliseconds(700), nullptr),
            HelloOutcome::kRestarted);
  const wire::MemberList list = table.ToWire();
  ASSERT_EQ(list.members_size(), 1);
  EXPECT_EQ(list.members(0).incarnation(), 11u);
  EXPECT_EQ(list.members(0).endpoints().peer_router(), "tcp://a:9");

  EXPECT_EQ(table.OnGoodbye(1, 11, kConn), GoodbyeOutcome::kLeft);
  EXPECT_EQ(table.OnGoodbye(1, 11, kConn), GoodbyeOutcome::kUnknown);
  EXPECT_EQ(table.size(), 0u);
}

// The link counts: what a member sent on its own connection, not what another connection sent
// in its name; a restart starts from zero; a non-member has none.
TEST(MembershipTableTest, CountsWhatAMemberSentOnItsOwnConnection) {
  MembershipTable table(MembershipOptions{});
  const Clock::time_point t = Clock::time_point{} + std::chrono::hours(1);
  EXPECT_FALSE(table.Link(1).has_value());
  table.CountReceived(1, kConn, 100);  // not a member yet: not counted
  ASSERT_EQ(table.OnHello(1, MakeHello(10, "tcp://a:1"), kConn, t, nullptr), HelloOutcome::kJoined);
  table.CountReceived(1, kConn, 40);
  table.CountReceived(1, kConn, 60);
  table.CountReceived(1, kConn2, 1000);  // another connection claiming node 1
  table.CountReceived(2, kConn, 1000);   // node 1's connection claiming another id
  ASSERT_TRUE(table.Link(1).has_value());
  EXPECT_EQ(table.Link(1)->messages_in, 2u);
  EXPECT_EQ(table.Link(1)->bytes_in, 100u);
  EXPECT_FALSE(table.Link(2).has_value());
  ASSERT_EQ(table.OnHello(1, MakeHello(11, "tcp://a:1"), kConn, t, nullptr),
            HelloOutcome::kRestarted);
  EXPECT_EQ(table.Link(1)->messages_in, 0u);
  EXPECT_EQ(table.OnGoodbye(1, 11, kConn), GoodbyeOutcome::kLeft);
  EXPECT_FALSE(table.Link(1).has_value());
}

// A forger on another connection cannot take a member off the list (Goodbye), keep it alive
// (Heartbeat), or take its id (Hello) while the member's connection is up, even when it copies
// the member's incarnation from the published member list.
TEST(MembershipTableTest, ForgedGoodbyeHeartbeatAndHelloFromAnotherConnectionAreRefused) {
  MembershipTable table(MembershipOptions{});
  const Clock::time_point t = Clock::time_point{} + std::chrono::hours(1);
  const std::string victim = "victim-conn", forger = "forger-conn";
  bool victim_connected = true;
  const auto still_connected = [&](const std::string& id) {
    return id == victim && victim_connected;
  };
  ASSERT_EQ(table.OnHello(3, MakeHello(30, "tcp://a:3"), victim, t, still_connected),
            HelloOutcome::kJoined);
  EXPECT_EQ(table.OnGoodbye(3, 30, forger), GoodbyeOutcome::kForged);
  EXPECT_EQ(table.OnGoodbye(3, 31, victim), GoodbyeOutcome::kForged);  // wrong incarnation
  EXPECT_FALSE(table.OnHeartbeat(3, 30, forger, t));
  EXPECT_EQ(table.OnHello(3, MakeHello(30, "tcp://evil:1"), forger, t, still_connected),
            HelloOutcome::kIdInUse);
  EXPECT_EQ(table.OnHello(3, MakeHello(99, "tcp://evil:1"), forger, t, still_connected),
            HelloOutcome::kIdInUse);
  ASSERT_TRUE(table.Contains(3));
  EXPECT_EQ(table.ToWire().members(0).endpoints().peer_router(), "tcp://a:3");

  // The victim's connection drops and it reconnects (same process): it takes its id back.
  victim_connected = false;
  EXPECT_EQ(table.OnHello(3, MakeHello(30, "tcp://a:3"), "victim-conn-2", t, still_connected),
            HelloOutcome::kReconnected);
  EXPECT_TRUE(table.OnHeartbeat(3, 30, "victim-conn-2", t));
  EXPECT_EQ(table.OnGoodbye(3, 30, "victim-conn-2"), GoodbyeOutcome::kLeft);
}

TEST(MembershipTableTest, SiteFullRefusesNewIdsButNotKnownOnes) {
  MembershipOptions options;
  options.max_members = 2;
  MembershipTable table(options);
  const Clock::time_point t = Clock::time_point{} + std::chrono::hours(1);
  EXPECT_EQ(table.OnHello(1, MakeHello(1, "tcp://a:1"), "c1", t, nullptr), HelloOutcome::kJoined);
  EXPECT_EQ(table.OnHello(2, MakeHello(2, "tcp://a:2"), "c2", t, nullptr), HelloOutcome::kJoined);
  EXPECT_EQ(table.OnHello(3, MakeHello(3, "tcp://a:3"), "c3", t, nullptr), HelloOutcome::kSiteFull);
  EXPECT_EQ(table.OnHello(2, MakeHello(22, "tcp://a:2"), "c2", t, nullptr),
            HelloOutcome::kRestarted);
  EXPECT_EQ(table.size(), 2u);
  // One connection holds one id: fake members cost a connection each.
  MembershipTable open_site(MembershipOptions{});
  EXPECT_EQ(open_site.OnHello(1, MakeHello(1, "tcp://a:1"), "c1", t, nullptr),
            HelloOutcome::kJoined);
  EXPECT_EQ(open_site.OnHello(2, MakeHello(2, "tcp://a:2"), "c1", t, nullptr),
            HelloOutcome::kConnectionInUse);
  EXPECT_FALSE(Accepted(HelloOutcome::kConnectionInUse));
}

TEST(MembershipTableTest, CheckHelloBoundsEveryStoredField) {
  EXPECT_TRUE(CheckHello(MakeHello(1, "tcp://127.0.0.1:4000")).ok());
  EXPECT_TRUE(CheckHello(MakeHello(1, "")).ok());
  const std::string huge(20 << 20, 'x');  // the 20 MB Hello of the report
  Status s = CheckHello(MakeHello(1, "tcp://" + huge));
  EXPECT_NE(s.message().find("endpoints.peer_router"), std::string::npos) << s.ToString();
  EXPECT_FALSE(CheckHello(MakeHello(1, "tcp://*:4000")).ok());
  EXPECT_FALSE(CheckHello(MakeHello(1, "http://a:1")).ok());
  wire::Hello hello = MakeHello(1, "tcp://a:1");
  hello.mutable_capabilities()->set_projector_output(std::string(kMaxCapabilityNameBytes + 1, 'p'));
  EXPECT_NE(CheckHello(hello).message().find("projector_output"), std::string::npos);
  hello = MakeHello(1, "tcp://a:1");
  hello.mutable_capabilities()->set_camera_input(huge);
  EXPECT_FALSE(CheckHello(hello).ok());
  hello = MakeHello(1, "tcp://a:1");
  hello.set_software_version(huge);
  EXPECT_FALSE(CheckHello(hello).ok());
  hello = MakeHello(1, "tcp://a:1");
  hello.mutable_capabilities()->set_frame_rate_hz(std::nan(""));
  EXPECT_FALSE(CheckHello(hello).ok());
  hello = MakeHello(1, "tcp://a:1");
  hello.mutable_capabilities()->set_camera_width_px(kMaxCapabilitySize_px + 1);
  EXPECT_FALSE(CheckHello(hello).ok());
}

TEST(MembershipOptionsTest, CheckRejectsNonsense) {
  MembershipOptions options;
  options.misses_allowed = 0;
  EXPECT_FALSE(options.Check().ok());
}

}  // namespace
}  // namespace sandtable::coordinator
