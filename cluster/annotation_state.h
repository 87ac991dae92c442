// AnnotationState: the strokes on the table, rebuilt by applying sequenced annotation events
// (wire::AnnotationEvent, the coordinator's log record) in order.
//
// Frames and units: points in the table frame, metres (float on the wire: ~0.1 um resolution
// over a 2 m table); width_m is the stroke width on the surface in metres; colour is linear RGB
// in [0, 1].
// Validation: Check() says whether an event may be applied to the current state (untrusted
// input from the network: never aborts). Rules: stroke ids are non-zero and below
// kDerivedStrokeIdBit (ids at or above it are made by the spot eraser); a stroke begins once;
// points go to an open stroke at first_point_index == its point count (no gaps, no repeats);
// coordinates finite; 0 < width_m <= kMaxStrokeWidth_m; colour in [0, 1]; erase names an
// existing stroke; spot erase has 0 < radius_m <= kMaxEraseRadius_m.
// Apply() of a checked event is deterministic, so replaying the log rebuilds the same state.
#pragma once

#include <cstdint>
#include <map>
#include <vector>

#include <Eigen/Core>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "proto/events.pb.h"

namespace sandtable::cluster {

constexpr double kMaxStrokeWidth_m = 0.5;
constexpr double kMaxEraseRadius_m = 2.0;
constexpr uint32_t kMaxPointsPerMessage = 100000;
// Ids with this bit are made by the spot eraser when it splits a stroke:
// kDerivedStrokeIdBit | (event_sequence << 16) | run_index (run_index >= 1).
constexpr StrokeId kDerivedStrokeIdBit = StrokeId{1} << 63;

struct Stroke {
  StrokeId id = kInvalidStrokeId;
  Eigen::Vector3f color_rgb{1.f, 1.f, 1.f};
  float width_m = 0.f;
  std::vector<Eigen::Vector3f> points_in_table_m;
  bool ended = false;
};

class AnnotationState {
 public:
  // OK if `event` may be applied now; otherwise INVALID_ARGUMENT naming the broken rule.
  Status Check(const wire::AnnotationEvent& event) const;
  // Applies a checked event (ST_CHECKs that it passes Check()). Events must come in sequence
  // order; event.event_sequence() becomes last_sequence().
  void Apply(const wire::AnnotationEvent& event);

  const std::map<StrokeId, Stroke>& strokes() const { return strokes_; }
  SequenceNumber last_sequence() const { return last_sequence_; }
  size_t NumPoints() const;

  wire::Snapshot ToSnapshot() const;
  // The state a snapshot describes (a late joiner's catch-up). Untrusted input: the same
  // rules as Check() (finite points, width and colour ranges, whole xyz triples, no duplicate
  // stroke ids), INVALID_ARGUMENT naming the stroke otherwise.
  static Expected<AnnotationState> FromSnapshot(const wire::Snapshot& snapshot);

 private:
  void ApplySpotErase(const wire::SpotErase& erase, SequenceNumber sequence);

  std::map<StrokeId, Stroke> strokes_;
  SequenceNumber last_sequence_ = 0;
};

}  // namespace sandtable::cluster
