#include "coordinator/membership/membership_table.h"

#include <gtest/gtest.h>

namespace sandtable::coordinator {
namespace {

using std::chrono::milliseconds;

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
  EXPECT_EQ(table.OnHello(1, MakeHello(10, "tcp://a:1"), t), HelloOutcome::kJoined);
  EXPECT_EQ(table.OnHello(2, MakeHello(20, "tcp://a:2"), t), HelloOutcome::kJoined);
  const uint64_t v = table.version();
  EXPECT_EQ(table.OnHello(1, MakeHello(10, "tcp://a:1"), t), HelloOutcome::kRepeated);
  EXPECT_EQ(table.version(), v);

  // Node 1 keeps heartbeating, node 2 falls silent.
  for (int i = 1; i <= 6; ++i) {
    EXPECT_TRUE(table.OnHeartbeat(1, 10, t + milliseconds(100 * i)));
  }
  EXPECT_TRUE(table.ExpireSilent(t + options.Timeout()).empty());  // exactly at the limit
  const std::vector<NodeId> dead = table.ExpireSilent(t + options.Timeout() + milliseconds(1));
  ASSERT_EQ(dead.size(), 1u);
  EXPECT_EQ(dead[0], 2u);
  EXPECT_GT(table.version(), v);
  EXPECT_FALSE(table.OnHeartbeat(2, 20, t + milliseconds(700)));  // unknown: must Hello again

  // Node 1 restarts (new incarnation, new port): one entry, new endpoint.
  EXPECT_FALSE(table.OnHeartbeat(1, 11, t + milliseconds(700)));
  EXPECT_EQ(table.OnHello(1, MakeHello(11, "tcp://a:9"), t + milliseconds(700)),
            HelloOutcome::kRestarted);
  const wire::MemberList list = table.ToWire();
  ASSERT_EQ(list.members_size(), 1);
  EXPECT_EQ(list.members(0).incarnation(), 11u);
  EXPECT_EQ(list.members(0).endpoints().peer_router(), "tcp://a:9");

  EXPECT_TRUE(table.OnGoodbye(1));
  EXPECT_FALSE(table.OnGoodbye(1));
  EXPECT_EQ(table.size(), 0u);
}

TEST(MembershipOptionsTest, CheckRejectsNonsense) {
  MembershipOptions options;
  options.misses_allowed = 0;
  EXPECT_FALSE(options.Check().ok());
}

}  // namespace
}  // namespace sandtable::coordinator
