// EventStateService: what the coordinator publishes, kept on the node for its renderer.
//
// - Annotations: the strokes, rebuilt from the sequenced annotation events exactly as the
//   coordinator rebuilds them (cluster::AnnotationState). On registration, and whenever an
//   event arrives out of sequence (a gap: events were lost, or the node joined late), the
//   service asks for a catch-up (CatchUpRequest on the coordinator link; at most one
//   outstanding, retried after catch_up_retry) and applies the reply (snapshot or events).
//   Duplicates (sequence <= last applied) are ignored; an event that fails the state's rules
//   is counted and triggers a catch-up instead of being applied.
//   Paging (events.proto CatchUpReply): a reply that leaves the node behind the coordinator's
//   last_event_sequence is followed AT ONCE by the next request (not after catch_up_retry);
//   a snapshot in chunks is assembled (each chunk must continue the bytes so far; at most
//   kMaxCatchUpSnapshotBytes in all, else it is refused and logged) and parsed when whole; an
//   expired snapshot starts again. A lost reply is retried after catch_up_retry from where it
//   stopped.
// - Timeline: the last TimelineClock; MediaTimeAt(node time) converts node steady time to
//   coordinator time with the node's clock offset estimate and extrapolates the clock, so
//   every node evaluates the same media time for the same instant.
// - Tracker: the last TrackerPose per sensor and the last Cursor.
// - Test patterns: the last TestPatternState (a newer change_count replaces it); the pattern for
//   a node is its own, else the site's (names as in node/render/render_content.h).
// Network thread only.
#pragma once

#include <chrono>
#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "cluster/annotation_state.h"
#include "cluster/media_clock.h"
#include "node/net/node_runtime.h"
#include "proto/events.pb.h"
#include "proto/timeline.pb.h"

namespace sandtable::node {

struct EventStateCounters {
  uint64_t annotation_events_applied = 0;
  uint64_t annotation_events_duplicate = 0;
  uint64_t annotation_events_invalid = 0;
  uint64_t catch_ups_requested = 0;
  uint64_t catch_ups_applied = 0;
  uint64_t snapshot_chunks = 0;
  uint64_t snapshots_refused = 0;
  uint64_t timeline_clocks = 0;
  uint64_t tracker_poses = 0;
  uint64_t cursors = 0;
  uint64_t test_pattern_states = 0;
};

// Largest snapshot a node assembles from chunks (its memory while catching up): 1 GiB.
inline constexpr uint64_t kMaxCatchUpSnapshotBytes = uint64_t{1} << 30;

class EventStateService : public NodeService {
 public:
  explicit EventStateService(std::chrono::milliseconds catch_up_retry = std::chrono::seconds(1))
      : catch_up_retry_(catch_up_retry) {}

  const char* name() const override { return "events"; }
  bool ServesCoordinator(wire::Envelope::BodyCase body) const override;
  void OnCoordinatorMessage(const wire::Envelope& message, NodeRuntime& node) override;
  void OnRegistered(NodeRuntime& node) override;
  Status OnStep(NodeRuntime& node) override;

  const cluster::AnnotationState& annotations() const { return annotations_; }
  // Media time (s) at node steady time `node_now_ns`; nullopt before the first clock.
  std::optional<double> MediaTimeAt(const NodeRuntime& node, int64_t node_now_ns) const;
  const std::optional<wire::TimelineClock>& timeline() const { return timeline_; }
  const std::map<uint32_t, wire::TrackerPose>& tracker_poses() const { return poses_; }
  const std::optional<wire::Cursor>& cursor() const { return cursor_; }
  const EventStateCounters& counters() const { return counters_; }
  // "none" until the coordinator published a state.
  std::string TestPatternFor(NodeId node) const;

 private:
  void OnAnnotationEvent(const wire::AnnotationEvent& event, NodeRuntime& node);
  void OnCatchUpReply(const wire::CatchUpReply& reply, NodeRuntime& node);
  // Adds a chunk; asks for the next one, or parses and applies the whole snapshot.
  void OnSnapshotChunk(const wire::CatchUpReply& reply, NodeRuntime& node);
  void ApplyCatchUp(cluster::AnnotationState next, const wire::CatchUpReply& reply,
                    NodeRuntime& node);
  void RequestCatchUp(NodeRuntime& node);

  std::chrono::milliseconds catch_up_retry_;
  cluster::AnnotationState annotations_;
  bool catch_up_wanted_ = false;
  // A snapshot arriving in chunks: its sequence (0: none), total and the bytes so far.
  uint64_t chunked_sequence_ = 0;
  uint64_t chunked_total_bytes_ = 0;
  std::string chunked_bytes_;
  std::chrono::steady_clock::time_point catch_up_sent_{};
  std::optional<wire::TimelineClock> timeline_;
  std::map<uint32_t, wire::TrackerPose> poses_;
  std::optional<wire::Cursor> cursor_;
  std::optional<wire::TestPatternState> test_patterns_;
  EventStateCounters counters_;
};

}  // namespace sandtable::node
