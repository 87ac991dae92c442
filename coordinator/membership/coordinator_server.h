// CoordinatorServer: the coordinator's sockets and its membership/time service.
//
// Binds a ROUTER for requests (Hello -> HelloAck, Heartbeat -> HeartbeatAck, Goodbye,
// TimeRequest -> TimeReply) and an event publisher (MemberList on every change and every
// republish_period for late subscribers; later tracker, cursor, annotation and timeline
// events through Publish()). Any other request is answered with Rejected and counted as
// wrong_type, unless a CoordinatorService added with AddService() serves it (annotations,
// tracker calibration, timeline); invalid messages are counted and answered with Rejected
// (net/server_loop.h).
//
// With an enrollment endpoint (and CURVE) it binds a third ROUTER where any CURVE key gets
// through and only EnrollRequest is served: a unit without the site's key asks there, an
// operator decides with EnrollmentRequest on the requests socket (only the site's key reaches
// it), and an accepted unit is handed the site's key pair
// (coordinator/membership/enrollment_desk.h).
//
// Hostile peers (docs/reliability.md): a Hello whose fields exceed the limits of
// membership_table.h is answered with Rejected and counted over_limit; a full site or an id
// bound to another live connection gets HelloAck{accepted: false} (counted over_limit /
// forged); a Goodbye or Heartbeat for an id from another connection or incarnation changes
// nothing (counted forged). Events leave through a net::EventPublisher (a ROUTER that
// subscribers' DEALERs connect to), which a subscription flood cannot grow or stall. A publish that
// fails (a message over the codec limit, a full queue) is logged and counted (publish_failures()),
// and the server keeps serving: Step() fails only when a socket itself fails. Single-threaded: call
// Step() in a loop (or Run()). Never throws; failures of sockets come back as Status.
#pragma once

#include <atomic>
#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "common/base/ids.h"
#include "coordinator/membership/enrollment_desk.h"
#include "coordinator/membership/membership_table.h"
#include "net/channel.h"
#include "net/curve.h"
#include "net/endpoint.h"
#include "net/event_publisher.h"
#include "net/handshake_monitor.h"
#include "net/server_loop.h"

namespace sandtable::coordinator {

class CoordinatorServer;

// A concern of the coordinator that serves some request bodies and/or does periodic work
// (tracker polling, publishing). Called on the server's thread only.
class CoordinatorService {
 public:
  virtual ~CoordinatorService() = default;
  // True if this service handles requests with this body.
  virtual bool Serves(wire::Envelope::BodyCase body) const = 0;
  // One request it serves; reply now with server.Reply(), or later (e.g. after a commit).
  virtual void OnRequest(net::Incoming request, CoordinatorServer& server) = 0;
  // After every drain of the request socket (at least every step_period).
  virtual Status OnStep(CoordinatorServer& server) = 0;
};

struct CoordinatorOptions {
  std::string request_endpoint = "tcp://127.0.0.1:*";  // ROUTER
  std::string event_endpoint = "tcp://127.0.0.1:*";    // events (ROUTER)
  MembershipOptions membership;
  std::chrono::milliseconds republish_period{1000};
  // Longest wait for requests in Run(): services polling a tracker at 100 Hz need <= 5 ms.
  std::chrono::milliseconds step_period{50};
  std::optional<net::CurveKeyPair> curve;  // site keys: require CURVE on both sockets
  // Units without the site's key ask to be accepted here (empty: no enrollment; needs curve).
  std::string enroll_endpoint;
  EnrollmentDeskOptions enrollment;
  // Without CURVE the sockets stay on loopback unless this is set (an open site: anyone on the
  // network may join it, read its events and write its annotations; logged every minute).
  bool insecure = false;
  proto::CodecLimits limits;
  net::EventPublisherLimits events;  // what the event socket accepts from subscribers

  Status Check() const;
};

class CoordinatorServer {
 public:
  explicit CoordinatorServer(CoordinatorOptions options);
  ~CoordinatorServer();

  // Binds both sockets (and starts the ZAP handler with CURVE).
  Status Start();
  const std::string& request_endpoint() const { return request_endpoint_; }
  const std::string& event_endpoint() const { return event_endpoint_; }
  const std::string& enroll_endpoint() const { return enroll_endpoint_; }  // empty: none

  // Serves what is waiting (at most `max_wait` of waiting), expires silent nodes, publishes.
  Status Step(std::chrono::milliseconds max_wait);
  // Steps until `stop` becomes true.
  Status Run(const std::atomic<bool>& stop);

  // Publishes an event (body set by the caller) to every subscriber.
  Status Publish(wire::Envelope event);
  // Sends a reply (body set by the caller) to the requester with this routing id.
  Status Reply(wire::Envelope reply, const std::string& routing_id);

  // Adds a service (not owned; must outlive the server). Services are asked in order.
  void AddService(CoordinatorService* service) { services_.push_back(service); }

  const MembershipTable& members() const { return members_; }
  EnrollmentDesk& enrollment() { return desk_; }
  const proto::MessageCounters& counters() const { return counters_; }
  // Publishes that failed (logged; the server kept serving).
  uint64_t publish_failures() const { return publish_failures_; }
  const net::EventPublisherStats& event_stats() const { return events_->stats(); }
  size_t event_subscribers() const { return events_ ? events_->subscribers() : 0; }
  // Senders whose sequence state the request socket keeps (bounded).
  size_t tracked_senders() const { return requests_ ? requests_->tracked_senders() : 0; }

 private:
  void HandleRequest(net::Incoming request);
  void HandleEnroll(net::Incoming request);
  Status BindEnrollment(const net::SocketOptions& site_socket_options, uint64_t incarnation);
  Status PublishMemberList();
  void CountPublishFailure(const Status& status, const char* what);
  // True when the connection with this routing id is still up (a probe send).
  bool StillConnected(const std::string& routing_id);
  // With CURVE, logs and counts refused handshakes on `socket` (net/handshake_monitor.h).
  Status MonitorHandshakes(net::Socket* socket, const char* name);

  CoordinatorOptions options_;
  zmq::context_t context_;
  std::unique_ptr<net::ZapHandler> zap_;
  std::vector<std::unique_ptr<net::HandshakeMonitor>> handshake_monitors_;
  proto::MessageCounters counters_;
  std::unique_ptr<net::Channel> requests_;
  std::unique_ptr<net::EventPublisher> events_;
  std::unique_ptr<net::Channel> enroll_;
  net::ServerLoop loop_;
  std::string request_endpoint_, event_endpoint_, enroll_endpoint_;
  EnrollmentDesk desk_;
  MembershipTable members_;
  std::vector<CoordinatorService*> services_;
  std::unique_ptr<net::InsecureNotice> open_notice_;  // an open site's repeated warning
  uint64_t publish_failures_ = 0;
  uint64_t published_version_ = ~uint64_t{0};
  Clock::time_point last_publish_{};
};

}  // namespace sandtable::coordinator
