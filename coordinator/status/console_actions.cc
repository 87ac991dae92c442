#include "coordinator/status/console_actions.h"

#include <algorithm>
#include <cmath>

#include <nlohmann/json.hpp>
#include <zmq.hpp>

#include "cluster/annotation_state.h"
#include "common/base/ids.h"
#include "common/base/log.h"
#include "coordinator/annotations/session_file.h"
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
      "\"action\" is test_pattern, recalibrate, timeline, annotations_clear, enrollment, "
      "annotation_stroke, annotation_erase, annotations_export or annotations_import");
}

// Whole xyz triples of finite numbers from [[x, y, z], ...]; at most `max_points`.
Expected<std::vector<float>> Points(const json& value, const std::string& field,
                                    size_t max_points) {
  if (!value.is_array() || value.empty() || value.size() > max_points) {
    return InvalidArgumentError("\"" + field + "\" must hold 1.." + std::to_string(max_points) +
                                " points [x, y, z] (metres, table frame)");
  }
  std::vector<float> out;
  for (const json& p : value) {
    if (!p.is_array() || p.size() != 3) {
      return InvalidArgumentError("\"" + field + "\": each point is [x, y, z]");
    }
    for (const json& v : p) {
      if (!v.is_number() || !std::isfinite(v.get<double>()) || std::abs(v.get<double>()) > 100) {
        return InvalidArgumentError("\"" + field + "\": coordinates are numbers within 100 m");
      }
      out.push_back(v.get<float>());
    }
  }
  return out;
}

// The events that draw the strokes of `state` again (sequences 1, 2, ...).
std::vector<wire::AnnotationEvent> StrokeEvents(const cluster::AnnotationState& state) {
  std::vector<wire::AnnotationEvent> events;
  auto add = [&]() -> wire::AnnotationEvent& {
    events.emplace_back();
    events.back().set_event_sequence(events.size());
    return events.back();
  };
  for (const auto& [id, stroke] : state.strokes()) {
    wire::StrokeBegin* b = add().mutable_stroke_begin();
    b->set_stroke_id(id);
    b->set_color_r(stroke.color_rgb.x());
    b->set_color_g(stroke.color_rgb.y());
    b->set_color_b(stroke.color_rgb.z());
    b->set_width_m(stroke.width_m);
    if (!stroke.points_in_table_m.empty()) {
      wire::StrokePoints* p = add().mutable_stroke_points();
      p->set_stroke_id(id);
      for (const Eigen::Vector3f& v : stroke.points_in_table_m) {
        p->add_points_in_table_m(v.x());
        p->add_points_in_table_m(v.y());
        p->add_points_in_table_m(v.z());
      }
    }
    if (stroke.ended) {
      wire::StrokeEnd* e = add().mutable_stroke_end();
      e->set_stroke_id(id);
      e->set_point_count(static_cast<uint32_t>(stroke.points_in_table_m.size()));
    }
  }
  return events;
}

std::string Strokes(size_t n) { return std::to_string(n) + (n == 1 ? " stroke" : " strokes"); }

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
  const std::string action = parsed.value("action", std::string());
  if (action.rfind("annotation_", 0) == 0 || action.rfind("annotations_", 0) == 0) {
    if (action != "annotations_clear") return Annotation(action, parsed);
  }
  Expected<wire::Envelope> request = RequestFor(parsed);
  if (!request.ok()) return BadAction(request.status().message());
  return Ask(action, std::move(*request));
}

ActionResult ConsoleActions::FromStatus(const std::string& what, const Status& status) const {
  const int code = timed_out_                                      ? 504
                   : status.code() == StatusCode::kUnavailable     ? 503
                   : status.code() == StatusCode::kInvalidArgument ? 409
                                                                   : 500;
  return Answer(code, false, what + ": " + status.message());
}

Expected<wire::Envelope> ConsoleActions::Exchange(
    wire::Envelope request, const std::function<bool(const wire::Envelope&)>& wanted) {
  timed_out_ = false;
  if (Status connected = Connect(); !connected.ok()) {
    return UnavailableError("cannot reach the coordinator's requests socket: " +
                            connected.message());
  }
  if (Status sent = channel_->Send(std::move(request)); !sent.ok()) {
    return UnavailableError("not sent: " + sent.message());
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
    const wire::Envelope& reply = (*in)->envelope;
    if (reply.has_rejected() || wanted(reply)) return reply;
  }
  // A reply that comes late would answer the next action: start over on a new connection.
  channel_.reset();
  timed_out_ = true;
  return UnavailableError("no answer from the coordinator in " + std::to_string(timeout_.count()) +
                          " ms");
}

ActionResult ConsoleActions::Ask(const std::string& what, wire::Envelope request) {
  std::lock_guard<std::mutex> lock(mutex_);
  Expected<wire::Envelope> reply = Exchange(
      std::move(request), [](const wire::Envelope& e) { return FromReply(e).has_value(); });
  if (!reply.ok()) return FromStatus(what, reply.status());
  ActionResult answer = *FromReply(*reply);
  ST_LOG(kInfo) << "console: " << what << ": " << answer.json;
  return answer;
}

Status ConsoleActions::Submit(wire::AnnotationEvent event) {
  wire::Envelope request;
  *request.mutable_annotation_request() = std::move(event);
  Expected<wire::Envelope> reply =
      Exchange(std::move(request), [](const wire::Envelope& e) { return e.has_annotation_ack(); });
  if (!reply.ok()) return reply.status();
  if (reply->has_rejected()) return InvalidArgumentError("refused: " + reply->rejected().reason());
  if (!reply->annotation_ack().accepted()) {
    return InvalidArgumentError(reply->annotation_ack().reason());
  }
  return OkStatus();
}

Expected<StrokeId> ConsoleActions::DrawStroke(const wire::StrokeBegin& style,
                                              const std::vector<float>& points_in_table_m) {
  // n: microseconds of the system clock, above the last one: fresh across restarts.
  const auto now_us = std::chrono::duration_cast<std::chrono::microseconds>(
                          std::chrono::system_clock::now().time_since_epoch())
                          .count();
  next_stroke_number_ = std::max<StrokeId>(next_stroke_number_ + 1,
                                           static_cast<StrokeId>(std::max<int64_t>(now_us, 1)));
  const StrokeId id = kConsoleStrokeIdBit | (next_stroke_number_ & (kConsoleStrokeIdBit - 1));
  wire::AnnotationEvent begin;
  *begin.mutable_stroke_begin() = style;
  begin.mutable_stroke_begin()->set_stroke_id(id);
  ST_RETURN_IF_ERROR(Submit(std::move(begin)));
  const size_t count = points_in_table_m.size() / 3;
  for (size_t first = 0; first < count; first += cluster::kMaxPointsPerMessage) {
    const size_t n = std::min<size_t>(cluster::kMaxPointsPerMessage, count - first);
    wire::AnnotationEvent points;
    wire::StrokePoints* p = points.mutable_stroke_points();
    p->set_stroke_id(id);
    p->set_first_point_index(static_cast<uint32_t>(first));
    p->mutable_points_in_table_m()->Assign(points_in_table_m.begin() + 3 * first,
                                           points_in_table_m.begin() + 3 * (first + n));
    ST_RETURN_IF_ERROR(Submit(std::move(points)));
  }
  wire::AnnotationEvent end;
  end.mutable_stroke_end()->set_stroke_id(id);
  end.mutable_stroke_end()->set_point_count(static_cast<uint32_t>(count));
  ST_RETURN_IF_ERROR(Submit(std::move(end)));
  return id;
}

ActionResult ConsoleActions::Annotation(const std::string& action, const json& body) {
  if (action == "annotation_stroke") {
    const json colour = body.value("color_rgb", json());
    if (!colour.is_array() || colour.size() != 3) {
      return BadAction("annotation_stroke needs \"color_rgb\": [r, g, b], each 0..1");
    }
    float rgb[3];
    for (int i = 0; i < 3; ++i) {
      if (!colour[i].is_number() || !(colour[i].get<double>() >= 0.0) ||
          !(colour[i].get<double>() <= 1.0)) {
        return BadAction("annotation_stroke: \"color_rgb\" components are numbers 0..1");
      }
      rgb[i] = colour[i].get<float>();
    }
    const json width = body.value("width_m", json());
    if (!width.is_number() || !(width.get<double>() > 0.0) ||
        !(width.get<double>() <= cluster::kMaxStrokeWidth_m)) {
      return BadAction("annotation_stroke needs \"width_m\" in (0, " +
                       std::to_string(cluster::kMaxStrokeWidth_m) + "] m");
    }
    constexpr size_t kMaxConsoleStrokePoints = 10000;
    Expected<std::vector<float>> points = Points(body.value("points_in_table_m", json()),
                                                 "points_in_table_m", kMaxConsoleStrokePoints);
    if (!points.ok()) return BadAction("annotation_stroke: " + points.status().message());
    wire::StrokeBegin style;
    style.set_color_r(rgb[0]);
    style.set_color_g(rgb[1]);
    style.set_color_b(rgb[2]);
    style.set_width_m(width.get<float>());
    std::lock_guard<std::mutex> lock(mutex_);
    Expected<StrokeId> id = DrawStroke(style, *points);
    if (!id.ok()) return FromStatus("annotation_stroke", id.status());
    ST_LOG(kInfo) << "console: stroke " << *id << " drawn, " << points->size() / 3 << " points";
    return Answer(200, true, "stroke drawn (" + std::to_string(points->size() / 3) + " points)");
  }
  if (action == "annotation_erase") {
    Expected<std::vector<float>> centre =
        Points(json::array({body.value("center_in_table_m", json())}), "center_in_table_m", 1);
    if (!centre.ok()) return BadAction("annotation_erase: " + centre.status().message());
    const json radius = body.value("radius_m", json());
    if (!radius.is_number() || !(radius.get<double>() > 0.0) ||
        !(radius.get<double>() <= cluster::kMaxEraseRadius_m)) {
      return BadAction("annotation_erase needs \"radius_m\" in (0, " +
                       std::to_string(cluster::kMaxEraseRadius_m) + "] m");
    }
    wire::AnnotationEvent erase;
    wire::SpotErase* e = erase.mutable_spot_erase();
    e->mutable_center_in_table_m()->set_x((*centre)[0]);
    e->mutable_center_in_table_m()->set_y((*centre)[1]);
    e->mutable_center_in_table_m()->set_z((*centre)[2]);
    e->set_radius_m(radius.get<float>());
    std::lock_guard<std::mutex> lock(mutex_);
    if (Status s = Submit(std::move(erase)); !s.ok()) return FromStatus("annotation_erase", s);
    return Answer(200, true, "erased within " + radius.dump() + " m");
  }
  if (action == "annotations_export") return Export();
  if (action == "annotations_import") {
    if (!body.contains("session") || !body["session"].is_string()) {
      return BadAction("annotations_import needs \"session\": the session file's text");
    }
    return Import(body["session"].get<std::string>());
  }
  return BadAction("unknown annotation action \"" + action + "\"");
}

ActionResult ConsoleActions::Export() {
  std::lock_guard<std::mutex> lock(mutex_);
  // A snapshot of every stroke (catch_up_request 0), in chunks when it is large.
  std::string chunks;
  wire::Snapshot snapshot;
  wire::CatchUpRequest ask;
  for (int page = 0;; ++page) {
    constexpr int kMaxPages = 1024;
    if (page == kMaxPages)
      return Answer(500, false, "annotations_export: the snapshot never ended");
    wire::Envelope request;
    *request.mutable_catch_up_request() = ask;
    Expected<wire::Envelope> reply = Exchange(
        std::move(request), [](const wire::Envelope& e) { return e.has_catch_up_reply(); });
    if (!reply.ok()) return FromStatus("annotations_export", reply.status());
    if (reply->has_rejected()) {
      return Answer(409, false, "annotations_export: refused: " + reply->rejected().reason());
    }
    const wire::CatchUpReply& r = reply->catch_up_reply();
    if (r.snapshot_expired()) {
      return Answer(409, false, "annotations_export: the snapshot expired; export again");
    }
    if (!r.snapshot_sent()) {
      return Answer(500, false, "annotations_export: the coordinator sent events, not a snapshot");
    }
    if (r.snapshot_total_bytes() == 0) {  // the whole snapshot in one reply
      snapshot = r.snapshot();
      break;
    }
    chunks += r.snapshot_chunk();
    if (chunks.size() >= r.snapshot_total_bytes()) {
      if (!snapshot.ParseFromString(chunks)) {
        return Answer(500, false, "annotations_export: the snapshot's chunks do not parse");
      }
      break;
    }
    ask.set_snapshot_sequence(r.snapshot_sequence());
    ask.set_snapshot_offset_bytes(chunks.size());
  }
  Expected<cluster::AnnotationState> state = cluster::AnnotationState::FromSnapshot(snapshot);
  if (!state.ok()) return FromStatus("annotations_export", state.status());
  const std::string text = SessionText(StrokeEvents(*state));
  const size_t strokes = state->strokes().size();
  return {200, json{{"ok", true},
                    {"message", Strokes(strokes) + " exported"},
                    {"strokes", strokes},
                    {"session", text}}
                   .dump()};
}

ActionResult ConsoleActions::Import(const std::string& session) {
  // The whole file is read and replayed here before anything on the site changes.
  Expected<std::vector<wire::AnnotationEvent>> events = ParseSession(session, "the session");
  if (!events.ok()) return BadAction("annotations_import: " + events.status().message());
  cluster::AnnotationState state;
  SequenceNumber sequence = 0;
  for (wire::AnnotationEvent& event : *events) {
    event.set_event_sequence(++sequence);
    if (Status s = state.Check(event); !s.ok()) {
      return BadAction("annotations_import: event " + std::to_string(sequence) + ": " +
                       s.message());
    }
    state.Apply(event);
  }
  std::lock_guard<std::mutex> lock(mutex_);
  wire::AnnotationEvent clear;
  clear.mutable_clear();
  if (Status s = Submit(std::move(clear)); !s.ok()) return FromStatus("annotations_import", s);
  size_t drawn = 0;
  for (const auto& [id, stroke] : state.strokes()) {
    wire::StrokeBegin style;
    style.set_color_r(stroke.color_rgb.x());
    style.set_color_g(stroke.color_rgb.y());
    style.set_color_b(stroke.color_rgb.z());
    style.set_width_m(stroke.width_m);
    std::vector<float> points;
    for (const Eigen::Vector3f& v : stroke.points_in_table_m) {
      points.insert(points.end(), {v.x(), v.y(), v.z()});
    }
    Expected<StrokeId> drawn_id = DrawStroke(style, points);
    if (!drawn_id.ok()) {
      return FromStatus("annotations_import: stroke " + std::to_string(drawn + 1) + " of " +
                            std::to_string(state.strokes().size()),
                        drawn_id.status());
    }
    ++drawn;
  }
  ST_LOG(kInfo) << "console: imported a session: " << drawn << " strokes";
  return Answer(200, true, Strokes(drawn) + " imported");
}

}  // namespace sandtable::coordinator
