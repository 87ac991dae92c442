#include "node/net/node_runtime.h"

#include <random>

#include "common/base/log.h"

namespace sandtable::node {
namespace {

uint64_t NewIncarnation() {
  std::random_device device;
  return (uint64_t{device()} << 32) ^ device() ^
         static_cast<uint64_t>(Clock::now().time_since_epoch().count());
}

double Seconds(Clock::duration d) { return std::chrono::duration<double>(d).count(); }

}  // namespace

Status NodeOptions::Check() const {
  if (id == kInvalidNodeId) return InvalidArgumentError("node: --id is required");
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
    : options_(std::move(options)), incarnation_(NewIncarnation()) {}

NodeRuntime::~NodeRuntime() {
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
  peer_endpoint_ = *bound;
  peer_router_ = std::make_unique<net::Channel>(std::move(*router), options_.id, incarnation_,
                                                &counters_, options_.limits);

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

  auto sub = net::Socket::Create(&context_, net::SocketType::kSub, ClientSocketOptions());
  if (!sub.ok()) return sub.status();
  ST_RETURN_IF_ERROR((*sub)->Connect(options_.coordinator_events));
  events_ = std::make_unique<net::Channel>(std::move(*sub), options_.id, incarnation_, &counters_,
                                           options_.limits);
  return OkStatus();
}

bool NodeRuntime::coordinator_alive() const {
  return last_coordinator_message_ != Clock::time_point{} &&
         Clock::now() - last_coordinator_message_ < options_.coordinator_timeout;
}

wire::Envelope NodeRuntime::MakeHello() const {
  wire::Envelope e;
  auto* hello = e.mutable_hello();
  hello->set_role(wire::ROLE_NODE);
  hello->set_incarnation(incarnation_);
  hello->mutable_endpoints()->set_peer_router(peer_endpoint_);
  hello->set_software_version("sandtable 0.1.0");
  return e;
}

void NodeRuntime::SendToCoordinator(wire::Envelope envelope) {
  Status sent = coordinator_->Send(std::move(envelope));
  if (!sent.ok()) ST_LOG(kDebug) << "to coordinator: " << sent.ToString();
}

void NodeRuntime::SendTimers(Clock::time_point now) {
  if (!registered_ && now >= next_hello_) {
    SendToCoordinator(MakeHello());
    next_hello_ = now + options_.coordinator_timeout;
  }
  if (now >= next_heartbeat_) {
    next_heartbeat_ = now + options_.heartbeat_period;
    if (registered_) {
      wire::Envelope hb;
      hb.mutable_heartbeat()->set_incarnation(incarnation_);
      SendToCoordinator(std::move(hb));
    }
    for (auto& [id, peer] : peers_) {
      wire::Envelope hb;
      hb.mutable_heartbeat()->set_incarnation(incarnation_);
      (void)peer.to_peer->Send(std::move(hb));  // a full queue means the peer is down
    }
    // A coordinator that went silent may have restarted: register again.
    if (registered_ && !coordinator_alive()) {
      registered_ = false;
      ST_LOG(kWarning) << "coordinator silent for more than "
                       << options_.coordinator_timeout.count() << " ms; peers keep running";
    }
  }
  if (now >= next_time_sync_) {
    next_time_sync_ = now + options_.time_sync_period;
    wire::Envelope request;
    request.mutable_time_request()->set_t0_client_send_ns(proto::SteadyNowNs());
    SendToCoordinator(std::move(request));
  }
}

Status NodeRuntime::Step(std::chrono::milliseconds max_wait) {
  ST_CHECK(coordinator_ != nullptr) << "NodeRuntime::Step before a successful Start()";
  SendTimers(Clock::now());
  const auto wait = std::min(max_wait, options_.heartbeat_period / 4);
  std::vector<bool> readable;
  ST_RETURN_IF_ERROR(net::Socket::Poll(
      {&coordinator_->socket(), &events_->socket(), &peer_router_->socket()}, wait, &readable));
  net::Channel* channels[] = {coordinator_.get(), events_.get(), peer_router_.get()};
  for (int c = 0; c < 3; ++c) {
    if (!readable[c]) continue;
    for (int drained = 0; drained < 1000; ++drained) {
      Expected<std::optional<net::Incoming>> in = channels[c]->TryReceive();
      if (!in.ok()) {
        ST_LOG(kDebug) << "rejected message: " << in.status().ToString();
        continue;
      }
      if (!in->has_value()) break;
      if (c == 0) {
        HandleCoordinatorReply((*in)->envelope);
      } else if (c == 1) {
        HandleEvent((*in)->envelope);
      } else {
        HandlePeerMessage(std::move(**in));
      }
    }
  }
  return OkStatus();
}

void NodeRuntime::HandleCoordinatorReply(const wire::Envelope& in) {
  const int64_t t3_ns = proto::SteadyNowNs();
  last_coordinator_message_ = Clock::now();
  switch (in.body_case()) {
    case wire::Envelope::kHelloAck:
      if (in.hello_ack().accepted()) {
        if (!registered_) ST_LOG(kInfo) << "registered with the coordinator";
        registered_ = true;
      } else {
        ST_LOG(kWarning) << "coordinator refused us: " << in.hello_ack().reason();
      }
      break;
    case wire::Envelope::kHeartbeatAck:
      if (!in.heartbeat_ack().known()) {
        registered_ = false;  // the coordinator restarted or declared us dead: Hello again
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
      counters_.CountRejected(proto::RejectReason::kWrongType);
  }
}

void NodeRuntime::HandleEvent(const wire::Envelope& in) {
  last_coordinator_message_ = Clock::now();
  if (in.has_member_list()) {
    ApplyMemberList(in.member_list());
    return;
  }
  // Tracker, cursor, annotation and timeline events are consumed by later modules.
}

void NodeRuntime::ApplyMemberList(const wire::MemberList& list) {
  member_list_version_ = list.version();
  std::map<NodeId, const wire::Member*> listed;
  for (const wire::Member& m : list.members()) {
    if (m.node_id() != options_.id && !m.endpoints().peer_router().empty()) {
      listed[m.node_id()] = &m;
    }
  }
  for (auto it = peers_.begin(); it != peers_.end();) {
    auto found = listed.find(it->first);
    const bool gone = found == listed.end() ||
                      found->second->incarnation() != it->second.incarnation ||
                      found->second->endpoints().peer_router() != it->second.endpoint;
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
    PeerInfo& peer = peers_[id];
    peer.endpoint = member->endpoints().peer_router();
    peer.incarnation = member->incarnation();
    peer.to_peer = std::make_unique<net::Channel>(std::move(*dealer), options_.id, incarnation_,
                                                  &counters_, options_.limits);
  }
}

void NodeRuntime::HandlePeerMessage(net::Incoming in) {
  const wire::Envelope& e = in.envelope;
  if (e.has_heartbeat()) {
    auto it = peers_.find(e.sender_id());
    if (it != peers_.end()) {
      it->second.last_heard = Clock::now();
      ++it->second.heartbeats_received;
    }
    return;
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
      p->set_alive(heard && now - peer.last_heard < options_.peer_timeout);
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
  SendToCoordinator(std::move(bye));
}

Status NodeRuntime::Run(const std::atomic<bool>& stop) {
  while (!stop.load()) {
    ST_RETURN_IF_ERROR(Step(std::chrono::milliseconds(50)));
  }
  SayGoodbye("shutdown");
  return OkStatus();
}

}  // namespace sandtable::node
