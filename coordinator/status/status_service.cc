#include "coordinator/status/status_service.h"

#include <nlohmann/json.hpp>

#include "common/base/check.h"
#include "proto/envelope_stamper.h"

namespace sandtable::coordinator {

StatusService::StatusService(HttpStatusServer* http, StatusSources sources,
                             std::chrono::milliseconds refresh_period)
    : http_(http), sources_(sources), refresh_period_(refresh_period) {
  ST_CHECK(http_ != nullptr) << "StatusService needs a started HttpStatusServer";
}

Status StatusService::OnStep(CoordinatorServer& server) {
  const auto now = std::chrono::steady_clock::now();
  if (last_ != std::chrono::steady_clock::time_point{} && now - last_ < refresh_period_) {
    return OkStatus();
  }
  last_ = now;
  http_->Publish(BuildJson(server));
  return OkStatus();
}

std::string StatusService::BuildJson(const CoordinatorServer& server) const {
  using nlohmann::json;
  const int64_t now_ns = proto::SteadyNowNs();
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
                       {"calibration", nullptr}});
  }
  doc["members"] = std::move(members);

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
                 {"bad_request", h.bad_request.load()}};
  return doc.dump();
}

}  // namespace sandtable::coordinator
