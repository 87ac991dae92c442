// A node links to at most max_peer_links peers, the nearest ids first, plus the lowest id (the
// calibration runner, which itself links up to kMaxRunnerPeerLinks): a member list flooded
// with 1 100 fake members (the report: each node pushed to ZeroMQ's 1 023-socket limit, real
// peers never connected) costs a node max_peer_links sockets and the runner
// kMaxRunnerPeerLinks, and the real neighbours are linked and heard both ways. The member list
// comes from a publisher of the test (a stand-in for the coordinator's event publisher, real
// sockets), the nodes are real NodeRuntimes stepped on this thread.
#include <gtest/gtest.h>

#include <chrono>
#include <memory>

#include "common/base/ids.h"
#include "net/event_publisher.h"
#include "node/net/node_runtime.h"
#include "tests/net/test_wait.h"

namespace sandtable::node {
namespace {

using std::chrono::milliseconds;
using SteadyClock = std::chrono::steady_clock;

constexpr int kFakeMembers = 1100;
constexpr NodeId kFirstFakeId = 1000;
constexpr milliseconds kDeadline{10000};
constexpr milliseconds kRepublish{50};

TEST(NodePeerBoundTest, FakeMembersCannotCrowdOutARealNeighbour) {
  zmq::context_t context;
  proto::MessageCounters counters;
  Expected<std::unique_ptr<net::EventPublisher>> publisher =
      net::EventPublisher::Bind(&context, net::SocketOptions{}, net::EventPublisherLimits{},
                                "tcp://127.0.0.1:*", kCoordinatorSenderId, 1, &counters, {});
  ASSERT_TRUE(publisher.ok()) << publisher.status().ToString();
  const std::string events = (*publisher)->endpoint();
  auto router = net::Socket::Create(&context, net::SocketType::kRouter);
  ASSERT_TRUE(router.ok());
  Expected<std::string> requests = (*router)->Bind("tcp://127.0.0.1:*");
  ASSERT_TRUE(requests.ok());

  auto options = [&](NodeId id) {
    NodeOptions o;
    o.id = id;
    o.coordinator_requests = *requests;
    o.coordinator_events = events;
    o.heartbeat_period = milliseconds(50);
    o.coordinator_timeout = milliseconds(5000);
    o.peer_timeout = milliseconds(5000);
    return o;
  };
  NodeRuntime a(options(1)), b(options(2));
  ASSERT_TRUE(a.Start().ok());
  ASSERT_TRUE(b.Start().ok());

  wire::Envelope list;
  wire::MemberList* members = list.mutable_member_list();
  members->set_version(1);
  auto add = [&](NodeId id, const std::string& endpoint) {
    wire::Member* m = members->add_members();
    m->set_node_id(id);
    m->set_incarnation(1);
    m->mutable_endpoints()->set_peer_router(endpoint);
  };
  add(1, a.peer_endpoint());
  add(2, b.peer_endpoint());
  // Fake members: nothing listens on port 9 (connects are asynchronous, they just retry).
  for (int i = 0; i < kFakeMembers; ++i) add(kFirstFakeId + i, "tcp://127.0.0.1:9");
  add(5000, "tcp://*:1");          // not linkable: wildcard
  add(5001, "udp://127.0.0.1:1");  // not linkable: transport

  const NodeOptions defaults;
  auto next_publish = SteadyClock::now();
  const bool heard = net::testing::WaitFor(
      [&] {
        if (SteadyClock::now() >= next_publish) {
          (void)(*publisher)->Drain();
          (void)(*publisher)->Publish(list);  // republished: subscribers may join late
          next_publish = SteadyClock::now() + kRepublish;
        }
        EXPECT_TRUE(a.Step(milliseconds(1)).ok());
        EXPECT_TRUE(b.Step(milliseconds(1)).ok());
        EXPECT_LE(a.peers().size(), static_cast<size_t>(kMaxRunnerPeerLinks));
        EXPECT_LE(b.peers().size(), static_cast<size_t>(defaults.max_peer_links) + 1);
        const auto ab = a.peers().find(2), ba = b.peers().find(1);
        return ab != a.peers().end() && ab->second.heartbeats_received > 0 &&
               ba != b.peers().end() && ba->second.heartbeats_received > 0;
      },
      kDeadline);
  EXPECT_TRUE(heard) << "nodes 1 and 2 never heard each other";
  // Node 1 has the lowest id: it runs the rounds and links up to kMaxRunnerPeerLinks.
  EXPECT_EQ(a.peers().size(), static_cast<size_t>(kMaxRunnerPeerLinks));
  // Node 2: its max_peer_links nearest ids, node 1 among them.
  EXPECT_EQ(b.peers().size(), static_cast<size_t>(defaults.max_peer_links));
  EXPECT_EQ(a.peers().count(5000) + a.peers().count(5001), 0u);
  // The nearest ids: 2 and the lowest fake ids.
  EXPECT_EQ(a.peers().count(kFirstFakeId), 1u);
  EXPECT_EQ(a.peers().count(kFirstFakeId + kFakeMembers - 1), 0u);
  EXPECT_EQ(b.peers().count(kFirstFakeId), 1u);
  EXPECT_EQ(b.peers().count(kFirstFakeId + defaults.max_peer_links), 0u);
}

}  // namespace
}  // namespace sandtable::node
