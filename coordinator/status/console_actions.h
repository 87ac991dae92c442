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
//   | {"action": "annotation_stroke", "color_rgb": [r, g, b] (0..1), "width_m": W,
//      "points_in_table_m": [[x, y, z], ...]}: one stroke (begin, points, end; the console
//      picks its id: kConsoleStrokeIdBit | n)
//   | {"action": "annotation_erase", "center_in_table_m": [x, y, z], "radius_m": R}
//   | {"action": "annotations_export"}: the strokes held now as a session file
//      (session_file.h), in the answer's "session"; "strokes" their count
//   | {"action": "annotations_import", "session": TEXT}: the strokes the session leaves
//      replace every stroke held (a clear, then each stroke under a new id); refused whole,
//      before anything changes, when the file does not read
// Answer: 200 {"ok": true, "message"} when the coordinator accepted it; 400 {"ok": false,
// "message"} for a body that is not one of these; 409 when the coordinator refused it (its
// reason); 504 when no reply came within the timeout.
#pragma once

#include <chrono>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json_fwd.hpp>

#include "common/base/ids.h"
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

// Strokes drawn from the console: kConsoleStrokeIdBit | n (below the wand's kWandStrokeIdBit).
constexpr StrokeId kConsoleStrokeIdBit = StrokeId{1} << 61;

class ConsoleActions {
 public:
  ConsoleActions(std::string requests_endpoint, std::optional<net::CurveKeyPair> curve,
                 std::chrono::milliseconds timeout = std::chrono::milliseconds(3000));
  ~ConsoleActions();

  ActionResult Handle(const std::string& body);

 private:
  ActionResult Ask(const std::string& what, wire::Envelope request);
  // One request and the first reply `wanted` takes (Rejected too); UNAVAILABLE when the
  // coordinator cannot be reached, DEADLINE_EXCEEDED after the timeout. Holds mutex_.
  Expected<wire::Envelope> Exchange(wire::Envelope request,
                                    const std::function<bool(const wire::Envelope&)>& wanted);
  // An annotation request and its ack: OK, or why it was refused / not answered.
  Status Submit(wire::AnnotationEvent event);
  // Draws one stroke (begin, points, end) under a fresh console id; its id.
  Expected<StrokeId> DrawStroke(const wire::StrokeBegin& style,
                                const std::vector<float>& points_in_table_m);
  ActionResult Annotation(const std::string& action, const nlohmann::json& body);
  ActionResult Export();
  ActionResult Import(const std::string& session);
  // The answer for a failed exchange or refused request: 504 when the last exchange timed
  // out, 503 when the coordinator was not reachable, 409 when it refused.
  ActionResult FromStatus(const std::string& what, const Status& status) const;
  StrokeId next_stroke_number_ = 0;
  bool timed_out_ = false;
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
