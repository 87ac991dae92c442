#include "coordinator/timeline/timeline_service.h"

#include <cmath>

#include "common/base/check.h"
#include "common/base/log.h"
#include "proto/envelope_stamper.h"

namespace sandtable::coordinator {

Status TimelineServiceOptions::Check() const {
  if (!std::isfinite(publish_rate_hz) || publish_rate_hz <= 0.0 || publish_rate_hz > 1000.0) {
    return InvalidArgumentError("timeline: publish_rate_hz must be in (0, 1000]");
  }
  if (!std::isfinite(max_rate) || max_rate <= 0.0) {
    return InvalidArgumentError("timeline: max_rate must be finite and > 0");
  }
  return OkStatus();
}

namespace {
cluster::MediaClockOptions ClockOptions(const PersonnelTracks& tracks,
                                        const TimelineServiceOptions& o) {
  const Status ok = o.Check();
  ST_CHECK(ok.ok()) << ok.ToString() << "; check TimelineServiceOptions before constructing";
  cluster::MediaClockOptions clock;
  clock.duration_s = tracks.duration_s();
  clock.max_rate = o.max_rate;
  return clock;
}
}  // namespace

TimelineService::TimelineService(PersonnelTracks tracks, TimelineServiceOptions options)
    : tracks_(std::move(tracks)), options_(options), clock_(ClockOptions(tracks_, options_)) {}

bool TimelineService::Serves(wire::Envelope::BodyCase body) const {
  return body == wire::Envelope::kPlay || body == wire::Envelope::kPause ||
         body == wire::Envelope::kSeek || body == wire::Envelope::kRate;
}

wire::TimelineClock TimelineService::ClockAt(int64_t now_ns) const {
  const cluster::MediaClockState s = clock_.SampleAt(now_ns);
  wire::TimelineClock out;
  out.set_media_time_s(s.media_time_s);
  out.set_rate(s.rate);
  out.set_playing(s.playing);
  out.set_sample_time_ns(s.anchor_time_ns);
  out.set_duration_s(clock_.duration_s());
  out.set_change_count(s.change_count);
  for (const auto& [id, samples] : tracks_.tracks()) {
    Expected<TrackPositionAt> p = tracks_.PositionAt(id, s.media_time_s);
    if (!p.ok()) continue;  // cannot happen: id is a known track and the time is finite
    wire::TrackPosition* t = out.add_tracks();
    t->set_track_id(id);
    t->mutable_position_in_table_m()->set_x(p->position_in_table_m.x());
    t->mutable_position_in_table_m()->set_y(p->position_in_table_m.y());
    t->mutable_position_in_table_m()->set_z(p->position_in_table_m.z());
    t->set_active(p->active);
  }
  return out;
}

void TimelineService::OnRequest(net::Incoming request, CoordinatorServer& server) {
  const int64_t now_ns = proto::SteadyNowNs();
  (void)clock_.Advance(now_ns);
  const wire::Envelope& e = request.envelope;
  Status applied;
  switch (e.body_case()) {
    case wire::Envelope::kPlay:
      applied = clock_.Play(now_ns, e.play().at_time_ns());
      break;
    case wire::Envelope::kPause:
      applied = clock_.Pause(now_ns, e.pause().at_time_ns());
      break;
    case wire::Envelope::kSeek:
      applied = clock_.Seek(now_ns, e.seek().position_s());
      break;
    case wire::Envelope::kRate:
      applied = clock_.SetRate(now_ns, e.rate().rate());
      break;
    default:
      applied = InvalidArgumentError("timeline: not a timeline request");
      break;
  }
  applied.ok() ? ++counters_.accepted : ++counters_.rejected;
  wire::Envelope reply;
  wire::TimelineReply* r = reply.mutable_timeline_reply();
  r->set_request_sequence(e.sequence());
  r->set_accepted(applied.ok());
  if (!applied.ok()) r->set_reason(applied.ToString());
  *r->mutable_clock() = ClockAt(now_ns);
  Status sent = server.Reply(std::move(reply), request.routing_id);
  if (!sent.ok()) ST_LOG(kDebug) << "timeline reply dropped: " << sent.ToString();
  if (applied.ok()) {
    Status published = PublishClock(server, now_ns);
    if (!published.ok()) ST_LOG(kDebug) << "timeline clock not published: " << published.ToString();
  }
}

Status TimelineService::OnStep(CoordinatorServer& server) {
  const int64_t now_ns = proto::SteadyNowNs();
  const bool ended = clock_.Advance(now_ns);
  const auto period_ns = static_cast<int64_t>(1e9 / options_.publish_rate_hz);
  if (!ended && last_publish_ns_ != 0 && now_ns - last_publish_ns_ < period_ns) return OkStatus();
  return PublishClock(server, now_ns);
}

Status TimelineService::PublishClock(CoordinatorServer& server, int64_t now_ns) {
  wire::Envelope event;
  *event.mutable_timeline_clock() = ClockAt(now_ns);
  last_publish_ns_ = now_ns;
  ++counters_.clocks_published;
  return server.Publish(std::move(event));
}

}  // namespace sandtable::coordinator
