#include "coordinator/status/status_service.h"

#include <nlohmann/json.hpp>

#include "common/base/check.h"
#include "common/base/log.h"
#include "proto/envelope_stamper.h"

namespace sandtable::coordinator {

StatusService::StatusService(HttpStatusServer* http, StatusSources sources,
                             std::chrono::milliseconds refresh_period)
    : http_(http), sources_(sources), refresh_period_(refresh_period) {
  ST_CHECK(http_ != nullptr) << "StatusService needs a started HttpStatusServer";
}

void StatusService::OnRequest(net::Incoming request, CoordinatorServer& server) {
  const wire::Envelope& in = request.envelope;
  Status kept = board_.Update(in.sender_id(), request.routing_id, in.unit_status(),
                              server.members(), std::chrono::steady_clock::now());
  if (!kept.ok()) ST_LOG(kDebug) << "unit status refused: " << kept.message();
}

Status StatusService::OnStep(CoordinatorServer& server) {
  const auto now = std::chrono::steady_clock::now();
  board_.Sweep(server.members(), now);
  if (last_ != std::chrono::steady_clock::time_point{} && now - last_ < refresh_period_) {
    return OkStatus();
  }
  last_ = now;
  http_->Publish(BuildJson(server));
  return OkStatus();
}

std::string StatusService::BuildJson(CoordinatorServer& server) {
  using nlohmann::json;
  const int64_t now_ns = proto::SteadyNowNs();
  const auto clock_now = std::chrono::steady_clock::now();
  json doc;
  doc["time_ns"] = now_ns;
  const wire::MemberList list = server.members().ToWire();
  doc["member_list_version"] = list.version();
  json members = json::array();
  for (const wire::Member& m : list.members()) {
    members.push_back({{"node_id", m.node_id()},
                       {"incarnation", m.incarnation()},
                       {"joined_time_ns", m.joined_time_ns()},
                       {"peer_router", m.endpoints().peer_router()},
                       {"capabilities",
                        {{"projector_width_px", m.capabilities().projector_width_px()},
                         {"projector_height_px", m.capabilities().projector_height_px()},
                         {"camera_width_px", m.capabilities().camera_width_px()},
                         {"camera_height_px", m.capabilities().camera_height_px()},
                         {"projector_output", m.capabilities().projector_output()},
                         {"camera_input", m.capabilities().camera_input()}}},
                       {"state", board_.ConsoleState(m.node_id(), server.members(), clock_now)}});
  }
  doc["members"] = std::move(members);
  doc["units"] = board_.Json(server.members(), clock_now);
  doc["unit_status_refused"] = board_.refused();
  if (sources_.patterns != nullptr) {
    const wire::TestPatternState& p = sources_.patterns->state();
    json nodes = json::object();
    for (const auto& [id, pattern] : p.node_patterns()) nodes[std::to_string(id)] = pattern;
    doc["test_patterns"] = {
        {"site", p.site_pattern()}, {"nodes", nodes}, {"change_count", p.change_count()}};
  } else {
    doc["test_patterns"] = nullptr;
  }
  if (sources_.recalibration != nullptr) {
    const wire::RecalibrateAsk& a = sources_.recalibration->ask();
    doc["recalibration"] = {
        {"ask_id", a.ask_id()},
        {"all_units", a.all_units()},
        {"node_id", a.all_units() || a.ask_id() == 0 ? json(nullptr) : json(a.node_id())}};
  } else {
    doc["recalibration"] = nullptr;
  }
  json enrolling = json::array();
  for (const EnrollingUnit& u : server.enrollment().Units(clock_now)) {
    enrolling.push_back(
        {{"fingerprint", u.fingerprint},
         {"host_name", u.host_name},
         {"address", u.address},
         {"node_id", u.node_id},
         {"waiting_s", std::chrono::duration<double>(clock_now - u.first_asked).count()},
         {"state", EnrollStateName(u.state)}});
  }
  doc["enrollment"] = {{"on", !server.enroll_endpoint().empty()}, {"units", enrolling}};

  const proto::MessageCounters& c = server.counters();
  json rejected = json::object();
  for (int r = 0; r < static_cast<int>(proto::RejectReason::kCount); ++r) {
    const auto reason = static_cast<proto::RejectReason>(r);
    rejected[std::string(proto::RejectReasonName(reason))] = c.rejected(reason);
  }
  doc["messages"] = {
      {"accepted", c.accepted()}, {"rejected", rejected}, {"rejected_total", c.total_rejected()}};
  doc["limits"] = {{"publish_failures", server.publish_failures()},
                   {"event_subscribers", server.event_subscribers()},
                   {"event_messages_refused", server.event_stats().refused},
                   {"event_subscribers_refused", server.event_stats().refused_full},
                   {"events_dropped_queue_full", server.event_stats().dropped_queue_full},
                   {"tracked_senders", server.tracked_senders()},
                   {"max_members", server.members().options().max_members}};

  if (sources_.annotations != nullptr) {
    const AnnotationCounters& a = sources_.annotations->counters();
    const AnnotationStore& store = sources_.annotations->store();
    doc["annotations"] = {{"database", store.path()},
                          {"last_event_sequence", store.last_sequence()},
                          {"strokes", store.state().strokes().size()},
                          {"accepted", a.accepted},
                          {"rejected", a.rejected},
                          {"commits", a.commits},
                          {"commit_failures", a.commit_failures},
                          {"catch_ups", a.catch_ups},
                          {"snapshots_sent", a.snapshots_sent}};
  } else {
    doc["annotations"] = nullptr;
  }

  if (sources_.timeline != nullptr) {
    const TimelineService& t = *sources_.timeline;
    const cluster::MediaClockState s = t.clock().SampleAt(now_ns);
    doc["timeline"] = {{"media_time_s", s.media_time_s},
                       {"rate", s.rate},
                       {"playing", s.playing},
                       {"duration_s", t.clock().duration_s()},
                       {"change_count", s.change_count},
                       {"tracks", t.tracks().tracks().size()},
                       {"track_samples", t.tracks().sample_count()},
                       {"requests_accepted", t.counters().accepted},
                       {"requests_rejected", t.counters().rejected},
                       {"clocks_published", t.counters().clocks_published}};
  } else {
    doc["timeline"] = nullptr;
  }
  if (sources_.tracker != nullptr) {
    // "replaying" while a replay streams, "finished" at its end; other sources: the state.
    const WandService& w = *sources_.tracker;
    const TrackerState state = w.source().state();
    const char* name = state == TrackerState::kStreaming ? "replaying"
                       : state == TrackerState::kEnded   ? "finished"
                                                         : TrackerStateName(state);
    doc["tracker"] = {{"state", name},
                      {"source", w.source().Describe()},
                      {"rate_hz", w.source().rate_hz()},
                      {"samples", w.counters().samples},
                      {"poses_published", w.counters().poses_published},
                      {"cursors_published", w.counters().cursors_published},
                      {"cursor_hits", w.counters().cursor_hits}};
  } else {
    doc["tracker"] = {{"state", "not_running"}};  // no --tracker-replay
  }
  const HttpStatusCounters& h = http_->counters();
  doc["http"] = {{"ok", h.ok.load()},
                 {"not_found", h.not_found.load()},
                 {"bad_request", h.bad_request.load()},
                 {"unauthorized", h.unauthorized.load()},
                 {"actions", h.actions.load()},
                 {"streams", h.streams.load()}};
  return doc.dump();
}

}  // namespace sandtable::coordinator
