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
    case wire::Envelope::kTestPatternState:
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
      OnCatchUpReply(message.catch_up_reply(), node);
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
    case wire::Envelope::kTestPatternState:
      // Older states (a reordered or repeated event) never replace newer ones.
      if (!test_patterns_ ||
          message.test_pattern_state().change_count() >= test_patterns_->change_count()) {
        test_patterns_ = message.test_pattern_state();
      }
      ++counters_.test_pattern_states;
      break;
    default:
      break;
  }
}

std::string EventStateService::TestPatternFor(NodeId node) const {
  if (!test_patterns_) return "none";
  auto own = test_patterns_->node_patterns().find(node);
  if (own != test_patterns_->node_patterns().end()) return own->second;
  return test_patterns_->site_pattern().empty() ? "none" : test_patterns_->site_pattern();
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
  wire::CatchUpRequest* out = request.mutable_catch_up_request();
  out->set_last_seen_sequence(annotations_.last_sequence());
  if (chunked_sequence_ != 0) {
    out->set_snapshot_sequence(chunked_sequence_);
    out->set_snapshot_offset_bytes(chunked_bytes_.size());
  }
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

void EventStateService::OnCatchUpReply(const wire::CatchUpReply& reply, NodeRuntime& node) {
  if (reply.snapshot_expired()) {
    ST_LOG(kInfo) << "catch-up snapshot " << chunked_sequence_ << " expired; starting again";
    chunked_sequence_ = chunked_total_bytes_ = 0;
    chunked_bytes_.clear();
    catch_up_wanted_ = true;
    RequestCatchUp(node);
    return;
  }
  if (reply.snapshot_total_bytes() > 0) {
    OnSnapshotChunk(reply, node);
    return;
  }
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
  ApplyCatchUp(std::move(next), reply, node);
}

void EventStateService::OnSnapshotChunk(const wire::CatchUpReply& reply, NodeRuntime& node) {
  ++counters_.snapshot_chunks;
  const uint64_t total = reply.snapshot_total_bytes();
  const uint64_t offset = reply.snapshot_offset_bytes();
  auto refuse = [&](const std::string& why) {
    ++counters_.snapshots_refused;
    ST_LOG(kWarning) << "catch-up snapshot " << reply.snapshot_sequence() << " refused: " << why;
    chunked_sequence_ = chunked_total_bytes_ = 0;
    chunked_bytes_.clear();
  };
  if (total > kMaxCatchUpSnapshotBytes) {
    refuse(std::to_string(total) + " bytes, more than kMaxCatchUpSnapshotBytes = " +
           std::to_string(kMaxCatchUpSnapshotBytes));
    return;  // retried after catch_up_retry
  }
  if (offset == 0) {
    chunked_sequence_ = reply.snapshot_sequence();
    chunked_total_bytes_ = total;
    chunked_bytes_.clear();
  }
  if (chunked_sequence_ == 0 || reply.snapshot_sequence() != chunked_sequence_ ||
      total != chunked_total_bytes_ || offset != chunked_bytes_.size() ||
      reply.snapshot_chunk().empty() || offset + reply.snapshot_chunk().size() > total) {
    // A stale or duplicate chunk (e.g. the answer to a retried request): ignored.
    ST_LOG(kDebug) << "catch-up chunk at " << offset << " of snapshot " << reply.snapshot_sequence()
                   << " does not continue ours; ignored";
    return;
  }
  chunked_bytes_ += reply.snapshot_chunk();
  if (chunked_bytes_.size() < total) {
    RequestCatchUp(node);  // the next chunk, at once
    return;
  }
  wire::Snapshot snapshot;
  const bool parsed = snapshot.ParseFromString(chunked_bytes_);
  chunked_sequence_ = chunked_total_bytes_ = 0;
  chunked_bytes_.clear();
  chunked_bytes_.shrink_to_fit();
  if (!parsed) {
    refuse("the assembled chunks do not parse");
    return;
  }
  Expected<cluster::AnnotationState> from = cluster::AnnotationState::FromSnapshot(snapshot);
  if (!from.ok()) {
    refuse(from.status().ToString());
    return;
  }
  wire::CatchUpReply whole;
  whole.set_last_event_sequence(reply.last_event_sequence());
  ApplyCatchUp(std::move(*from), whole, node);
}

void EventStateService::ApplyCatchUp(cluster::AnnotationState next, const wire::CatchUpReply& reply,
                                     NodeRuntime& node) {
  for (const wire::AnnotationEvent& event : reply.events()) {
    if (event.event_sequence() <= next.last_sequence()) continue;
    if (event.event_sequence() != next.last_sequence() + 1 || !next.Check(event).ok()) {
      ST_LOG(kWarning) << "catch-up event " << event.event_sequence() << " out of order or invalid";
      return;
    }
    next.Apply(event);
  }
  const bool progressed = next.last_sequence() > annotations_.last_sequence();
  annotations_ = std::move(next);
  ++counters_.catch_ups_applied;
  catch_up_wanted_ = annotations_.last_sequence() < reply.last_event_sequence();
  // Still behind after progress: the next page at once (the reply was cut at the page size,
  // or the snapshot is older than the log's head). Without progress: after catch_up_retry.
  if (catch_up_wanted_ && progressed) RequestCatchUp(node);
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
