#include "node/events/event_state_service.h"

#include "common/base/log.h"

namespace sandtable::node {

bool EventStateService::ServesCoordinator(wire::Envelope::BodyCase body) const {
  switch (body) {
    case wire::Envelope::kAnnotationEvent:
    case wire::Envelope::kCatchUpReply:
    case wire::Envelope::kTimelineClock:
    case wire::Envelope::kTrackerPose:
    case wire::Envelope::kCursor:
      return true;
    default:
      return false;
  }
}

void EventStateService::OnCoordinatorMessage(const wire::Envelope& message, NodeRuntime& node) {
  switch (message.body_case()) {
    case wire::Envelope::kAnnotationEvent:
      OnAnnotationEvent(message.annotation_event(), node);
      break;
    case wire::Envelope::kCatchUpReply:
      OnCatchUpReply(message.catch_up_reply());
      break;
    case wire::Envelope::kTimelineClock:
      timeline_ = message.timeline_clock();
      ++counters_.timeline_clocks;
      break;
    case wire::Envelope::kTrackerPose:
      poses_[message.tracker_pose().sensor_index()] = message.tracker_pose();
      ++counters_.tracker_poses;
      break;
    case wire::Envelope::kCursor:
      cursor_ = message.cursor();
      ++counters_.cursors;
      break;
    default:
      break;
  }
}

void EventStateService::OnRegistered(NodeRuntime& node) {
  // Whatever was published while we were away is fetched, not assumed.
  catch_up_wanted_ = true;
  RequestCatchUp(node);
}

Status EventStateService::OnStep(NodeRuntime& node) {
  if (catch_up_wanted_ && node.registered() &&
      std::chrono::steady_clock::now() - catch_up_sent_ >= catch_up_retry_) {
    RequestCatchUp(node);
  }
  return OkStatus();
}

void EventStateService::RequestCatchUp(NodeRuntime& node) {
  wire::Envelope request;
  request.mutable_catch_up_request()->set_last_seen_sequence(annotations_.last_sequence());
  catch_up_sent_ = std::chrono::steady_clock::now();
  if (node.SendToCoordinator(std::move(request)).ok()) ++counters_.catch_ups_requested;
}

void EventStateService::OnAnnotationEvent(const wire::AnnotationEvent& event, NodeRuntime& node) {
  const SequenceNumber last = annotations_.last_sequence();
  if (event.event_sequence() <= last) {
    ++counters_.annotation_events_duplicate;
    return;
  }
  if (event.event_sequence() != last + 1) {
    // A gap: ask for what is missing (at most one request outstanding).
    if (!catch_up_wanted_) {
      catch_up_wanted_ = true;
      RequestCatchUp(node);
    }
    return;
  }
  if (Status ok = annotations_.Check(event); !ok.ok()) {
    ++counters_.annotation_events_invalid;
    ST_LOG(kWarning) << "annotation event " << event.event_sequence()
                     << " refused: " << ok.ToString() << "; asking for a catch-up";
    catch_up_wanted_ = true;
    return;
  }
  annotations_.Apply(event);
  ++counters_.annotation_events_applied;
}

void EventStateService::OnCatchUpReply(const wire::CatchUpReply& reply) {
  cluster::AnnotationState next;
  if (reply.snapshot_sent()) {
    Expected<cluster::AnnotationState> from =
        cluster::AnnotationState::FromSnapshot(reply.snapshot());
    if (!from.ok()) {
      ST_LOG(kWarning) << "catch-up snapshot refused: " << from.status().ToString();
      return;  // catch_up_wanted_ stays set: retried
    }
    next = std::move(*from);
  } else {
    next = annotations_;
  }
  for (const wire::AnnotationEvent& event : reply.events()) {
    if (event.event_sequence() <= next.last_sequence()) continue;
    if (event.event_sequence() != next.last_sequence() + 1 || !next.Check(event).ok()) {
      ST_LOG(kWarning) << "catch-up event " << event.event_sequence() << " out of order or invalid";
      return;
    }
    next.Apply(event);
  }
  annotations_ = std::move(next);
  ++counters_.catch_ups_applied;
  catch_up_wanted_ = annotations_.last_sequence() < reply.last_event_sequence();
}

std::optional<double> EventStateService::MediaTimeAt(const NodeRuntime& node,
                                                     int64_t node_now_ns) const {
  if (!timeline_) return std::nullopt;
  const std::optional<ClockOffsetEstimate> offset = node.clock_offset();
  const int64_t coordinator_ns =
      node_now_ns + (offset ? static_cast<int64_t>(offset->offset_s * 1e9) : 0);
  cluster::MediaClockState state;
  state.media_time_s = timeline_->media_time_s();
  state.rate = timeline_->rate();
  state.playing = timeline_->playing();
  state.anchor_time_ns = timeline_->sample_time_ns();
  return cluster::MediaClock::MediaTimeOf(state, timeline_->duration_s(), coordinator_ns);
}

}  // namespace sandtable::node
