#include "coordinator/membership/coordinator_server.h"

#include <thread>

#include "common/base/log.h"
#include "net/endpoint.h"

namespace sandtable::coordinator {

Status CoordinatorOptions::Check() const {
  ST_RETURN_IF_ERROR(membership.Check());
  ST_RETURN_IF_ERROR(limits.Check());
  ST_RETURN_IF_ERROR(events.Check());
  ST_RETURN_IF_ERROR(enrollment.Check());
  if (!enroll_endpoint.empty() && !curve) {
    return InvalidArgumentError(
        "coordinator: enrollment needs CURVE (an accepted unit is handed the site's key): give "
        "--curve-keys");
  }
  if (step_period.count() <= 0)
    return InvalidArgumentError("coordinator: step_period must be > 0 ms");
  if (republish_period.count() <= 0) {
    return InvalidArgumentError("coordinator: republish_period must be > 0 ms");
  }
  for (const std::string* endpoint : {&request_endpoint, &event_endpoint}) {
    if (!curve && !insecure && net::BeyondLoopback(*endpoint)) {
      return InvalidArgumentError(
          "coordinator: " + *endpoint +
          " is beyond loopback without CURVE: anyone on the network could join the site, read "
          "its events and write its annotations; give --curve-keys, or --insecure for an open "
          "site");
    }
  }
  return OkStatus();
}

CoordinatorServer::CoordinatorServer(CoordinatorOptions options)
    : options_(std::move(options)), desk_(options_.enrollment), members_(options_.membership) {}

CoordinatorServer::~CoordinatorServer() {
  for (auto& monitor : handshake_monitors_) monitor->Stop();
  requests_.reset();
  events_.reset();
  enroll_.reset();
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
  if (!options_.curve && (net::BeyondLoopback(options_.request_endpoint) ||
                          net::BeyondLoopback(options_.event_endpoint))) {
    open_notice_ = std::make_unique<net::InsecureNotice>(
        "OPEN SITE (--insecure): the coordinator listens beyond loopback without CURVE; anyone "
        "on the network may join the site, read its events and write its annotations");
  }
  net::SocketOptions socket_options;
  socket_options.max_message_bytes = static_cast<int64_t>(options_.limits.max_message_bytes);
  if (options_.curve) {
    zap_ = std::make_unique<net::ZapHandler>(&context_,
                                             std::set<std::string>{options_.curve->public_key_z85});
    if (!options_.enroll_endpoint.empty()) zap_->AdmitAnyKeyIn(net::kEnrollZapDomain);
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

  Expected<std::unique_ptr<net::EventPublisher>> events =
      net::EventPublisher::Bind(&context_, socket_options, options_.events, options_.event_endpoint,
                                kCoordinatorSenderId, incarnation, &counters_, options_.limits);
  if (!events.ok()) return events.status().WithContext("events");
  events_ = std::move(*events);
  event_endpoint_ = events_->endpoint();
  ST_RETURN_IF_ERROR(MonitorHandshakes(&events_->socket(), "coordinator events"));
  loop_.Add(
      requests_.get(), [this](net::Incoming in) { HandleRequest(std::move(in)); },
      /*answer_refusals=*/true);
  if (!options_.enroll_endpoint.empty()) {
    ST_RETURN_IF_ERROR(BindEnrollment(socket_options, incarnation));
  }
  return OkStatus();
}

Status CoordinatorServer::BindEnrollment(const net::SocketOptions& site_socket_options,
                                         uint64_t incarnation) {
  net::SocketOptions options = site_socket_options;
  options.curve.zap_domain = net::kEnrollZapDomain;  // any CURVE key gets through, here only
  options.max_message_bytes = 4096;                  // an EnrollRequest is a few dozen bytes
  options.receive_high_water_mark = 100;
  Expected<std::unique_ptr<net::Socket>> router =
      net::Socket::Create(&context_, net::SocketType::kRouter, options);
  if (!router.ok()) return router.status();
  ST_RETURN_IF_ERROR(MonitorHandshakes(router->get(), "coordinator enrollment"));
  Expected<std::string> endpoint = (*router)->Bind(options_.enroll_endpoint);
  if (!endpoint.ok()) return endpoint.status().WithContext("enrollment");
  enroll_endpoint_ = *endpoint;
  proto::CodecLimits limits = options_.limits;
  limits.max_message_bytes = limits.max_body_bytes = 4096;
  enroll_ = std::make_unique<net::Channel>(std::move(*router), kCoordinatorSenderId, incarnation,
                                           &counters_, limits);
  loop_.Add(
      enroll_.get(), [this](net::Incoming in) { HandleEnroll(std::move(in)); },
      /*answer_refusals=*/true);
  ST_LOG(kInfo) << "enrollment: units without the site's key may ask to join at "
                << enroll_endpoint_ << " (an operator accepts them)";
  return OkStatus();
}

void CoordinatorServer::HandleEnroll(net::Incoming request) {
  const wire::Envelope& in = request.envelope;
  wire::Envelope reply;
  if (in.body_case() != wire::Envelope::kEnrollRequest) {
    counters_.CountRejected(proto::RejectReason::kWrongType);
    reply.mutable_rejected()->set_rejected_sequence(in.sequence());
    reply.mutable_rejected()->set_reason("the enrollment socket serves only enroll_request, not " +
                                         proto::BodyName(in));
  } else {
    const bool known = desk_.Knows(request.peer_key);
    Expected<EnrollState> state =
        desk_.OnRequest(request.peer_key, in.enroll_request().host_name(), request.peer_address,
                        in.sender_id(), Clock::now());
    auto* out = reply.mutable_enroll_reply();
    out->set_fingerprint(net::KeyFingerprint(request.peer_key));
    if (!state.ok()) {
      out->set_state(wire::EnrollReply::STATE_REFUSED);
      out->set_message(state.status().message());
    } else if (*state == EnrollState::kAccepted) {
      out->set_state(wire::EnrollReply::STATE_ACCEPTED);
      out->set_site_public_key(options_.curve->public_key_z85);
      out->set_site_secret_key(options_.curve->secret_key_z85);
      out->set_message("accepted by the site's operator");
      ST_LOG(kInfo) << "enrollment: unit " << out->fingerprint() << " (node " << in.sender_id()
                    << ") was handed the site's key";
    } else if (*state == EnrollState::kRefused) {
      out->set_state(wire::EnrollReply::STATE_REFUSED);
      out->set_message("refused by the site's operator");
    } else {
      out->set_state(wire::EnrollReply::STATE_PENDING);
      out->set_message("waiting for the site's operator to accept unit " + out->fingerprint());
      if (!known) {
        ST_LOG(kInfo) << "enrollment: unit " << out->fingerprint() << " ("
                      << in.enroll_request().host_name().substr(0, 64) << " at "
                      << request.peer_address << ", node " << in.sender_id()
                      << ") asks to join; accept it with `sandtable-coordinator enrollment "
                         "--accept "
                      << out->fingerprint() << "`";
      }
    }
  }
  Status sent = enroll_->Send(std::move(reply), request.routing_id);
  if (!sent.ok()) ST_LOG(kDebug) << "enrollment reply dropped: " << sent.ToString();
}

void CoordinatorServer::CountPublishFailure(const Status& status, const char* what) {
  if (status.ok()) return;
  ++publish_failures_;
  ST_LOG(kWarning) << what << " not published (" << publish_failures_
                   << " failed publishes so far; still serving): " << status.ToString();
}

bool CoordinatorServer::StillConnected(const std::string& routing_id) {
  // ROUTER_MANDATORY: a send to a routing id without a connection fails with NOT_FOUND. The
  // probe is a HeartbeatAck{known}, which a member takes as a sign of life.
  wire::Envelope probe;
  probe.mutable_heartbeat_ack()->set_known(true);
  probe.mutable_heartbeat_ack()->set_member_list_version(members_.version());
  const Status sent = requests_->Send(std::move(probe), routing_id);
  return sent.code() != StatusCode::kNotFound;
}

Status CoordinatorServer::Step(std::chrono::milliseconds max_wait) {
  ST_CHECK(requests_ != nullptr) << "CoordinatorServer::Step before a successful Start()";
  // Never sleep past the next expiry check: dead nodes must be found within a period.
  const auto wait = std::min(max_wait, options_.membership.heartbeat_period / 2);
  ST_RETURN_IF_ERROR(loop_.RunOnce(wait));
  ST_RETURN_IF_ERROR(events_->Drain());
  if (open_notice_) open_notice_->Tick(Clock::now());
  for (CoordinatorService* service : services_) {
    // A service's failure (e.g. a publish over the codec limit) is logged, not fatal.
    if (Status stepped = service->OnStep(*this); !stepped.ok()) {
      CountPublishFailure(stepped, "service step:");
    }
  }
  const Clock::time_point now = Clock::now();
  for (NodeId id : members_.ExpireSilent(now)) {
    ST_LOG(kInfo) << "node " << id << " declared dead (silent for more than "
                  << options_.membership.Timeout().count() << " ms)";
    requests_->ForgetSender(id);
  }
  if (members_.version() != published_version_ ||
      now - last_publish_ >= options_.republish_period) {
    CountPublishFailure(PublishMemberList(), "member list");
  }
  return OkStatus();
}

Status CoordinatorServer::Run(const std::atomic<bool>& stop) {
  while (!stop.load()) {
    ST_RETURN_IF_ERROR(Step(options_.step_period));
  }
  return OkStatus();
}

Status CoordinatorServer::Publish(wire::Envelope event) {
  return events_->Publish(std::move(event));
}

Status CoordinatorServer::Reply(wire::Envelope reply, const std::string& routing_id) {
  return requests_->Send(std::move(reply), routing_id);
}

Status CoordinatorServer::PublishMemberList() {
  wire::Envelope envelope;
  *envelope.mutable_member_list() = members_.ToWire();
  published_version_ = members_.version();
  last_publish_ = Clock::now();
  return events_->Publish(std::move(envelope));
}

void CoordinatorServer::HandleRequest(net::Incoming request) {
  const wire::Envelope& in = request.envelope;
  const NodeId sender = in.sender_id();
  const Clock::time_point now = Clock::now();
  members_.CountReceived(sender, request.routing_id, request.wire_bytes);
  for (CoordinatorService* service : services_) {
    if (service->Serves(in.body_case())) {
      service->OnRequest(std::move(request), *this);
      return;
    }
  }
  wire::Envelope reply;
  switch (in.body_case()) {
    case wire::Envelope::kHello: {
      if (Status valid = CheckHello(in.hello()); !valid.ok()) {
        counters_.ReclassifyAcceptedAsRejected(proto::RejectReason::kOverLimit);
        ST_LOG(kWarning) << "refused a Hello claiming node " << sender << ": " << valid.message();
        auto* rejected = reply.mutable_rejected();
        rejected->set_rejected_sequence(in.sequence());
        rejected->set_reason(valid.message());
        break;
      }
      const HelloOutcome outcome =
          members_.OnHello(sender, in.hello(), request.routing_id, now,
                           [this](const std::string& id) { return StillConnected(id); });
      auto* ack = reply.mutable_hello_ack();
      ack->set_accepted(Accepted(outcome));
      if (outcome == HelloOutcome::kSiteFull) {
        counters_.ReclassifyAcceptedAsRejected(proto::RejectReason::kOverLimit);
        ack->set_reason("site full: " + std::to_string(options_.membership.max_members) +
                        " members already (--max-members)");
        ST_LOG(kWarning) << "refused node " << sender << ": " << ack->reason();
      } else if (outcome == HelloOutcome::kIdInUse || outcome == HelloOutcome::kConnectionInUse) {
        counters_.ReclassifyAcceptedAsRejected(proto::RejectReason::kForged);
        ack->set_reason(outcome == HelloOutcome::kIdInUse
                            ? "node id " + std::to_string(sender) +
                                  " is held by another live connection (two nodes with one --id?)"
                            : "this connection already holds another node id (one per node)");
        ST_LOG(kWarning) << "refused a Hello claiming node " << sender << ": " << ack->reason();
      } else if (outcome == HelloOutcome::kJoined || outcome == HelloOutcome::kRestarted) {
        ST_LOG(kInfo) << "node " << sender
                      << (outcome == HelloOutcome::kJoined ? " joined" : " restarted")
                      << " (peer endpoint " << in.hello().endpoints().peer_router() << ")";
      }
      ack->set_heartbeat_period_s(
          std::chrono::duration<double>(options_.membership.heartbeat_period).count());
      ack->set_heartbeat_misses_allowed(static_cast<uint32_t>(options_.membership.misses_allowed));
      ack->set_member_list_version(members_.version());
      break;
    }
    case wire::Envelope::kHeartbeat: {
      auto* ack = reply.mutable_heartbeat_ack();
      ack->set_known(
          members_.OnHeartbeat(sender, in.heartbeat().incarnation(), request.routing_id, now));
      ack->set_member_list_version(members_.version());
      break;
    }
    case wire::Envelope::kGoodbye:
      switch (members_.OnGoodbye(sender, in.sender_incarnation(), request.routing_id)) {
        case GoodbyeOutcome::kLeft:
          ST_LOG(kInfo) << "node " << sender << " left: " << in.goodbye().reason().substr(0, 200);
          requests_->ForgetSender(sender);
          break;
        case GoodbyeOutcome::kForged:
          counters_.ReclassifyAcceptedAsRejected(proto::RejectReason::kForged);
          ST_LOG(kWarning) << "ignored a Goodbye for node " << sender
                           << " from another connection or incarnation than the member's";
          break;
        case GoodbyeOutcome::kUnknown:
          break;
      }
      return;  // no reply: the node is closing
    case wire::Envelope::kEnrollmentRequest: {
      if (!enroll_) {
        auto* out = reply.mutable_enrollment_reply();
        out->set_ok(false);
        out->set_message("enrollment is off on this coordinator (--enroll ENDPOINT turns it on)");
        break;
      }
      *reply.mutable_enrollment_reply() = desk_.Serve(in.enrollment_request(), now);
      if (!in.enrollment_request().accept().empty() || !in.enrollment_request().refuse().empty()) {
        ST_LOG(kInfo) << "enrollment: " << reply.enrollment_reply().message();
      }
      break;
    }
    case wire::Envelope::kUnitStatus:
      return;  // for the console (StatusService); without one, nobody reads it: no reply
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
