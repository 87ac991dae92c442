// ConsoleActions: the operator console's actions (POST /api/action, docs/console.md) turned into
// the coordinator's own requests and sent to its requests socket like any operator's tool would
// (one DEALER, with the site's CURVE key on a CURVE site), so the console holds no state and
// passes every check a request passes. One action at a time; each waits for its reply.
//
// Body (JSON): {"action": "test_pattern", "pattern": NAME, "node_id": N (absent: every unit)}
//   | {"action": "recalibrate", "node_id": N (absent: the whole site)}
//   | {"action": "timeline", "op": "play" | "pause" | "seek" | "rate", "value": X (seek: s,
//      rate: timeline s per s)}
//   | {"action": "annotations_clear"}
//   | {"action": "enrollment", "accept" | "refuse": FINGERPRINT}
// Answer: 200 {"ok": true, "message"} when the coordinator accepted it; 400 {"ok": false,
// "message"} for a body that is not one of these; 409 when the coordinator refused it (its
// reason); 504 when no reply came within the timeout.
#pragma once

#include <chrono>
#include <memory>
#include <mutex>
#include <optional>
#include <string>

#include "coordinator/status/http_status_server.h"
#include "net/curve.h"
#include "proto/envelope.pb.h"
#include "proto/message_counters.h"

namespace zmq {
class context_t;
}

namespace sandtable::net {
class Channel;
}

namespace sandtable::coordinator {

// The endpoint a client on this host connects to for a bound endpoint ("tcp://*:5555",
// "tcp://0.0.0.0:5555" -> "tcp://127.0.0.1:5555"; others unchanged).
std::string LocalEndpoint(const std::string& bound);

class ConsoleActions {
 public:
  ConsoleActions(std::string requests_endpoint, std::optional<net::CurveKeyPair> curve,
                 std::chrono::milliseconds timeout = std::chrono::milliseconds(3000));
  ~ConsoleActions();

  ActionResult Handle(const std::string& body);

 private:
  ActionResult Ask(const std::string& what, wire::Envelope request);
  Status Connect();

  std::string endpoint_;
  std::optional<net::CurveKeyPair> curve_;
  std::chrono::milliseconds timeout_;
  std::mutex mutex_;
  proto::MessageCounters counters_;  // the channel's (outlives it: declared before)
  std::unique_ptr<zmq::context_t> context_;
  std::unique_ptr<net::Channel> channel_;
};

}  // namespace sandtable::coordinator
