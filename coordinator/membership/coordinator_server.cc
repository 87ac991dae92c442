#include "coordinator/membership/coordinator_server.h"

#include "common/base/log.h"

namespace sandtable::coordinator {

Status CoordinatorOptions::Check() const {
  ST_RETURN_IF_ERROR(membership.Check());
  ST_RETURN_IF_ERROR(limits.Check());
  if (step_period.count() <= 0)
    return InvalidArgumentError("coordinator: step_period must be > 0 ms");
  if (republish_period.count() <= 0) {
    return InvalidArgumentError("coordinator: republish_period must be > 0 ms");
  }
  return OkStatus();
}

CoordinatorServer::CoordinatorServer(CoordinatorOptions options)
    : options_(std::move(options)), members_(options_.membership) {}

CoordinatorServer::~CoordinatorServer() {
  for (auto& monitor : handshake_monitors_) monitor->Stop();
  requests_.reset();
  events_.reset();
  if (zap_) zap_->Stop();
}

Status CoordinatorServer::MonitorHandshakes(net::Socket* socket, const char* name) {
  // Only with CURVE: a client without keys is dropped in the ZMTP greeting and never reaches
  // ZAP, so the monitor is what logs its refusal.
  if (!options_.curve) return OkStatus();
  auto monitor = std::make_unique<net::HandshakeMonitor>();
  ST_RETURN_IF_ERROR(monitor->Attach(&context_, socket, name));
  handshake_monitors_.push_back(std::move(monitor));
  return OkStatus();
}

Status CoordinatorServer::Start() {
  ST_RETURN_IF_ERROR(options_.Check());
  net::SocketOptions socket_options;
  socket_options.max_message_bytes = static_cast<int64_t>(options_.limits.max_message_bytes);
  if (options_.curve) {
    zap_ = std::make_unique<net::ZapHandler>(&context_,
                                             std::set<std::string>{options_.curve->public_key_z85});
    ST_RETURN_IF_ERROR(zap_->Start());
    socket_options.curve = net::ServerCurve(*options_.curve);
  }
  const uint64_t incarnation = net::NewIncarnation();
  Expected<std::unique_ptr<net::Socket>> router =
      net::Socket::Create(&context_, net::SocketType::kRouter, socket_options);
  if (!router.ok()) return router.status();
  ST_RETURN_IF_ERROR(MonitorHandshakes(router->get(), "coordinator requests"));
  Expected<std::string> request_endpoint = (*router)->Bind(options_.request_endpoint);
  if (!request_endpoint.ok()) return request_endpoint.status().WithContext("requests");
  request_endpoint_ = *request_endpoint;
  requests_ = std::make_unique<net::Channel>(std::move(*router), kCoordinatorSenderId, incarnation,
                                             &counters_, options_.limits);

  Expected<std::unique_ptr<net::Socket>> pub =
      net::Socket::Create(&context_, net::SocketType::kPub, socket_options);
  if (!pub.ok()) return pub.status();
  ST_RETURN_IF_ERROR(MonitorHandshakes(pub->get(), "coordinator events"));
  Expected<std::string> event_endpoint = (*pub)->Bind(options_.event_endpoint);
  if (!event_endpoint.ok()) return event_endpoint.status().WithContext("events");
  event_endpoint_ = *event_endpoint;
  events_ = std::make_unique<net::Channel>(std::move(*pub), kCoordinatorSenderId, incarnation,
                                           &counters_, options_.limits);
  loop_.Add(
      requests_.get(), [this](net::Incoming in) { HandleRequest(std::move(in)); },
      /*answer_refusals=*/true);
  return OkStatus();
}

Status CoordinatorServer::Step(std::chrono::milliseconds max_wait) {
  ST_CHECK(requests_ != nullptr) << "CoordinatorServer::Step before a successful Start()";
  // Never sleep past the next expiry check: dead nodes must be found within a period.
  const auto wait = std::min(max_wait, options_.membership.heartbeat_period / 2);
  ST_RETURN_IF_ERROR(loop_.RunOnce(wait));
  for (CoordinatorService* service : services_) ST_RETURN_IF_ERROR(service->OnStep(*this));
  const Clock::time_point now = Clock::now();
  for (NodeId id : members_.ExpireSilent(now)) {
    ST_LOG(kInfo) << "node " << id << " declared dead (silent for more than "
                  << options_.membership.Timeout().count() << " ms)";
    requests_->ForgetSender(id);
  }
  if (members_.version() != published_version_ ||
      now - last_publish_ >= options_.republish_period) {
    ST_RETURN_IF_ERROR(PublishMemberList());
  }
  return OkStatus();
}

Status CoordinatorServer::Run(const std::atomic<bool>& stop) {
  while (!stop.load()) {
    ST_RETURN_IF_ERROR(Step(options_.step_period));
  }
  return OkStatus();
}

Status CoordinatorServer::Publish(wire::Envelope event) { return events_->Send(std::move(event)); }

Status CoordinatorServer::Reply(wire::Envelope reply, const std::string& routing_id) {
  return requests_->Send(std::move(reply), routing_id);
}

Status CoordinatorServer::PublishMemberList() {
  wire::Envelope envelope;
  *envelope.mutable_member_list() = members_.ToWire();
  published_version_ = members_.version();
  last_publish_ = Clock::now();
  return events_->Send(std::move(envelope));
}

void CoordinatorServer::HandleRequest(net::Incoming request) {
  const wire::Envelope& in = request.envelope;
  const NodeId sender = in.sender_id();
  const Clock::time_point now = Clock::now();
  for (CoordinatorService* service : services_) {
    if (service->Serves(in.body_case())) {
      service->OnRequest(std::move(request), *this);
      return;
    }
  }
  wire::Envelope reply;
  switch (in.body_case()) {
    case wire::Envelope::kHello: {
      const HelloOutcome outcome = members_.OnHello(sender, in.hello(), now);
      if (outcome != HelloOutcome::kRepeated) {
        ST_LOG(kInfo) << "node " << sender
                      << (outcome == HelloOutcome::kJoined ? " joined" : " restarted")
                      << " (peer endpoint " << in.hello().endpoints().peer_router() << ")";
      }
      auto* ack = reply.mutable_hello_ack();
      ack->set_accepted(true);
      ack->set_heartbeat_period_s(
          std::chrono::duration<double>(options_.membership.heartbeat_period).count());
      ack->set_heartbeat_misses_allowed(static_cast<uint32_t>(options_.membership.misses_allowed));
      ack->set_member_list_version(members_.version());
      break;
    }
    case wire::Envelope::kHeartbeat: {
      auto* ack = reply.mutable_heartbeat_ack();
      ack->set_known(members_.OnHeartbeat(sender, in.heartbeat().incarnation(), now));
      ack->set_member_list_version(members_.version());
      break;
    }
    case wire::Envelope::kGoodbye:
      if (members_.OnGoodbye(sender)) {
        ST_LOG(kInfo) << "node " << sender << " left: " << in.goodbye().reason();
      }
      requests_->ForgetSender(sender);
      return;  // no reply: the node is closing
    case wire::Envelope::kTimeRequest: {
      auto* time = reply.mutable_time_reply();
      time->set_t0_client_send_ns(in.time_request().t0_client_send_ns());
      // t1: when this message was taken off the socket; t2: as late as possible before send.
      time->set_t1_server_receive_ns(
          std::chrono::duration_cast<std::chrono::nanoseconds>(now.time_since_epoch()).count());
      time->set_t2_server_send_ns(proto::SteadyNowNs());
      break;
    }
    default: {
      counters_.CountRejected(proto::RejectReason::kWrongType);
      auto* rejected = reply.mutable_rejected();
      rejected->set_rejected_sequence(in.sequence());
      rejected->set_reason("coordinator requests socket does not serve " + proto::BodyName(in));
      break;
    }
  }
  Status sent = requests_->Send(std::move(reply), request.routing_id);
  if (!sent.ok()) ST_LOG(kDebug) << "reply to node " << sender << " dropped: " << sent.ToString();
}

}  // namespace sandtable::coordinator
