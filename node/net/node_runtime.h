// NodeRuntime: a node's network side and the host of its services.
//
// Sockets: a DEALER to the coordinator's ROUTER (Hello, Heartbeat, TimeRequest, Goodbye, and
// the services' requests); an event subscriber to the coordinator's events (MemberList and events);
// a bound ROUTER for peers; one DEALER per peer it links to. Membership comes from the
// coordinator's member list; the node links every member, or only the ones given to SetNeighbours
// (no service narrows the links today: the blend picks its overlapping units among the linked
// peers). Peer heartbeats: every heartbeat_period up to kPeersAtFullHeartbeatRate peers, the
// period growing in proportion beyond, so the heartbeats a node sends and receives stay flat
// as a site grows; each says its period and a peer counts as silent after kPeerSilencePeriods
// of them. An idle node sleeps in one poll over its sockets, its peers' ZMQ_FDs and its
// worker pool's wake fd. Bounded: at most max_peer_links peers are
// linked (one socket each; ZeroMQ's default limit is 1023 sockets per context): when more
// members qualify, the ones with the nearest ids (|id - own id|, ties to the lower id) are
// linked, so a member list flooded with fake members cannot crowd out the node's sockets. The
// member with the lowest id runs the calibration rounds and must reach every unit: it links up
// to kMaxRunnerPeerLinks (128: a link costs ~3 ZeroMQ sockets, its DEALER and its connection
// monitor's pair, and a flood of 1 100 fake members ran into the 1 023-socket limit at ~340
// links) members, and every node links it beyond its own cap (grid-64: with 32 nearest ids
// only, units 33 and up were out of the runner's reach and no round began). A
// member whose endpoint is not tcp:// or ipc:// (or is over 256 bytes) is not linked. The peer mesh
// does not depend on the coordinator: when it is down, peers keep heartbeating each other from the
// last member list; when it returns the node says Hello again and membership resumes.
//
// Services (node/net/node_service.h) consume coordinator replies and events and serve peer
// requests; long work runs on workers() and its completions run on the network thread in
// Step(), so a node busy with a long solve keeps heartbeating.
// Threading: Start/Step/Run and every service callback on one thread (the network thread);
// workers() is the only thread-safe entry point.
#pragma once

#include <atomic>
#include <chrono>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "common/base/ids.h"
#include "net/channel.h"
#include "net/curve.h"
#include "net/endpoint.h"
#include "net/handshake_monitor.h"
#include "net/server_loop.h"
#include "node/net/clock_offset_estimator.h"
#include "node/net/node_service.h"
#include "node/net/worker_pool.h"

namespace sandtable::node {

using Clock = std::chrono::steady_clock;

// What a node drives, announced in its Hello (wire::Capabilities).
struct NodeCapabilities {
  int projector_width_px = 0, projector_height_px = 0;  // 0: no projector
  int camera_width_px = 0, camera_height_px = 0;        // 0: no camera
  int camera_bit_depth = 0;
  double frame_rate_hz = 60.0;
  std::string projector_output;  // "world", "window", "none"
  std::string camera_input;      // "world", "video", "replay", "none"
};

inline constexpr int kMaxRunnerPeerLinks = 128;
// Services get an OnStep at least this often when nothing wakes the node (time-based checks:
// resends, silences, quiet periods).
inline constexpr std::chrono::milliseconds kServiceTick{30};
// Up to this many peers a node heartbeats each one every heartbeat_period; beyond, the period
// grows in proportion, so the heartbeats a node sends and receives stay flat as a site grows
// (64 nodes linking 32 peers each at 10 Hz were 20 000 messages a second on one machine).
inline constexpr double kPeersAtFullHeartbeatRate = 8.0;
// A peer is silent when not heard for this many of its own heartbeat periods (or the
// configured peer timeout, whichever is longer).
inline constexpr int kPeerSilencePeriods = 5;

struct NodeOptions {
  NodeId id = kInvalidNodeId;                   // below kFirstReservedSenderId
  std::string coordinator_requests;             // coordinator ROUTER endpoint
  std::string coordinator_events;               // the coordinator's events endpoint
  std::string peer_bind = "tcp://127.0.0.1:*";  // own ROUTER for peers
  // The host peers are told to connect to (empty: the bound address, or when bound to every
  // interface the one facing the coordinator; net/endpoint.h, docs/deploy.md).
  std::string peer_advertise_host;
  std::chrono::milliseconds heartbeat_period{100};
  std::chrono::milliseconds coordinator_timeout{500};  // silent this long: coordinator down
  std::chrono::milliseconds peer_timeout{500};         // silent this long: peer down
  std::chrono::milliseconds time_sync_period{100};
  int worker_threads = 1;
  int max_peer_links = 32;  // kMaxPeerLinks: peers linked at most (sockets)
  NodeCapabilities capabilities;
  std::optional<net::CurveKeyPair> curve;
  // Without CURVE the peer socket stays on loopback unless this is set (an open site; logged
  // every minute).
  bool insecure = false;
  proto::CodecLimits limits;
  // Lab chaos only (--fault-*): faults on every link this node sends on (its peer router, its
  // links to peers, its requests to the coordinator); net/channel.h.
  net::ChannelFaults faults;

  Status Check() const;
};

struct PeerInfo {
  std::string endpoint;
  uint64_t incarnation = 0;
  std::unique_ptr<net::Channel> to_peer;  // our DEALER to its ROUTER
  Clock::time_point last_heard{};         // last heartbeat it sent us
  uint64_t heartbeats_received = 0;
  std::chrono::milliseconds heartbeat_period{0};  // what its last heartbeat said (0: unsaid)
  wire::CalibrationState calibration_state = wire::CALIBRATION_STATE_UNSPECIFIED;  // its last
  // The DEALER's connection events (zmq_socket_monitor): a peer whose process died closes its
  // socket at once, long before its heartbeats are missed. Set when the connection dropped and
  // has not come back (cleared by the next handshake); services that must react within a frame
  // (the blend) read it. Destroyed before to_peer (declared after it).
  Clock::time_point disconnected_at{};
  // When it was linked and whether a connection to its advertised address ever completed: a
  // peer not reached within kPeerUnreachableAfter is logged once (its address does not route
  // from this host), and again once it is reached.
  Clock::time_point linked_at{};
  bool reached = false;
  bool unreachable_logged = false;
  std::unique_ptr<zmq::socket_t> monitor;
  int dealer_fd = -1, monitor_fd = -1;  // ZMQ_FD of to_peer and of monitor (-1: none)
};

class NodeRuntime {
 public:
  explicit NodeRuntime(NodeOptions options);
  ~NodeRuntime();

  // Adds a service (not owned; must outlive the runtime). Before Start().
  void AddService(NodeService* service);

  Status Start();
  NodeId id() const { return options_.id; }
  const std::string& peer_endpoint() const { return peer_endpoint_; }

  Status Step(std::chrono::milliseconds max_wait);
  // Steps until `stop`; then says Goodbye to the coordinator.
  Status Run(const std::atomic<bool>& stop);
  void SayGoodbye(const std::string& reason);

  // For services (network thread). Sends are fire-and-forget: a full queue or a gone peer is
  // an UNAVAILABLE status, never a block.
  Status SendToCoordinator(wire::Envelope envelope);
  Status SendToPeer(NodeId peer, wire::Envelope envelope);
  Status ReplyToPeer(const std::string& routing_id, wire::Envelope envelope);
  WorkerPool& workers() { return workers_; }

  // The peers to link to: nullopt = every member (before calibration knows the overlaps).
  void SetNeighbours(std::optional<std::set<NodeId>> neighbours);

  bool registered() const { return registered_; }
  bool coordinator_alive() const;
  std::optional<ClockOffsetEstimate> clock_offset() const { return clock_.Estimate(); }
  // The coordinator's steady clock now, as this node estimates it (offset 0 until known).
  int64_t CoordinatorNowNs() const;
  const std::map<NodeId, PeerInfo>& peers() const { return peers_; }
  // This node's heartbeat period to its peers: heartbeat_period up to
  // kPeersAtFullHeartbeatRate peers, in proportion beyond.
  std::chrono::milliseconds peer_heartbeat_period() const;
  // How long `peer` may be silent before it counts as down: `at_least`, or
  // kPeerSilencePeriods of the peer's own heartbeat period when that is longer.
  static std::chrono::milliseconds PeerSilence(const PeerInfo& peer,
                                               std::chrono::milliseconds at_least);
  // What this node tells its peers in every heartbeat (proto CalibrationState).
  // (A change is announced to the peers at once.)
  void set_calibration_state(wire::CalibrationState state);
  wire::CalibrationState calibration_state() const { return calibration_state_; }
  // The coordinator's last member list (nullopt before the first), and how long ago its
  // version last changed.
  const std::optional<wire::MemberList>& member_list() const { return last_member_list_; }
  std::chrono::milliseconds member_list_age() const {
    return std::chrono::duration_cast<std::chrono::milliseconds>(Clock::now() -
                                                                 member_list_changed_);
  }
  const proto::MessageCounters& counters() const { return counters_; }
  uint64_t registrations() const { return registrations_; }
  // The faults injected so far on this node's links (options.faults), closed links included.
  net::ChannelFaultCounts fault_counts() const;

 private:
  void HandleCoordinatorReply(const wire::Envelope& in);
  void HandleEvent(const wire::Envelope& in);
  void HandlePeerMessage(net::Incoming in);
  void ApplyMemberList(const wire::MemberList& list);
  void SendTimers(Clock::time_point now);
  void SetRegistered(bool registered);
  void DrainPeerDealers(const std::vector<NodeId>& ids);
  void DrainPeerMonitors(const std::vector<NodeId>& ids);
  // Sends what the injected latency held (lab faults); the earliest still held.
  std::optional<Clock::time_point> FlushDelayed(Clock::time_point now);
  // Logs, once, a peer linked kPeerUnreachableAfter ago that no connection has reached.
  void WarnIfUnreachable(NodeId id, PeerInfo& peer, Clock::time_point now);
  NodeService* CoordinatorServiceFor(wire::Envelope::BodyCase body) const;
  wire::Envelope MakeHello() const;
  net::SocketOptions ClientSocketOptions() const;

  NodeOptions options_;
  uint64_t incarnation_ = 0;
  zmq::context_t context_;
  std::unique_ptr<net::ZapHandler> zap_;
  std::unique_ptr<net::HandshakeMonitor> peer_monitor_;
  proto::MessageCounters counters_;
  net::ChannelFaultCounts closed_link_faults_;  // of peer links since closed
  std::unique_ptr<net::Channel> coordinator_;
  std::unique_ptr<net::Channel> events_;
  std::unique_ptr<net::Channel> peer_router_;
  net::ServerLoop loop_;
  std::string peer_endpoint_;
  std::map<NodeId, PeerInfo> peers_;
  uint64_t monitors_made_ = 0;
  std::optional<std::set<NodeId>> neighbours_;
  std::optional<wire::MemberList> last_member_list_;
  std::vector<NodeService*> services_;
  WorkerPool workers_;
  ClockOffsetEstimator clock_;
  bool registered_ = false;
  wire::CalibrationState calibration_state_ = wire::CALIBRATION_STATE_UNSPECIFIED;
  bool peer_links_capped_ = false;
  uint64_t registrations_ = 0;
  uint64_t member_list_version_ = 0;
  Clock::time_point member_list_changed_{};
  Clock::time_point last_coordinator_message_{};
  Clock::time_point next_heartbeat_{}, next_time_sync_{}, next_hello_{};
  // Unanswered Hellos: since when (the first one sent unregistered), how many, and when the
  // next log line says so (the gap doubles up to a minute).
  Clock::time_point unanswered_since_{}, next_unanswered_log_{};
  uint64_t hellos_unanswered_ = 0;
  std::unique_ptr<net::InsecureNotice> open_notice_;  // an open site's repeated warning
  std::chrono::seconds unanswered_log_gap_{5};
  Clock::time_point next_peer_drain_{}, next_peer_heartbeat_{};
  bool drain_all_peers_ = false;  // a drain stopped at its cap, or a peer was linked
};

}  // namespace sandtable::node
