// NodeRuntime: a node's network side (membership, time, peer mesh).
//
// Sockets: a DEALER to the coordinator's ROUTER (Hello, Heartbeat, TimeRequest, Goodbye); a
// SUB to the coordinator's PUB (MemberList and events); a bound ROUTER for peers (peer
// heartbeats, PeerStatusRequest); one DEALER per peer learnt from the member list (heartbeats
// to that peer). The peer mesh does not depend on the coordinator: when it is down, peers keep
// heartbeating each other from the last member list; when it returns the node says Hello again
// (HeartbeatAck known = false) and membership resumes. Single-threaded: Step() in a loop.
#pragma once

#include <atomic>
#include <chrono>
#include <map>
#include <memory>
#include <optional>
#include <string>

#include "common/base/ids.h"
#include "net/channel.h"
#include "net/curve.h"
#include "net/handshake_monitor.h"
#include "node/net/clock_offset_estimator.h"

namespace sandtable::node {

using Clock = std::chrono::steady_clock;

struct NodeOptions {
  NodeId id = kInvalidNodeId;
  std::string coordinator_requests;             // coordinator ROUTER endpoint
  std::string coordinator_events;               // coordinator PUB endpoint
  std::string peer_bind = "tcp://127.0.0.1:*";  // own ROUTER for peers (advertised as bound)
  std::chrono::milliseconds heartbeat_period{100};
  std::chrono::milliseconds coordinator_timeout{500};  // silent this long: coordinator down
  std::chrono::milliseconds peer_timeout{500};         // silent this long: peer down
  std::chrono::milliseconds time_sync_period{100};
  std::optional<net::CurveKeyPair> curve;
  proto::CodecLimits limits;

  Status Check() const;
};

struct PeerInfo {
  std::string endpoint;
  uint64_t incarnation = 0;
  std::unique_ptr<net::Channel> to_peer;  // our DEALER to its ROUTER
  Clock::time_point last_heard{};         // last heartbeat it sent us
  uint64_t heartbeats_received = 0;
};

class NodeRuntime {
 public:
  explicit NodeRuntime(NodeOptions options);
  ~NodeRuntime();

  Status Start();
  const std::string& peer_endpoint() const { return peer_endpoint_; }

  Status Step(std::chrono::milliseconds max_wait);
  // Steps until `stop`; then says Goodbye to the coordinator.
  Status Run(const std::atomic<bool>& stop);
  void SayGoodbye(const std::string& reason);

  bool registered() const { return registered_; }
  bool coordinator_alive() const;
  std::optional<ClockOffsetEstimate> clock_offset() const { return clock_.Estimate(); }
  const std::map<NodeId, PeerInfo>& peers() const { return peers_; }
  const proto::MessageCounters& counters() const { return counters_; }

 private:
  void HandleCoordinatorReply(const wire::Envelope& in);
  void HandleEvent(const wire::Envelope& in);
  void HandlePeerMessage(net::Incoming in);
  void ApplyMemberList(const wire::MemberList& list);
  void SendTimers(Clock::time_point now);
  void SendToCoordinator(wire::Envelope envelope);
  wire::Envelope MakeHello() const;
  net::SocketOptions ClientSocketOptions() const;

  NodeOptions options_;
  uint64_t incarnation_ = 0;
  zmq::context_t context_;
  std::unique_ptr<net::ZapHandler> zap_;
  std::unique_ptr<net::HandshakeMonitor> peer_monitor_;
  proto::MessageCounters counters_;
  std::unique_ptr<net::Channel> coordinator_;
  std::unique_ptr<net::Channel> events_;
  std::unique_ptr<net::Channel> peer_router_;
  std::string peer_endpoint_;
  std::map<NodeId, PeerInfo> peers_;
  ClockOffsetEstimator clock_;
  bool registered_ = false;
  uint64_t member_list_version_ = 0;
  Clock::time_point last_coordinator_message_{};
  Clock::time_point next_heartbeat_{}, next_time_sync_{}, next_hello_{};
};

}  // namespace sandtable::node
