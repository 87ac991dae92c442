#include "node/render/render_service.h"

#include "common/base/log.h"

namespace sandtable::node {

RenderService::RenderService(const EventStateService* events, RenderLoop* loop,
                             RenderServiceOptions options,
                             std::function<void(const report::ReportLine&)> print)
    : events_(events), loop_(loop), options_(options), print_(std::move(print)) {
  inputs_.sun = options_.sun;
}

Status RenderService::OnStep(NodeRuntime& node) {
  bool changed = !inputs_sent_;
  // The operator's pattern for this unit.
  const std::string name = events_->TestPatternFor(node.id());
  const TestPattern pattern = TestPatternFromName(name).value_or(TestPattern::kNone);
  if (pattern != inputs_.pattern || inputs_.projector_id != node.id()) {
    inputs_.pattern = pattern;
    inputs_.projector_id = node.id();
    changed = true;
  }
  // Strokes, when the annotation sequence moved.
  const SequenceNumber sequence = events_->annotations().last_sequence();
  if (sequence != strokes_sequence_) {
    strokes_sequence_ = sequence;
    inputs_.strokes = std::make_shared<const std::vector<Polyline>>(
        StrokesFromAnnotations(events_->annotations()));
    ++inputs_.strokes_version;
    changed = true;
  }
  // The wand's cursor where its ray hits the model.
  std::optional<Marker> cursor;
  if (const std::optional<wire::Cursor>& c = events_->cursor(); c && c->hit()) {
    Marker m;
    m.position_in_table_m =
        Eigen::Vector3d(c->hit_in_table_m().x(), c->hit_in_table_m().y(), c->hit_in_table_m().z());
    m.ring = true;
    m.radius_m = 0.02;
    m.colour =
        c->button_pressed() ? Eigen::Vector3f(1.0f, 0.2f, 0.2f) : Eigen::Vector3f(1.0f, 1.0f, 0.0f);
    if (m.position_in_table_m.allFinite()) cursor = m;
  }
  const bool cursor_changed =
      cursor.has_value() != inputs_.cursor.has_value() ||
      (cursor && (cursor->position_in_table_m != inputs_.cursor->position_in_table_m ||
                  cursor->colour != inputs_.cursor->colour));
  if (cursor_changed) {
    inputs_.cursor = cursor;
    changed = true;
  }
  if (changed) {
    inputs_.timeline_known = events_->timeline().has_value();
    loop_->SetInputs(inputs_);
    inputs_sent_ = true;
  }
  // The timeline, in this node's clock.
  TimelineView timeline;
  if (const std::optional<wire::TimelineClock>& clock = events_->timeline()) {
    timeline.known = true;
    timeline.media_time_s = clock->media_time_s();
    timeline.rate = clock->rate();
    timeline.playing = clock->playing();
    timeline.anchor_coordinator_ns = clock->sample_time_ns();
    timeline.duration_s = clock->duration_s();
    if (std::optional<ClockOffsetEstimate> offset = node.clock_offset()) {
      timeline.coordinator_minus_node_ns = static_cast<int64_t>(offset->offset_s * 1e9);
    }
  }
  loop_->SetTimeline(timeline);

  // Lines for the lab: a new pattern's first frame, and the summary.
  const auto [frames_shown, shown_pattern] = loop_->ShownPattern();
  if (shown_pattern != announced_pattern_ && frames_shown > 0) {
    announced_pattern_ = shown_pattern;
    print_(report::RenderPattern{node.id(), shown_pattern});
  }
  const auto now = std::chrono::steady_clock::now();
  if (now - last_summary_ >= options_.summary_period && frames_shown > 0) {
    last_summary_ = now;
    print_(Summary(node.id()));
  }
  return OkStatus();
}

report::RenderSummary RenderService::Summary(NodeId id) const {
  const RenderSummary s = loop_->Summary();
  report::RenderSummary line;
  line.id = id;
  line.frames = s.frames_shown;
  line.failed = s.frames_failed;
  line.unchanged = s.frames_unchanged;
  line.rewarped = s.frames_rewarped;
  line.frame_ms_p50 = s.frame_ms_p50;
  line.frame_ms_p99 = s.frame_ms_p99;
  line.first_frame_ms = s.first_frame_ms;
  line.floor_ms = s.floor_ms;
  line.show_ms_p50 = s.show_ms_p50;
  for (int p = 0; p < kPassCount; ++p) line.passes[PassName(static_cast<Pass>(p))] = s.pass_runs[p];
  line.groups_culled = s.groups_culled;
  line.context = s.context;
  return line;
}

Status RenderServiceOptions::Check() const {
  ST_RETURN_IF_ERROR(sun.Check());
  if (summary_period.count() <= 0) {
    return InvalidArgumentError("render service: summary_period must be > 0");
  }
  return OkStatus();
}

}  // namespace sandtable::node
