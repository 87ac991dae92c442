#include "coordinator/wand/wand_service.h"

#include <chrono>
#include <cmath>
#include <utility>

#include "common/base/log.h"
#include "proto/convert.h"
#include "proto/envelope_stamper.h"

namespace sandtable::coordinator {
namespace {

// The table plane plus the given triangles, as a Scene (float vertices) and its caster.
Expected<std::unique_ptr<RayCaster>> BuildScene(double half_extent_m,
                                                std::vector<Eigen::Vector3d> positions,
                                                std::vector<Eigen::Vector3i> triangles) {
  AppendTablePlane(half_extent_m, &positions, &triangles);
  auto scene = std::make_shared<Scene>();
  scene->positions_in_table_m.reserve(positions.size());
  for (const Eigen::Vector3d& p : positions) scene->positions_in_table_m.push_back(p.cast<float>());
  scene->triangles = std::move(triangles);
  scene->triangle_material.assign(scene->triangles.size(), 0);
  scene->materials.push_back(Material{"wand scene", {1.0, 1.0, 1.0, 1.0}, -1});
  return RayCaster::Create(std::move(scene));
}

}  // namespace

Status WandServiceOptions::Check() const {
  if (!(scene_half_extent_m > 0.0) || !std::isfinite(scene_half_extent_m)) {
    return InvalidArgumentError("WandServiceOptions: scene_half_extent_m must be finite and > 0");
  }
  if (Status w = wand.Check(); !w.ok())
    return InvalidArgumentError("WandServiceOptions: " + w.message());
  return OkStatus();
}

void AppendTablePlane(double half_extent_m, std::vector<Eigen::Vector3d>* positions,
                      std::vector<Eigen::Vector3i>* triangles) {
  const int base = static_cast<int>(positions->size());
  const double h = half_extent_m;
  positions->push_back({-h, -h, 0.0});
  positions->push_back({h, -h, 0.0});
  positions->push_back({h, h, 0.0});
  positions->push_back({-h, h, 0.0});
  triangles->push_back({base, base + 1, base + 2});  // counter-clockwise seen from +z
  triangles->push_back({base, base + 2, base + 3});
}

WandService::WandService(std::unique_ptr<TrackerSource> source, WandServiceOptions options,
                         std::vector<Eigen::Vector3d> extra_positions_in_table_m,
                         std::vector<Eigen::Vector3i> extra_triangles)
    : source_(std::move(source)), options_(std::move(options)) {
  ST_CHECK(source_ != nullptr) << "WandService needs a tracker source";
  ST_CHECK(options_.Check().ok()) << options_.Check().ToString();
  Expected<std::unique_ptr<RayCaster>> scene =
      BuildScene(options_.scene_half_extent_m, std::move(extra_positions_in_table_m),
                 std::move(extra_triangles));
  if (scene.ok()) {
    scene_ = std::move(*scene);
  } else {
    scene_status_ = scene.status().WithContext("wand scene");
    ST_LOG(kError) << scene_status_.ToString() << "; cursors will hit nothing";
  }
  last_state_ = source_->state();
}

std::vector<wire::Envelope> WandService::PollEvents(int64_t now_ns) {
  batch_.clear();
  const TrackerClock::time_point now{std::chrono::nanoseconds(now_ns)};
  const Status polled = source_->Poll(now, &batch_);
  if (!polled.ok()) ST_LOG(kWarning) << "tracker: " << polled.ToString();
  const TrackerState state = source_->state();
  if (state != last_state_) {
    ST_LOG(kInfo) << "tracker " << TrackerStateName(last_state_) << " -> "
                  << TrackerStateName(state) << " (" << source_->Describe() << ", "
                  << counters_.samples + batch_.size() << " samples)";
    last_state_ = state;
  }
  std::vector<wire::Envelope> events;
  events.reserve(2 * batch_.size());
  for (const TrackerSample& sample : batch_) {
    if (!anchored_) {
      // The first sample is due on the Poll that returns it; later ones keep their spacing.
      anchored_ = true;
      anchor_ns_ = now_ns;
      anchor_source_s_ = sample.source_time_s;
    }
    const int64_t sample_time_ns =
        anchor_ns_ + std::llround((sample.source_time_s - anchor_source_s_) * 1e9);
    ++counters_.samples;
    wire::Envelope pose;
    wire::TrackerPose* p = pose.mutable_tracker_pose();
    p->set_sensor_index(sample.sensor_index);
    *p->mutable_table_from_sensor() =
        proto::ToWire(options_.table_from_tracker * sample.tracker_from_sensor);
    p->set_sample_time_ns(sample_time_ns);
    p->set_button_pressed(sample.button_pressed);
    events.push_back(std::move(pose));

    const CursorState cursor =
        ComputeCursor(sample, options_.table_from_tracker, scene_.get(), options_.wand);
    if (cursor.hit) ++counters_.cursor_hits;
    if (painter_) {
      for (wire::AnnotationEvent& e : painter_->OnCursor(cursor, next_id_floor_())) {
        ++counters_.annotation_events;
        submit_(std::move(e));
      }
    }
    wire::Envelope cursor_event;
    *cursor_event.mutable_cursor() = ToWire(cursor, sample_time_ns);
    events.push_back(std::move(cursor_event));
  }
  return events;
}

void WandService::EnablePainting(WandPainterOptions options, AnnotationSubmit submit,
                                 std::function<uint64_t()> next_id_floor) {
  ST_CHECK(submit && next_id_floor) << "EnablePainting needs a sink and an id floor";
  painter_.emplace(std::move(options));
  submit_ = std::move(submit);
  next_id_floor_ = std::move(next_id_floor);
}

void WandService::EnablePainting(WandPainterOptions options, AnnotationService* annotations) {
  ST_CHECK(annotations != nullptr) << "EnablePainting needs the AnnotationService";
  EnablePainting(
      std::move(options),
      [annotations](wire::AnnotationEvent e) { annotations->Submit(std::move(e)); },
      [annotations] { return annotations->store().last_sequence() + 1; });
}

Status WandService::OnStep(CoordinatorServer& server) {
  for (wire::Envelope& event : PollEvents(proto::SteadyNowNs())) {
    const bool is_pose = event.has_tracker_pose();
    const Status published = server.Publish(std::move(event));
    if (!published.ok()) {
      // A slow subscriber must not stop the tracker: count, log at debug, go on.
      ++counters_.publish_failures;
      ST_LOG(kDebug) << "tracker event not published: " << published.ToString();
      continue;
    }
    ++(is_pose ? counters_.poses_published : counters_.cursors_published);
  }
  return OkStatus();
}

}  // namespace sandtable::coordinator
