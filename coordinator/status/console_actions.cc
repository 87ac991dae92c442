#include "coordinator/status/console_actions.h"

#include <algorithm>
#include <cmath>

#include <nlohmann/json.hpp>
#include <zmq.hpp>

#include "common/base/ids.h"
#include "common/base/log.h"
#include "net/channel.h"
#include "net/server_loop.h"
#include "net/socket.h"
#include "proto/envelope.pb.h"

namespace sandtable::coordinator {
namespace {

using nlohmann::json;
using Clock = std::chrono::steady_clock;

ActionResult Answer(int http_status, bool ok, const std::string& message) {
  return {http_status, json{{"ok", ok}, {"message", message}}.dump()};
}

ActionResult BadAction(const std::string& message) { return Answer(400, false, message); }

// The request of a timeline action, or the reason it is not one.
Expected<wire::Envelope> TimelineRequest(const json& body) {
  const std::string op = body.value("op", std::string());
  wire::Envelope out;
  if (op == "play") {
    out.mutable_play();
  } else if (op == "pause") {
    out.mutable_pause();
  } else if (op == "seek" || op == "rate") {
    if (!body.contains("value") || !body["value"].is_number()) {
      return InvalidArgumentError("timeline " + op + " needs a number \"value\"");
    }
    const double value = body["value"].get<double>();
    if (!std::isfinite(value)) return InvalidArgumentError("timeline value is not finite");
    if (op == "seek") {
      out.mutable_seek()->set_position_s(value);
    } else {
      out.mutable_rate()->set_rate(value);
    }
  } else {
    return InvalidArgumentError("timeline \"op\" is play, pause, seek or rate");
  }
  return out;
}

// The unit a body's "node_id" names: nullopt when absent (every unit), or why it names none.
Expected<std::optional<NodeId>> UnitOf(const json& body) {
  if (!body.contains("node_id") || body["node_id"].is_null()) return std::optional<NodeId>();
  if (!body["node_id"].is_number_unsigned() ||
      !IsValidNodeId(static_cast<NodeId>(
          std::min<uint64_t>(body["node_id"].get<uint64_t>(), kInvalidNodeId)))) {
    return InvalidArgumentError("\"node_id\" is not a unit's id");
  }
  return std::optional<NodeId>(body["node_id"].get<uint32_t>());
}

// The request an action's body names, or why it names none.
Expected<wire::Envelope> RequestFor(const json& body) {
  const std::string action = body.value("action", std::string());
  wire::Envelope out;
  if (action == "test_pattern" || action == "recalibrate") {
    Expected<std::optional<NodeId>> unit = UnitOf(body);
    if (!unit.ok()) return unit.status();
    if (action == "recalibrate") {
      auto* request = out.mutable_recalibrate_request();
      request->set_all_units(!unit->has_value());
      request->set_node_id(unit->value_or(0));
      return out;
    }
    if (!body.contains("pattern") || !body["pattern"].is_string()) {
      return InvalidArgumentError("test_pattern needs a \"pattern\" name");
    }
    auto* request = out.mutable_test_pattern_request();
    request->set_pattern(body["pattern"].get<std::string>());
    request->set_all_nodes(!unit->has_value());
    request->set_node_id(unit->value_or(0));
    return out;
  }
  if (action == "timeline") return TimelineRequest(body);
  if (action == "annotations_clear") {
    out.mutable_annotation_request()->mutable_clear();
    return out;
  }
  if (action == "enrollment") {
    const std::string accept = body.value("accept", std::string());
    const std::string refuse = body.value("refuse", std::string());
    if (accept.empty() == refuse.empty()) {
      return InvalidArgumentError("enrollment needs one of \"accept\" or \"refuse\"");
    }
    out.mutable_enrollment_request()->set_accept(accept);
    out.mutable_enrollment_request()->set_refuse(refuse);
    return out;
  }
  return InvalidArgumentError(
      "\"action\" is test_pattern, recalibrate, timeline, annotations_clear or enrollment");
}

// The answer a reply carries, or nullopt for a reply to something else.
std::optional<ActionResult> FromReply(const wire::Envelope& reply) {
  auto decided = [](bool ok, const std::string& reason, const std::string& done) {
    return ok ? Answer(200, true, done) : Answer(409, false, reason);
  };
  switch (reply.body_case()) {
    case wire::Envelope::kTestPatternReply:
      return decided(reply.test_pattern_reply().accepted(), reply.test_pattern_reply().reason(),
                     "test pattern set");
    case wire::Envelope::kRecalibrateReply:
      return decided(
          reply.recalibrate_reply().accepted(), reply.recalibrate_reply().reason(),
          "recalibration asked (ask " + std::to_string(reply.recalibrate_reply().ask_id()) + ")");
    case wire::Envelope::kTimelineReply:
      return decided(reply.timeline_reply().accepted(), reply.timeline_reply().reason(),
                     "timeline changed");
    case wire::Envelope::kAnnotationAck:
      return decided(reply.annotation_ack().accepted(), reply.annotation_ack().reason(),
                     "annotations cleared");
    case wire::Envelope::kEnrollmentReply:
      return decided(reply.enrollment_reply().ok(), reply.enrollment_reply().message(),
                     reply.enrollment_reply().message());
    case wire::Envelope::kRejected:
      return Answer(409, false, "refused: " + reply.rejected().reason());
    default:
      return std::nullopt;
  }
}

}  // namespace

std::string LocalEndpoint(const std::string& bound) {
  for (const std::string any : {"tcp://*:", "tcp://0.0.0.0:"}) {
    if (bound.rfind(any, 0) == 0) return "tcp://127.0.0.1:" + bound.substr(any.size());
  }
  return bound;
}

ConsoleActions::ConsoleActions(std::string requests_endpoint,
                               std::optional<net::CurveKeyPair> curve,
                               std::chrono::milliseconds timeout)
    : endpoint_(LocalEndpoint(requests_endpoint)), curve_(std::move(curve)), timeout_(timeout) {}

ConsoleActions::~ConsoleActions() {
  channel_.reset();
  context_.reset();
}

Status ConsoleActions::Connect() {
  if (channel_) return OkStatus();
  if (!context_) context_ = std::make_unique<zmq::context_t>();
  net::SocketOptions options;
  if (curve_) options.curve = net::ClientCurve(*curve_);
  Expected<std::unique_ptr<net::Socket>> dealer =
      net::Socket::Create(context_.get(), net::SocketType::kDealer, options);
  if (!dealer.ok()) return dealer.status();
  ST_RETURN_IF_ERROR((*dealer)->Connect(endpoint_));
  channel_ = std::make_unique<net::Channel>(std::move(*dealer), kConsoleSenderId,
                                            net::NewIncarnation(), &counters_);
  return OkStatus();
}

ActionResult ConsoleActions::Handle(const std::string& body) {
  const json parsed = json::parse(body, nullptr, false);
  if (parsed.is_discarded() || !parsed.is_object()) {
    return BadAction("the body is not a JSON object");
  }
  Expected<wire::Envelope> request = RequestFor(parsed);
  if (!request.ok()) return BadAction(request.status().message());
  return Ask(parsed.value("action", std::string()), std::move(*request));
}

ActionResult ConsoleActions::Ask(const std::string& what, wire::Envelope request) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (Status connected = Connect(); !connected.ok()) {
    return Answer(503, false,
                  "cannot reach the coordinator's requests socket: " + connected.message());
  }
  if (Status sent = channel_->Send(std::move(request)); !sent.ok()) {
    return Answer(503, false, what + ": not sent: " + sent.message());
  }
  const Clock::time_point deadline = Clock::now() + timeout_;
  while (Clock::now() < deadline) {
    std::vector<bool> readable;
    if (!net::Socket::Poll({&channel_->socket()}, std::chrono::milliseconds(20), &readable).ok()) {
      break;
    }
    if (!readable[0]) continue;
    Expected<std::optional<net::Incoming>> in = channel_->TryReceive();
    if (!in.ok() || !in->has_value()) continue;
    if (std::optional<ActionResult> answer = FromReply((*in)->envelope)) {
      ST_LOG(kInfo) << "console: " << what << ": " << answer->json;
      return *answer;
    }
  }
  // A reply that comes late would answer the next action: start over on a new connection.
  channel_.reset();
  return Answer(
      504, false,
      what + ": no answer from the coordinator in " + std::to_string(timeout_.count()) + " ms");
}

}  // namespace sandtable::coordinator
