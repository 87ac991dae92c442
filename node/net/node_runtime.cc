#include "node/net/node_runtime.h"

#include <cmath>
#include <cstring>

#include <algorithm>
#include <cstdlib>
#include <utility>

#include "common/base/log.h"

namespace sandtable::node {
namespace {

constexpr int kMaxPeerDrain = 100;
// A linked peer whose advertised address no connection reached in this long is logged.
constexpr std::chrono::seconds kPeerUnreachableAfter{5};
// A turn of the loop (handlers, completions, services) longer than this is logged.
constexpr std::chrono::milliseconds kBusyTurn{250};
constexpr size_t kMaxPeerEndpointBytes = 256;

bool LinkableEndpoint(const std::string& endpoint) {
  return !endpoint.empty() && endpoint.size() <= kMaxPeerEndpointBytes &&
         (endpoint.rfind("tcp://", 0) == 0 || endpoint.rfind("ipc://", 0) == 0) &&
         endpoint.find('*') == std::string::npos;
}

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

}  // namespace

Status NodeOptions::Check() const {
  if (id == kInvalidNodeId) return InvalidArgumentError("node: --id is required");
  if (!IsValidNodeId(id)) {
    return InvalidArgumentError("node: --id " + std::to_string(id) +
                                " collides with the ids reserved for the site's services (>= " +
                                std::to_string(kFirstReservedSenderId) + ")");
  }
  if (max_peer_links < 0 || max_peer_links > 512) {
    return InvalidArgumentError("node: max_peer_links must be in [0, 512]");
  }
  if (worker_threads < 1 || worker_threads > 64) {
    return InvalidArgumentError("node: worker_threads must be in [1, 64]");
  }
  if (Status f = faults.Check(); !f.ok()) return InvalidArgumentError("node: " + f.message());
  if (!curve && !insecure && net::BeyondLoopback(peer_bind)) {
    return InvalidArgumentError("node: --bind " + peer_bind +
                                " is beyond loopback without CURVE: give --curve-keys, or "
                                "--insecure for an open site anyone on the network may join");
  }
  if (coordinator_requests.empty() || coordinator_events.empty()) {
    return InvalidArgumentError(
        "node: coordinator endpoints are required (--coordinator REQUESTS,EVENTS)");
  }
  if (heartbeat_period.count() <= 0 || time_sync_period.count() <= 0) {
    return InvalidArgumentError("node: heartbeat and time sync periods must be > 0 ms");
  }
  if (coordinator_timeout < heartbeat_period || peer_timeout < heartbeat_period) {
    return InvalidArgumentError("node: timeouts must be at least one heartbeat period");
  }
  return limits.Check();
}

NodeRuntime::NodeRuntime(NodeOptions options)
    : options_(std::move(options)),
      incarnation_(net::NewIncarnation()),
      workers_(std::clamp(options_.worker_threads, 1, 64)) {}

void NodeRuntime::AddService(NodeService* service) {
  ST_CHECK(service != nullptr) << "NodeRuntime::AddService needs a service";
  ST_CHECK(coordinator_ == nullptr) << "add services before NodeRuntime::Start()";
  services_.push_back(service);
}

namespace {

// Stops a peer link's connection monitor before its sockets close. libzmq's I/O thread sends
// monitor events with a blocking send: an event for a DEALER whose monitor PAIR is already
// gone (or full) blocks that thread for ever, and with it every socket of the context: the
// node stopped hearing the coordinator, was declared dead and never registered again (grid-64:
// 16 nodes declared dead while 64 started, the member list shrank, the peers they dropped
// froze their survivors). Unregistering the monitor (endpoint null) is synchronous.
void StopPeerMonitor(PeerInfo& peer) {
  if (peer.monitor && peer.to_peer) {
    (void)zmq_socket_monitor(peer.to_peer->socket().raw().handle(), nullptr, 0);
  }
  peer.monitor.reset();
  peer.monitor_fd = -1;
}

}  // namespace

NodeRuntime::~NodeRuntime() {
  for (auto& [id, peer] : peers_) StopPeerMonitor(peer);
  peers_.clear();
  coordinator_.reset();
  events_.reset();
  if (peer_monitor_) peer_monitor_->Stop();
  peer_router_.reset();
  if (zap_) zap_->Stop();
}

net::SocketOptions NodeRuntime::ClientSocketOptions() const {
  net::SocketOptions o;
  o.max_message_bytes = static_cast<int64_t>(options_.limits.max_message_bytes);
  if (options_.curve) o.curve = net::ClientCurve(*options_.curve);
  return o;
}

Status NodeRuntime::Start() {
  ST_RETURN_IF_ERROR(options_.Check());
  net::SocketOptions server = ClientSocketOptions();
  if (options_.curve) {
    zap_ = std::make_unique<net::ZapHandler>(&context_,
                                             std::set<std::string>{options_.curve->public_key_z85});
    ST_RETURN_IF_ERROR(zap_->Start());
    server.curve = net::ServerCurve(*options_.curve);
  }
  auto router = net::Socket::Create(&context_, net::SocketType::kRouter, server);
  if (!router.ok()) return router.status();
  if (options_.curve) {
    // Logs peers refused during the handshake (no CURVE at all never reaches ZAP).
    peer_monitor_ = std::make_unique<net::HandshakeMonitor>();
    ST_RETURN_IF_ERROR(peer_monitor_->Attach(&context_, router->get(), "node peer router"));
  }
  Expected<std::string> bound = (*router)->Bind(options_.peer_bind);
  if (!bound.ok()) return bound.status().WithContext("peer socket");
  Expected<net::Advertised> advertised =
      net::AdvertisedEndpoint(*bound, options_.coordinator_requests, options_.peer_advertise_host);
  if (!advertised.ok()) return advertised.status().WithContext("peer socket");
  peer_endpoint_ = advertised->endpoint;
  if (!options_.curve && net::BeyondLoopback(options_.peer_bind)) {
    open_notice_ = std::make_unique<net::InsecureNotice>(
        "OPEN SITE (--insecure): this node's peer socket " + *bound +
        " listens beyond loopback without CURVE; anyone on the network may talk to it");
  }
  if (!advertised->note.empty()) {
    ST_LOG(kInfo) << "peer socket bound to " << *bound << ", advertised as " << peer_endpoint_
                  << ": " << advertised->note;
  }
  peer_router_ = std::make_unique<net::Channel>(std::move(*router), options_.id, incarnation_,
                                                &counters_, options_.limits);
  ST_RETURN_IF_ERROR(peer_router_->SetFaults(options_.faults));

  net::SocketOptions to_coordinator = ClientSocketOptions();
  // Let the Goodbye leave on shutdown.
  to_coordinator.linger = std::chrono::milliseconds(200);
  // Small queue: heartbeats queued while the coordinator is down are stale anyway.
  to_coordinator.send_high_water_mark = 16;
  auto dealer = net::Socket::Create(&context_, net::SocketType::kDealer, to_coordinator);
  if (!dealer.ok()) return dealer.status();
  ST_RETURN_IF_ERROR((*dealer)->Connect(options_.coordinator_requests));
  coordinator_ = std::make_unique<net::Channel>(std::move(*dealer), options_.id, incarnation_,
                                                &counters_, options_.limits);
  net::ChannelFaults coordinator_faults = options_.faults;
  coordinator_faults.seed ^= 0x9e3779b97f4a7c15ull;  // its own draws
  ST_RETURN_IF_ERROR(coordinator_->SetFaults(coordinator_faults));

  auto sub =
      net::Socket::Create(&context_, net::SocketType::kEventSubscriber, ClientSocketOptions());
  if (!sub.ok()) return sub.status();
  ST_RETURN_IF_ERROR((*sub)->Connect(options_.coordinator_events));
  events_ = std::make_unique<net::Channel>(std::move(*sub), options_.id, incarnation_, &counters_,
                                           options_.limits);
  loop_.Add(coordinator_.get(), [this](net::Incoming in) { HandleCoordinatorReply(in.envelope); });
  loop_.Add(events_.get(), [this](net::Incoming in) { HandleEvent(in.envelope); });
  loop_.Add(
      peer_router_.get(), [this](net::Incoming in) { HandlePeerMessage(std::move(in)); },
      /*answer_refusals=*/true);
  return OkStatus();
}

bool NodeRuntime::coordinator_alive() const {
  return last_coordinator_message_ != Clock::time_point{} &&
         Clock::now() - last_coordinator_message_ < options_.coordinator_timeout;
}

int64_t NodeRuntime::CoordinatorNowNs() const {
  const int64_t now_ns = proto::SteadyNowNs();
  const std::optional<ClockOffsetEstimate> offset = clock_.Estimate();
  return offset ? now_ns + static_cast<int64_t>(offset->offset_s * 1e9) : now_ns;
}

wire::Envelope NodeRuntime::MakeHello() const {
  wire::Envelope e;
  auto* hello = e.mutable_hello();
  hello->set_role(wire::ROLE_NODE);
  hello->set_incarnation(incarnation_);
  hello->mutable_endpoints()->set_peer_router(peer_endpoint_);
  hello->set_software_version("sandtable 0.1.0");
  const NodeCapabilities& c = options_.capabilities;
  wire::Capabilities* caps = hello->mutable_capabilities();
  caps->set_has_projector(c.projector_width_px > 0);
  caps->set_has_camera(c.camera_width_px > 0);
  caps->set_projector_width_px(static_cast<uint32_t>(std::max(0, c.projector_width_px)));
  caps->set_projector_height_px(static_cast<uint32_t>(std::max(0, c.projector_height_px)));
  caps->set_camera_width_px(static_cast<uint32_t>(std::max(0, c.camera_width_px)));
  caps->set_camera_height_px(static_cast<uint32_t>(std::max(0, c.camera_height_px)));
  caps->set_camera_bit_depth(static_cast<uint32_t>(std::max(0, c.camera_bit_depth)));
  caps->set_frame_rate_hz(c.frame_rate_hz);
  caps->set_projector_output(c.projector_output);
  caps->set_camera_input(c.camera_input);
  return e;
}

Status NodeRuntime::SendToCoordinator(wire::Envelope envelope) {
  Status sent = coordinator_->Send(std::move(envelope));
  if (!sent.ok()) ST_LOG(kDebug) << "to coordinator: " << sent.ToString();
  return sent;
}

Status NodeRuntime::SendToPeer(NodeId peer, wire::Envelope envelope) {
  auto it = peers_.find(peer);
  if (it == peers_.end()) {
    return UnavailableError("node " + std::to_string(peer) + " is not a linked peer");
  }
  return it->second.to_peer->Send(std::move(envelope));
}

Status NodeRuntime::ReplyToPeer(const std::string& routing_id, wire::Envelope envelope) {
  return peer_router_->Send(std::move(envelope), routing_id);
}

void NodeRuntime::SetNeighbours(std::optional<std::set<NodeId>> neighbours) {
  neighbours_ = std::move(neighbours);
  if (last_member_list_) ApplyMemberList(*last_member_list_);
}

std::chrono::milliseconds NodeRuntime::peer_heartbeat_period() const {
  const double scale =
      std::max(1.0, static_cast<double>(peers_.size()) / kPeersAtFullHeartbeatRate);
  return std::chrono::milliseconds(static_cast<int64_t>(
      std::ceil(static_cast<double>(options_.heartbeat_period.count()) * scale)));
}

std::chrono::milliseconds NodeRuntime::PeerSilence(const PeerInfo& peer,
                                                   std::chrono::milliseconds at_least) {
  return std::max(at_least, kPeerSilencePeriods * peer.heartbeat_period);
}

void NodeRuntime::set_calibration_state(wire::CalibrationState state) {
  if (state != calibration_state_) next_peer_heartbeat_ = Clock::time_point{};  // say it now
  calibration_state_ = state;
}

void NodeRuntime::SetRegistered(bool registered) {
  if (registered == registered_) return;
  registered_ = registered;
  if (!registered) return;
  ++registrations_;
  for (NodeService* service : services_) service->OnRegistered(*this);
}

NodeService* NodeRuntime::CoordinatorServiceFor(wire::Envelope::BodyCase body) const {
  for (NodeService* service : services_) {
    if (service->ServesCoordinator(body)) return service;
  }
  return nullptr;
}

void NodeRuntime::SendTimers(Clock::time_point now) {
  if (open_notice_) open_notice_->Tick(now);
  if (!registered_ && now >= next_hello_) {
    (void)SendToCoordinator(MakeHello());
    next_hello_ = now + options_.coordinator_timeout;
    if (hellos_unanswered_++ == 0) {
      unanswered_since_ = now;
      unanswered_log_gap_ = std::chrono::seconds(5);
      next_unanswered_log_ = now + unanswered_log_gap_;
    }
  }
  if (!registered_ && hellos_unanswered_ > 0 && now >= next_unanswered_log_) {
    const auto waited = std::chrono::duration_cast<std::chrono::seconds>(now - unanswered_since_);
    ST_LOG(kWarning) << "no answer from the coordinator at " << options_.coordinator_requests
                     << " for " << waited.count() << " s (" << hellos_unanswered_
                     << " hellos sent): is it running, is the address right"
                     << (options_.curve ? ", does its CURVE key match this site's key file" : "")
                     << "? Still trying";
    unanswered_log_gap_ =
        std::min<std::chrono::seconds>(2 * unanswered_log_gap_, std::chrono::seconds(60));
    next_unanswered_log_ = now + unanswered_log_gap_;
  }
  if (now >= next_heartbeat_) {
    next_heartbeat_ = now + options_.heartbeat_period;
    if (registered_) {
      wire::Envelope hb;
      hb.mutable_heartbeat()->set_incarnation(incarnation_);
      (void)SendToCoordinator(std::move(hb));
    }
    // A coordinator that went silent may have restarted: register again.
    if (registered_ && !coordinator_alive()) {
      SetRegistered(false);
      ST_LOG(kWarning) << "coordinator silent for more than "
                       << options_.coordinator_timeout.count() << " ms; peers keep running";
    }
  }
  if (now >= next_peer_heartbeat_) {
    const std::chrono::milliseconds period = peer_heartbeat_period();
    next_peer_heartbeat_ = now + period;
    for (auto& [id, peer] : peers_) {
      wire::Envelope hb;
      hb.mutable_heartbeat()->set_incarnation(incarnation_);
      hb.mutable_heartbeat()->set_calibration_state(calibration_state_);
      hb.mutable_heartbeat()->set_period_ms(static_cast<uint32_t>(period.count()));
      (void)peer.to_peer->Send(std::move(hb));  // a full queue means the peer is down
      WarnIfUnreachable(id, peer, now);
    }
  }
  if (now >= next_time_sync_) {
    next_time_sync_ = now + options_.time_sync_period;
    wire::Envelope request;
    request.mutable_time_request()->set_t0_client_send_ns(proto::SteadyNowNs());
    (void)SendToCoordinator(std::move(request));
  }
}

Status NodeRuntime::Step(std::chrono::milliseconds max_wait) {
  ST_CHECK(coordinator_ != nullptr) << "NodeRuntime::Step before a successful Start()";
  const Clock::time_point now = Clock::now();
  SendTimers(now);
  const std::optional<Clock::time_point> next_delayed = FlushDelayed(now);
  // Sleep until a socket, a peer's connection monitor or a finished job wakes us, or until
  // the next timer; services whose checks are time-based (resends, silences) get a turn at
  // least every kServiceTick. An idle node wakes ~30 times a second instead of polling: with
  // 64 nodes on two cores the idle polling alone was more than the machine (docs/lab.md).
  Clock::time_point next =
      std::min({next_heartbeat_, next_time_sync_, next_peer_drain_, next_peer_heartbeat_});
  if (!registered_) next = std::min(next, next_hello_);
  if (next_delayed) next = std::min(next, *next_delayed);
  if (drain_all_peers_) next = now;
  auto wait = std::min({max_wait, kServiceTick,
                        std::chrono::duration_cast<std::chrono::milliseconds>(next - now) +
                            std::chrono::milliseconds(1)});
  wait = std::max(wait, std::chrono::milliseconds(0));
  // Poll set beyond the loop's three channels, all plain file descriptors (one poll() for
  // them all; a ZeroMQ socket in zmq_poll costs two system calls of its own each time): the
  // worker pool's wake fd, then per peer the ZMQ_FD of its DEALER and of its monitor, which
  // turn readable when the socket has something to process. ZMQ_FD can miss a message that a
  // send on the same socket processed first: every DEALER and monitor is drained on each
  // heartbeat anyway (drain_all).
  std::vector<zmq::pollitem_t> extra;
  std::vector<std::pair<NodeId, bool>> extra_owner;  // (peer, is monitor)
  extra.reserve(1 + 2 * peers_.size());
  if (workers_.wake_fd() >= 0) extra.push_back({nullptr, workers_.wake_fd(), ZMQ_POLLIN, 0});
  const size_t first_peer_item = extra.size();
  for (const auto& [id, peer] : peers_) {
    if (peer.dealer_fd >= 0) {
      extra.push_back({nullptr, peer.dealer_fd, ZMQ_POLLIN, 0});
      extra_owner.push_back({id, false});
    }
    if (peer.monitor_fd >= 0) {
      extra.push_back({nullptr, peer.monitor_fd, ZMQ_POLLIN, 0});
      extra_owner.push_back({id, true});
    }
  }
  ST_RETURN_IF_ERROR(loop_.RunOnce(wait, &extra));
  // Handlers may relink peers (a member list): look each one up again by id.
  std::vector<NodeId> dealers, monitors;
  const bool drain_all = drain_all_peers_ || Clock::now() >= next_peer_drain_;
  if (drain_all) {
    drain_all_peers_ = false;
    next_peer_drain_ = Clock::now() + peer_heartbeat_period();
    for (const auto& [id, peer] : peers_) {
      dealers.push_back(id);
      monitors.push_back(id);
    }
  } else {
    for (size_t i = first_peer_item; i < extra.size(); ++i) {
      if (!(extra[i].revents & ZMQ_POLLIN)) continue;
      const auto& [id, is_monitor] = extra_owner[i - first_peer_item];
      (is_monitor ? monitors : dealers).push_back(id);
    }
  }
  const Clock::time_point drained_channels = Clock::now();
  DrainPeerMonitors(monitors);
  DrainPeerDealers(dealers);
  const Clock::time_point drained_peers = Clock::now();
  workers_.RunCompletions();
  const Clock::time_point completed = Clock::now();
  for (NodeService* service : services_) {
    if (Status stepped = service->OnStep(*this); !stepped.ok()) {
      ST_LOG(kWarning) << service->name() << ": " << stepped.ToString();
    }
  }
  // Everything after the poll runs on this one thread; a turn that long keeps the node from
  // heartbeating (the coordinator declares it dead after 5 periods): say where it went.
  const Clock::time_point done = Clock::now();
  if (done - loop_.last_woke() > kBusyTurn) {
    const auto ms = [](Clock::duration d) {
      return std::chrono::duration_cast<std::chrono::milliseconds>(d).count();
    };
    ST_LOG(kWarning) << "network thread busy " << ms(done - loop_.last_woke())
                     << " ms in one turn (channels " << ms(drained_channels - loop_.last_woke())
                     << " ms, peers " << ms(drained_peers - drained_channels) << " ms, completions "
                     << ms(completed - drained_peers) << " ms, services " << ms(done - completed)
                     << " ms)";
  }
  return OkStatus();
}

void NodeRuntime::DrainPeerDealers(const std::vector<NodeId>& ids) {
  // Peers answer on their own DEALER to our ROUTER; what arrives on our DEALERs is a Rejected
  // (or a reply to a routing id) from a peer's ROUTER: hand it to the services like any peer
  // message, so queues never fill.
  for (NodeId id : ids) {
    for (int i = 0;; ++i) {
      if (i == kMaxPeerDrain) {  // more waiting; its fd will not signal again for them
        drain_all_peers_ = true;
        break;
      }
      auto it = peers_.find(id);
      if (it == peers_.end()) break;
      Expected<std::optional<net::Incoming>> in = it->second.to_peer->TryReceive();
      if (!in.ok()) continue;
      if (!in->has_value()) break;
      if ((*in)->envelope.has_rejected()) {
        ST_LOG(kDebug) << "peer " << id
                       << " rejected our message: " << (*in)->envelope.rejected().reason();
        continue;
      }
      HandlePeerMessage(std::move(**in));
    }
  }
}

void NodeRuntime::HandleCoordinatorReply(const wire::Envelope& in) {
  const int64_t t3_ns = proto::SteadyNowNs();
  last_coordinator_message_ = Clock::now();
  switch (in.body_case()) {
    case wire::Envelope::kHelloAck:
      if (in.hello_ack().accepted()) {
        if (!registered_) {
          ST_LOG(kInfo) << "registered with the coordinator"
                        << (hellos_unanswered_ > 1
                                ? " after " + std::to_string(hellos_unanswered_) + " hellos"
                                : std::string());
        }
        hellos_unanswered_ = 0;
        SetRegistered(true);
      } else {
        ST_LOG(kWarning) << "coordinator refused us: " << in.hello_ack().reason();
      }
      break;
    case wire::Envelope::kHeartbeatAck:
      if (!in.heartbeat_ack().known()) {
        SetRegistered(false);  // the coordinator restarted or declared us dead: Hello again
        next_hello_ = Clock::now();
      }
      break;
    case wire::Envelope::kTimeReply: {
      const wire::TimeReply& r = in.time_reply();
      if (!clock_.AddSample(r.t0_client_send_ns(), r.t1_server_receive_ns(), r.t2_server_send_ns(),
                            t3_ns)) {
        counters_.CountRejected(proto::RejectReason::kInvalidContent);
      }
      break;
    }
    case wire::Envelope::kRejected:
      ST_LOG(kWarning) << "coordinator rejected our message: " << in.rejected().reason();
      break;
    default:
      if (NodeService* service = CoordinatorServiceFor(in.body_case())) {
        service->OnCoordinatorMessage(in, *this);
      } else {
        counters_.CountRejected(proto::RejectReason::kWrongType);
      }
  }
}

void NodeRuntime::HandleEvent(const wire::Envelope& in) {
  last_coordinator_message_ = Clock::now();
  if (in.has_member_list()) {
    ApplyMemberList(in.member_list());
    return;
  }
  if (NodeService* service = CoordinatorServiceFor(in.body_case())) {
    service->OnCoordinatorMessage(in, *this);
  }
  // Events no service consumes (e.g. tracker poses on a node that renders no cursor) are
  // accepted and dropped.
}

void NodeRuntime::ApplyMemberList(const wire::MemberList& list) {
  if (!last_member_list_ || &list != &*last_member_list_) last_member_list_ = list;
  const wire::MemberList& members = *last_member_list_;
  if (members.version() != member_list_version_) member_list_changed_ = Clock::now();
  member_list_version_ = members.version();
  std::vector<const wire::Member*> candidates;
  for (const wire::Member& m : members.members()) {
    const bool neighbour = !neighbours_ || neighbours_->count(m.node_id()) > 0;
    if (m.node_id() != options_.id && IsValidNodeId(m.node_id()) && neighbour &&
        LinkableEndpoint(m.endpoints().peer_router())) {
      candidates.push_back(&m);
    }
  }
  // At most max_peer_links: the nearest ids (a deterministic choice every node agrees on).
  const auto distance = [this](const wire::Member* m) {
    return std::abs(static_cast<int64_t>(m->node_id()) - static_cast<int64_t>(options_.id));
  };
  // The lowest id runs the site's calibration rounds and must reach every unit: it links up to
  // kMaxRunnerPeerLinks, and every node links it (beyond the cap: max_peer_links + 1 at most).
  NodeId lowest = options_.id;
  const wire::Member* lowest_member = nullptr;
  for (const wire::Member& m : members.members()) {
    if (IsValidNodeId(m.node_id()) && m.node_id() < lowest &&
        LinkableEndpoint(m.endpoints().peer_router())) {
      lowest = m.node_id();
      lowest_member = &m;
    }
  }
  const size_t cap = lowest == options_.id ? static_cast<size_t>(kMaxRunnerPeerLinks)
                                           : static_cast<size_t>(options_.max_peer_links);
  const size_t links = std::min(candidates.size(), cap);
  std::partial_sort(candidates.begin(), candidates.begin() + static_cast<std::ptrdiff_t>(links),
                    candidates.end(), [&](const wire::Member* a, const wire::Member* b) {
                      return std::make_pair(distance(a), a->node_id()) <
                             std::make_pair(distance(b), b->node_id());
                    });
  if (candidates.size() > links && !peer_links_capped_) {
    ST_LOG(kWarning) << candidates.size() << " members qualify as peers; linking the " << links
                     << " nearest ids only (max_peer_links)";
  }
  peer_links_capped_ = candidates.size() > links;
  std::map<NodeId, const wire::Member*> listed;
  for (size_t i = 0; i < links; ++i) listed[candidates[i]->node_id()] = candidates[i];
  if (lowest_member) listed[lowest_member->node_id()] = lowest_member;
  for (auto it = peers_.begin(); it != peers_.end();) {
    auto found = listed.find(it->first);
    const bool gone = found == listed.end() ||
                      found->second->incarnation() != it->second.incarnation ||
                      found->second->endpoints().peer_router() != it->second.endpoint;
    if (gone && it->second.to_peer) {
      closed_link_faults_.dropped += it->second.to_peer->fault_counts().dropped;
      closed_link_faults_.corrupted += it->second.to_peer->fault_counts().corrupted;
      closed_link_faults_.delayed += it->second.to_peer->fault_counts().delayed;
      closed_link_faults_.delayed_dropped += it->second.to_peer->fault_counts().delayed_dropped;
    }
    if (gone) StopPeerMonitor(it->second);
    it = gone ? peers_.erase(it) : std::next(it);
  }
  for (const auto& [id, member] : listed) {
    if (peers_.count(id)) continue;
    auto dealer = net::Socket::Create(&context_, net::SocketType::kDealer, ClientSocketOptions());
    if (!dealer.ok() || !(*dealer)->Connect(member->endpoints().peer_router()).ok()) {
      ST_LOG(kWarning) << "cannot connect to peer " << id << " at "
                       << member->endpoints().peer_router();
      continue;
    }
    // Connection events of the DEALER on an inproc PAIR (zmq_socket_monitor), polled in Step.
    std::unique_ptr<zmq::socket_t> monitor;
    const std::string monitor_endpoint =
        "inproc://peer-monitor-" + std::to_string(id) + "-" + std::to_string(++monitors_made_);
    if (zmq_socket_monitor((*dealer)->raw().handle(), monitor_endpoint.c_str(),
                           ZMQ_EVENT_DISCONNECTED | ZMQ_EVENT_HANDSHAKE_SUCCEEDED) == 0) {
      try {
        monitor = std::make_unique<zmq::socket_t>(context_, zmq::socket_type::pair);
        monitor->set(zmq::sockopt::linger, 0);
        monitor->connect(monitor_endpoint);
      } catch (const zmq::error_t& e) {
        ST_LOG(kWarning) << "peer " << id << ": no connection monitor: " << e.what();
        monitor.reset();
      }
    }
    PeerInfo& peer = peers_[id];
    peer.linked_at = Clock::now();
    peer.endpoint = member->endpoints().peer_router();
    peer.incarnation = member->incarnation();
    peer.to_peer = std::make_unique<net::Channel>(std::move(*dealer), options_.id, incarnation_,
                                                  &counters_, options_.limits);
    net::ChannelFaults link_faults = options_.faults;
    link_faults.seed = options_.faults.seed * 1000003ull + id;  // one stream per link
    (void)peer.to_peer->SetFaults(link_faults);                 // checked in NodeOptions::Check
    peer.monitor = std::move(monitor);
    try {
      peer.dealer_fd = peer.to_peer->socket().raw().get(zmq::sockopt::fd);
      if (peer.monitor) peer.monitor_fd = peer.monitor->get(zmq::sockopt::fd);
    } catch (const zmq::error_t& e) {
      ST_LOG(kWarning) << "peer " << id << ": no ZMQ_FD (drained on heartbeats only): " << e.what();
    }
    drain_all_peers_ = true;
  }
}

net::ChannelFaultCounts NodeRuntime::fault_counts() const {
  net::ChannelFaultCounts total = closed_link_faults_;
  auto add = [&](const net::Channel* c) {
    if (!c) return;
    total.dropped += c->fault_counts().dropped;
    total.corrupted += c->fault_counts().corrupted;
    total.delayed += c->fault_counts().delayed;
    total.delayed_dropped += c->fault_counts().delayed_dropped;
  };
  add(peer_router_.get());
  add(coordinator_.get());
  for (const auto& [id, peer] : peers_) add(peer.to_peer.get());
  return total;
}

void NodeRuntime::DrainPeerMonitors(const std::vector<NodeId>& ids) {
  for (NodeId id : ids) {
    auto found = peers_.find(id);
    if (found == peers_.end() || !found->second.monitor) continue;
    PeerInfo& peer = found->second;
    // Each event is two frames: 6 bytes (uint16 event, uint32 value) and the endpoint.
    for (int i = 0;; ++i) {
      if (i == kMaxPeerDrain) {
        drain_all_peers_ = true;
        break;
      }
      zmq::message_t event, address;
      zmq::recv_result_t got;
      try {
        got = peer.monitor->recv(event, zmq::recv_flags::dontwait);
        if (!got) break;
        if (event.more()) (void)peer.monitor->recv(address, zmq::recv_flags::dontwait);
      } catch (const zmq::error_t&) {
        break;
      }
      if (event.size() < 2) continue;
      uint16_t code = 0;
      std::memcpy(&code, event.data(), sizeof(code));
      if (code == ZMQ_EVENT_DISCONNECTED) {
        if (peer.disconnected_at == Clock::time_point{}) peer.disconnected_at = Clock::now();
      } else if (code == ZMQ_EVENT_HANDSHAKE_SUCCEEDED) {
        peer.disconnected_at = Clock::time_point{};
        if (peer.unreachable_logged) {
          ST_LOG(kInfo) << "peer " << id << " at " << peer.endpoint << " reached after "
                        << std::chrono::duration_cast<std::chrono::seconds>(Clock::now() -
                                                                            peer.linked_at)
                               .count()
                        << " s";
        }
        peer.reached = true;
        peer.unreachable_logged = false;
      }
    }
  }
}

std::optional<Clock::time_point> NodeRuntime::FlushDelayed(Clock::time_point now) {
  if (options_.faults.delay.count() == 0) return std::nullopt;
  std::optional<Clock::time_point> next;
  auto flush = [&](net::Channel* channel) {
    channel->FlushDelayed(now);
    if (auto due = channel->next_delayed_due(); due && (!next || *due < *next)) next = due;
  };
  flush(coordinator_.get());
  flush(peer_router_.get());
  for (auto& [id, peer] : peers_) flush(peer.to_peer.get());
  return next;
}

void NodeRuntime::WarnIfUnreachable(NodeId id, PeerInfo& peer, Clock::time_point now) {
  // Without a monitor there are no connection events to go by.
  if (peer.reached || peer.unreachable_logged || !peer.monitor ||
      now - peer.linked_at < kPeerUnreachableAfter) {
    return;
  }
  peer.unreachable_logged = true;
  ST_LOG(kWarning)
      << "peer " << id << " advertised " << peer.endpoint << ", and no connection to it "
      << "completed in "
      << std::chrono::duration_cast<std::chrono::seconds>(kPeerUnreachableAfter).count()
      << " s: is that address reachable from this host (a firewall, a loopback "
         "address, a wrong --advertise on that unit, different site keys)? Still trying";
}

void NodeRuntime::HandlePeerMessage(net::Incoming in) {
  const wire::Envelope& e = in.envelope;
  if (e.has_heartbeat()) {
    auto it = peers_.find(e.sender_id());
    if (it != peers_.end()) {
      it->second.last_heard = Clock::now();
      ++it->second.heartbeats_received;
      it->second.calibration_state = e.heartbeat().calibration_state();
      it->second.heartbeat_period = std::chrono::milliseconds(e.heartbeat().period_ms());
    }
    return;
  }
  if (!e.has_peer_status_request()) {
    for (NodeService* service : services_) {
      if (service->ServesPeer(e.body_case())) {
        service->OnPeerMessage(std::move(in), *this);
        return;
      }
    }
  }
  wire::Envelope reply;
  if (e.has_peer_status_request()) {
    const Clock::time_point now = Clock::now();
    auto* status = reply.mutable_peer_status_reply();
    status->set_coordinator_alive(coordinator_alive());
    status->set_member_list_version(member_list_version_);
    for (const auto& [id, peer] : peers_) {
      auto* p = status->add_peers();
      p->set_node_id(id);
      const bool heard = peer.last_heard != Clock::time_point{};
      p->set_alive(heard && now - peer.last_heard < PeerSilence(peer, options_.peer_timeout));
      p->set_last_heard_age_s(heard ? Seconds(now - peer.last_heard) : -1.0);
      p->set_heartbeats_received(peer.heartbeats_received);
    }
    if (auto estimate = clock_.Estimate()) {
      status->set_clock_offset_s(estimate->offset_s);
      status->set_clock_offset_error_s(estimate->error_bound_s);
    }
    status->set_messages_rejected(counters_.total_rejected());
  } else {
    counters_.CountRejected(proto::RejectReason::kWrongType);
    reply.mutable_rejected()->set_rejected_sequence(e.sequence());
    reply.mutable_rejected()->set_reason("node peer socket does not serve " + proto::BodyName(e));
  }
  (void)peer_router_->Send(std::move(reply), in.routing_id);
}

void NodeRuntime::SayGoodbye(const std::string& reason) {
  if (!coordinator_) return;
  wire::Envelope bye;
  bye.mutable_goodbye()->set_reason(reason);
  (void)SendToCoordinator(std::move(bye));
}

Status NodeRuntime::Run(const std::atomic<bool>& stop) {
  while (!stop.load()) {
    ST_RETURN_IF_ERROR(Step(std::chrono::milliseconds(50)));
  }
  SayGoodbye("shutdown");
  return OkStatus();
}

}  // namespace sandtable::node
