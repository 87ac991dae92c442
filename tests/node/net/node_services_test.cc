// NodeRuntime as a host of services: long work on workers keeps membership, peer requests
// reach the service that declares them, undeclared or malformed ones are answered with
// Rejected, and a node links only to its neighbours. A real CoordinatorServer and real
// NodeRuntimes over loopback TCP, stepped on this thread (no fixed sleeps: loops end on
// events or deadlines).
#include <gtest/gtest.h>
#include <poll.h>

#include <chrono>
#include <cmath>
#include <functional>
#include <memory>
#include <thread>
#include <vector>

#include "coordinator/membership/coordinator_server.h"
#include "node/net/node_runtime.h"
#include "node/net/worker_pool.h"
#include "tests/net/test_wait.h"
#include "tests/node/net/node_site_test_util.h"

namespace sandtable::node {
namespace {

using std::chrono::milliseconds;
using SteadyClock = std::chrono::steady_clock;

constexpr milliseconds kHeartbeat{50};
constexpr milliseconds kJoinDeadline{5000};

coordinator::CoordinatorOptions CoordinatorFor() {
  return test_site::SiteCoordinatorOptions(kHeartbeat, /*misses_allowed=*/4);  // dead after 200 ms
}

NodeOptions NodeFor(NodeId id, const coordinator::CoordinatorServer& c) {
  return test_site::SiteNodeOptions(id, c, kHeartbeat, milliseconds(400));
}

using test_site::StepUntil;

TEST(WorkerPoolTest, CompletionRunsOnTheCallingThreadAfterTheJob) {
  WorkerPool pool(2);
  std::thread::id job_thread, done_thread;
  int result = 0;
  pool.Run<int>(
      [&] {
        job_thread = std::this_thread::get_id();
        return 42;
      },
      [&](int r) {
        done_thread = std::this_thread::get_id();
        result = r;
      });
  ASSERT_TRUE(net::testing::WaitFor(
      [&] {
        pool.RunCompletions();
        return result != 0;
      },
      milliseconds(5000)));
  EXPECT_EQ(result, 42);
  EXPECT_EQ(done_thread, std::this_thread::get_id());
  EXPECT_NE(job_thread, std::this_thread::get_id());
  EXPECT_EQ(pool.busy(), 0u);
}

// The pool's wake fd turns readable when a job's completion waits and is cleared by
// RunCompletions, so a network thread asleep in poll wakes for it at once.
TEST(WorkerPoolTest, WakeFdIsReadableWhileACompletionWaits) {
  WorkerPool pool(1);
  ASSERT_GE(pool.wake_fd(), 0);
  auto readable = [&](int timeout_ms) {
    pollfd p{pool.wake_fd(), POLLIN, 0};
    return poll(&p, 1, timeout_ms) == 1 && (p.revents & POLLIN);
  };
  EXPECT_FALSE(readable(0));
  bool done = false;
  pool.Run<int>([] { return 7; }, [&](int) { done = true; });
  EXPECT_TRUE(readable(5000));  // woken by the job, not by the timeout
  EXPECT_EQ(pool.RunCompletions(), 1u);
  EXPECT_TRUE(done);
  EXPECT_FALSE(readable(0));
}

// A service that starts one long job on a worker when the node registers.
class LongJobService : public NodeService {
 public:
  explicit LongJobService(milliseconds length) : length_(length) {}
  const char* name() const override { return "long-job"; }
  void OnRegistered(NodeRuntime& node) override {
    if (started_) return;
    started_ = true;
    node.workers().Run<int>(
        [length = length_] {
          // Busy, not sleeping: the job holds a core the whole time, as a solve would.
          const auto until = SteadyClock::now() + length;
          volatile double x = 0;
          while (SteadyClock::now() < until) x = x + 1e-9;
          return 1;
        },
        [this](int) { finished_ = true; });
  }
  bool started_ = false;
  bool finished_ = false;

 private:
  milliseconds length_;
};

TEST(NodeServicesTest, KeepsMembershipThroughATenSecondJobOnItsWorker) {
  coordinator::CoordinatorServer coordinator(CoordinatorFor());
  ASSERT_TRUE(coordinator.Start().ok());
  NodeRuntime node(NodeFor(7, coordinator));
  LongJobService job(milliseconds(10000));
  node.AddService(&job);
  ASSERT_TRUE(node.Start().ok());
  ASSERT_TRUE(StepUntil(
      coordinator, {&node}, [&] { return node.registered() && coordinator.members().Contains(7); },
      kJoinDeadline));
  ASSERT_TRUE(job.started_);
  const uint64_t version = coordinator.members().version();
  bool always_member = true;
  ASSERT_TRUE(StepUntil(
      coordinator, {&node},
      [&] {
        always_member = always_member && coordinator.members().Contains(7) && node.registered();
        return job.finished_;
      },
      milliseconds(20000)));
  EXPECT_TRUE(always_member) << "the node dropped out while its worker was busy";
  EXPECT_EQ(coordinator.members().version(), version) << "membership changed during the job";
  EXPECT_EQ(node.registrations(), 1u) << "the node had to register again";
}

// Answers PatternShown on the peer socket with a PeerStatusReply carrying a marker.
class EchoService : public NodeService {
 public:
  const char* name() const override { return "echo"; }
  bool ServesPeer(wire::Envelope::BodyCase body) const override {
    return body == wire::Envelope::kPatternShown;
  }
  void OnPeerMessage(net::Incoming in, NodeRuntime& node) override {
    ++received_;
    wire::Envelope reply;
    reply.mutable_peer_status_reply()->set_member_list_version(4242);
    (void)node.ReplyToPeer(in.routing_id, std::move(reply));
  }
  int received_ = 0;
};

TEST(NodeServicesTest, PeerRequestsReachTheirServiceAndOthersAreRejectedWithAReason) {
  coordinator::CoordinatorServer coordinator(CoordinatorFor());
  ASSERT_TRUE(coordinator.Start().ok());
  NodeRuntime node(NodeFor(3, coordinator));
  EchoService echo;
  node.AddService(&echo);
  ASSERT_TRUE(node.Start().ok());

  zmq::context_t context;
  auto dealer = net::Socket::Create(&context, net::SocketType::kDealer);
  ASSERT_TRUE(dealer.ok());
  ASSERT_TRUE((*dealer)->Connect(node.peer_endpoint()).ok());
  proto::MessageCounters counters;
  net::Channel client(std::move(*dealer), 99, 1, &counters);

  auto ask = [&](wire::Envelope request) -> std::optional<wire::Envelope> {
    if (!client.Send(std::move(request)).ok()) return std::nullopt;
    std::optional<wire::Envelope> reply;
    StepUntil(
        coordinator, {&node},
        [&] {
          Expected<std::optional<net::Incoming>> in = client.TryReceive();
          if (in.ok() && in->has_value()) reply = (*in)->envelope;
          return reply.has_value();
        },
        milliseconds(3000));
    return reply;
  };

  wire::Envelope served;
  served.mutable_pattern_shown();
  std::optional<wire::Envelope> r1 = ask(served);
  ASSERT_TRUE(r1.has_value());
  EXPECT_EQ(echo.received_, 1);
  EXPECT_EQ(r1->peer_status_reply().member_list_version(), 4242u);

  wire::Envelope unserved;
  unserved.mutable_blend_share();
  std::optional<wire::Envelope> r2 = ask(unserved);
  ASSERT_TRUE(r2.has_value());
  ASSERT_TRUE(r2->has_rejected());
  EXPECT_NE(r2->rejected().reason().find("does not serve"), std::string::npos)
      << r2->rejected().reason();

  // Garbage on the peer socket: answered with Rejected too (net/server_loop.h), never fatal.
  ASSERT_TRUE(client.socket().Send({"not an envelope"}).ok());
  std::optional<wire::Envelope> r3;
  StepUntil(
      coordinator, {&node},
      [&] {
        Expected<std::optional<net::Incoming>> in = client.TryReceive();
        if (in.ok() && in->has_value()) r3 = (*in)->envelope;
        return r3.has_value();
      },
      milliseconds(3000));
  ASSERT_TRUE(r3.has_value());
  EXPECT_TRUE(r3->has_rejected());
  EXPECT_EQ(echo.received_, 1);
}

TEST(NodeServicesTest, RefusesAnIdReservedForTheSiteServices) {
  NodeOptions o;
  o.id = kCoordinatorSenderId;
  o.coordinator_requests = "tcp://127.0.0.1:1";
  o.coordinator_events = "tcp://127.0.0.1:2";
  const Status checked = o.Check();
  EXPECT_FALSE(checked.ok());
  EXPECT_NE(checked.message().find("reserved"), std::string::npos) << checked.ToString();
}

TEST(NodeServicesTest, LinksOnlyToItsNeighbours) {
  coordinator::CoordinatorServer coordinator(CoordinatorFor());
  ASSERT_TRUE(coordinator.Start().ok());
  std::vector<std::unique_ptr<NodeRuntime>> nodes;
  std::vector<NodeRuntime*> all;
  for (NodeId id : {0u, 1u, 2u, 3u}) {
    nodes.push_back(std::make_unique<NodeRuntime>(NodeFor(id, coordinator)));
    all.push_back(nodes.back().get());
  }
  nodes[0]->SetNeighbours(std::set<NodeId>{1});
  for (auto& n : nodes) ASSERT_TRUE(n->Start().ok());
  // Everyone joins; node 0 links to node 1 only, the others to every member.
  ASSERT_TRUE(StepUntil(
      coordinator, all,
      [&] {
        if (coordinator.members().size() != 4) return false;
        if (nodes[0]->peers().size() != 1 || !nodes[0]->peers().count(1)) return false;
        for (int i = 1; i < 4; ++i) {
          if (nodes[i]->peers().size() != 3) return false;
        }
        // Heartbeats flow on the one link.
        return nodes[0]->peers().at(1).heartbeats_received > 0;
      },
      kJoinDeadline));
  // Widening the neighbourhood links the node to the others too.
  nodes[0]->SetNeighbours(std::nullopt);
  ASSERT_TRUE(StepUntil(
      coordinator, all, [&] { return nodes[0]->peers().size() == 3; }, kJoinDeadline));
}

// With more than kPeersAtFullHeartbeatRate peers a node heartbeats each one less often, in
// proportion, and says so: its peers judge its silence against its own period.
TEST(NodeServicesTest, HeartbeatPeriodGrowsPastEightPeersAndIsTold) {
  coordinator::CoordinatorServer coordinator(CoordinatorFor());
  ASSERT_TRUE(coordinator.Start().ok());
  constexpr int kNodes = 11;  // 10 peers each: 10 / 8 of the period
  std::vector<std::unique_ptr<NodeRuntime>> nodes;
  std::vector<NodeRuntime*> all;
  for (int i = 0; i < kNodes; ++i) {
    nodes.push_back(std::make_unique<NodeRuntime>(NodeFor(static_cast<NodeId>(i), coordinator)));
    all.push_back(nodes.back().get());
  }
  for (auto& n : nodes) ASSERT_TRUE(n->Start().ok());
  const milliseconds expected(static_cast<int64_t>(
      std::ceil(kHeartbeat.count() * (kNodes - 1) / kPeersAtFullHeartbeatRate)));
  ASSERT_TRUE(StepUntil(
      coordinator, all,
      [&] {
        for (NodeRuntime* n : all) {
          if (n->peers().size() != kNodes - 1) return false;
          for (const auto& [id, peer] : n->peers()) {
            if (peer.heartbeat_period != expected) return false;
          }
        }
        return true;
      },
      milliseconds(10000)));
  EXPECT_EQ(nodes[0]->peer_heartbeat_period(), expected);
  const PeerInfo& peer = nodes[0]->peers().at(1);
  EXPECT_EQ(NodeRuntime::PeerSilence(peer, milliseconds(100)), kPeerSilencePeriods * expected);
  EXPECT_EQ(NodeRuntime::PeerSilence(peer, milliseconds(5000)), milliseconds(5000));
}

}  // namespace
}  // namespace sandtable::node
