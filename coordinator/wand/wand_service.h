// WandService: runs a tracker source and the wand inside the coordinator (CoordinatorService).
//
// Every OnStep() polls the source (never blocks) and, for each sample that became due,
// publishes a TrackerPose (table_from_sensor = table_from_tracker *
// tracker_from_sensor) and a Cursor (ComputeCursor against the scene: the wand ray from the
// tip, hit point and normal). So events go out at the tracker rate (100 Hz for .traj replay),
// each at most one server step late; the server must step at least every 1 / (2 rate) s
// (main.cc sets step_period to 5 ms). Samples are scheduled by their own time, never by
// counting steps or sleeping: ReplaySource emits sample i when (t_i - t_0) has elapsed since
// its first Poll, so a late step emits the overdue samples together and the rate never drifts.
//
// sample_time_ns (coordinator steady clock) = the time of the first sample's Poll + (t_i -
// t_0) s: the instant the sample is due, independent of step jitter.
//
// Frames and units: table frame, metres. Scene: the table plane z = 0 as a square of half
// side scene_half_extent_m (two triangles), plus whatever triangles are added (the glTF
// scene's), cast with the common RayCaster (Embree; vertices stored in float, as glTF has
// them). Should the caster not start (Embree unavailable), the service logs it, reports it in
// scene_status() and publishes cursors that hit nothing; poses still go out.
#pragma once

#include <cstdint>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "common/geometry/rigid3.h"
#include "common/scene/ray_caster.h"
#include "coordinator/annotations/annotation_service.h"
#include "coordinator/membership/coordinator_server.h"
#include "coordinator/tracker/tracker_calibration.h"  // LoadTableFromTracker (its file)
#include "coordinator/tracker/tracker_source.h"
#include "coordinator/wand/wand.h"
#include "coordinator/wand/wand_painter.h"

namespace sandtable::coordinator {

struct WandServiceOptions {
  Rigid3d table_from_tracker = Rigid3d::Identity();
  WandOptions wand;
  double scene_half_extent_m = 5.0;  // table plane quad [-h, h]^2 at z = 0
  Status Check() const;
};

struct WandCounters {
  uint64_t samples = 0;            // samples taken from the source
  uint64_t poses_published = 0;    // TrackerPose events
  uint64_t cursors_published = 0;  // Cursor events
  uint64_t cursor_hits = 0;        // of which the ray hit the scene
  uint64_t publish_failures = 0;
  uint64_t annotation_events = 0;  // painted events handed to the annotation sink
};

// The table plane z = 0 as two counter-clockwise triangles over [-h, h]^2, appended.
void AppendTablePlane(double half_extent_m, std::vector<Eigen::Vector3d>* positions,
                      std::vector<Eigen::Vector3i>* triangles);

class WandService : public CoordinatorService {
 public:
  // `extra_triangles` (with `extra_positions_in_table_m`) are added to the table plane; their
  // indices must be valid and positions finite (LoadGltfScene checks both), else the scene is
  // left out (scene_status() says why).
  WandService(std::unique_ptr<TrackerSource> source, WandServiceOptions options,
              std::vector<Eigen::Vector3d> extra_positions_in_table_m = {},
              std::vector<Eigen::Vector3i> extra_triangles = {});

  bool Serves(wire::Envelope::BodyCase) const override { return false; }
  void OnRequest(net::Incoming, CoordinatorServer&) override {}
  Status OnStep(CoordinatorServer& server) override;

  // Polls the source at `now_ns` (coordinator steady clock) and returns the events due, in
  // order (TrackerPose, Cursor per sample). OnStep() publishes these. For tests.
  std::vector<wire::Envelope> PollEvents(int64_t now_ns);

  // Painting (docs/coordinator.md): every cursor also goes through a WandPainter and its
  // annotation events (strokes, spot erase, clear) go to `submit`, in order, during
  // PollEvents(). `next_id_floor` returns one more than the newest event sequence in the log
  // (wand stroke ids stay above it). Call before the first step.
  using AnnotationSubmit = std::function<void(wire::AnnotationEvent)>;
  void EnablePainting(WandPainterOptions options, AnnotationSubmit submit,
                      std::function<uint64_t()> next_id_floor);
  // The same through the AnnotationService's Submit(): the events are persisted (SQLite) and
  // only then published, like client requests. `annotations` must outlive this service.
  void EnablePainting(WandPainterOptions options, AnnotationService* annotations);

  const WandPainter* painter() const { return painter_ ? &*painter_ : nullptr; }
  const TrackerSource& source() const { return *source_; }
  const WandCounters& counters() const { return counters_; }
  // The wand's scene; nullptr when it could not be built (see scene_status()).
  const RayCaster* scene() const { return scene_.get(); }
  const Status& scene_status() const { return scene_status_; }

 private:
  std::unique_ptr<TrackerSource> source_;
  WandServiceOptions options_;
  std::unique_ptr<RayCaster> scene_;
  Status scene_status_;
  WandCounters counters_;
  bool anchored_ = false;
  int64_t anchor_ns_ = 0;
  double anchor_source_s_ = 0.0;
  TrackerState last_state_ = TrackerState::kNoDevice;
  std::vector<TrackerSample> batch_;
  std::optional<WandPainter> painter_;
  AnnotationSubmit submit_;
  std::function<uint64_t()> next_id_floor_;
};

}  // namespace sandtable::coordinator
