#include "node/render/render_loop.h"

#include <algorithm>
#include <cstring>
#include <optional>
#include <set>
#include <vector>

#include "common/base/bytes_hash.h"
#include "common/base/host_clock.h"
#include "common/base/log.h"
#include "common/scene/procedural_scene.h"
#include "node/devices/window_projector_output.h"
#include "node/render/gl_context.h"

namespace sandtable::node {
namespace {

using Clock = std::chrono::steady_clock;

double MsBetween(Clock::time_point from, Clock::time_point to) {
  return std::chrono::duration<double, std::milli>(to - from).count();
}
constexpr size_t kKeptFrames = 2000;  // frame times kept for the percentiles

// This host's clock (the timeline's time base; the render log's node_steady_ns).
int64_t NowNs() { return HostNowNs(); }

double Percentile(const std::deque<double>& values, double p) {
  if (values.empty()) return 0.0;
  std::vector<double> v(values.begin(), values.end());
  const size_t i =
      std::min(v.size() - 1, static_cast<size_t>(std::ceil(p * static_cast<double>(v.size()))) - 1);
  std::nth_element(v.begin(), v.begin() + static_cast<long>(i), v.end());
  return v[i];
}

// A 64-bit hash of a frame's bytes: frames equal to the last shown are not shown again.
uint64_t FrameHash(const cv::Mat& frame) {
  const cv::Mat packed = frame.isContinuous() ? frame : frame.clone();
  return HashBytes64(packed.data, packed.total() * packed.elemSize());
}

void Keep(std::deque<double>* values, double v) {
  values->push_back(v);
  if (values->size() > kKeptFrames) values->pop_front();
}

}  // namespace

Status RenderLoopOptions::Check() const {
  if (!(max_fps > 0.0 && max_fps <= 1000.0)) {
    return InvalidArgumentError("render loop: max_fps must be in (0, 1000]");
  }
  if (floor_samples < 0) return InvalidArgumentError("render loop: floor_samples must be >= 0");
  if (max_prepared_masks < 0) {
    return InvalidArgumentError("render loop: max_prepared_masks must be >= 0");
  }
  return renderer.Check();
}

double TimelineView::MediaTimeAt(int64_t node_ns) const {
  if (!known) return 0.0;
  double t = media_time_s;
  if (playing) {
    t += rate * 1e-9 *
         static_cast<double>(node_ns + coordinator_minus_node_ns - anchor_coordinator_ns);
  }
  return std::clamp(t, 0.0, std::max(0.0, duration_s));
}

Scene RenderLoop::SceneFor(const Scene* model, const UnitCalibration& calibration) {
  if (model && model->NumTriangles() > 0 && calibration.table_from_model) {
    return MovedScene(*model, *calibration.table_from_model);
  }
  // No placement: the table plane alone, so patterns, strokes and the blend still have a
  // surface: 3 x 3 m about the origin, grown to hold the projector's footprint on it (a site
  // wider than 3 m: grid-12's outer projectors lit nothing and blended to black).
  Eigen::AlignedBox2d area(Eigen::Vector2d(-1.5, -1.5), Eigen::Vector2d(1.5, 1.5));
  if (calibration.table_from_projector) {
    const Rigid3d& table_from_projector = *calibration.table_from_projector;
    const Eigen::Vector3d centre = table_from_projector.translation;
    const Eigen::Matrix3d rotation = table_from_projector.RotationMatrix();
    const CameraModel& projector = calibration.projector;
    constexpr int kSteps = 4;  // a 5 x 5 grid of pixels, corners and edges included
    constexpr double kMaxSide_m = 50.0;
    for (int j = 0; j <= kSteps; ++j) {
      for (int i = 0; i <= kSteps; ++i) {
        const Eigen::Vector2d pixel(-0.5 + projector.width_px * i / static_cast<double>(kSteps),
                                    -0.5 + projector.height_px * j / static_cast<double>(kSteps));
        Expected<Eigen::Vector3d> ray = projector.Unproject(pixel);
        if (!ray.ok()) continue;
        const Eigen::Vector3d direction = rotation * *ray;
        if (!(direction.z() < -1e-9)) continue;  // never meets the table
        const Eigen::Vector3d hit = centre - centre.z() / direction.z() * direction;
        if (hit.head<2>().cwiseAbs().maxCoeff() < 0.5 * kMaxSide_m) area.extend(hit.head<2>());
      }
    }
  }
  const Eigen::Vector2d size = 1.05 * area.sizes();
  Scene plane = MovedScene(MakeRectangleMesh(size, 0),
                           Rigid3d(Eigen::Quaterniond::Identity(),
                                   Eigen::Vector3d(area.center().x(), area.center().y(), 0.0)));
  plane.materials.resize(1);
  plane.materials[0].name = "table";
  return plane;
}

Expected<std::unique_ptr<RenderLoop>> RenderLoop::Start(
    ProjectorOutput* projector, std::shared_ptr<const Scene> model,
    const RenderLoopOptions& options, std::shared_ptr<const cluster::PersonnelTracks> tracks) {
  ST_RETURN_IF_ERROR(options.Check());
  std::unique_ptr<RenderLoop> loop(
      new RenderLoop(projector, std::move(model), options, std::move(tracks)));
  std::promise<Status> started;
  std::future<Status> result = started.get_future();
  loop->thread_ = std::thread([raw = loop.get(), &started] { raw->Run(&started); });
  Status status = result.get();
  if (!status.ok()) {
    loop->thread_.join();
    return status;
  }
  return loop;
}

RenderLoop::~RenderLoop() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  changed_.notify_all();
  if (thread_.joinable()) thread_.join();
}

void RenderLoop::SetInputs(ShowInputs inputs) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const bool overlay_only = inputs.pattern == inputs_.pattern &&
                              inputs.projector_id == inputs_.projector_id &&
                              inputs.tracks == inputs_.tracks && inputs.sun == inputs_.sun &&
                              inputs.timeline_known == inputs_.timeline_known;
    inputs_ = std::move(inputs);
    ++inputs_version_;
    if (!overlay_only) ++frame_inputs_version_;
  }
  changed_.notify_all();
}

void RenderLoop::SetTimeline(const TimelineView& timeline) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const bool changed =
        timeline.known != timeline_.known || timeline.playing != timeline_.playing ||
        timeline.media_time_s != timeline_.media_time_s || timeline.rate != timeline_.rate;
    timeline_ = timeline;
    if (changed) {
      ++inputs_version_;
      ++frame_inputs_version_;
    }
  }
  changed_.notify_all();
}

Status RenderLoop::ShowCalibration(const UnitCalibration& calibration,
                                   std::chrono::milliseconds timeout) {
  if (!calibration.table_from_projector) {
    return InvalidArgumentError("render: the calibration has no table_from_projector");
  }
  Scene scene = SceneFor(model_.get(), calibration);
  Expected<ProjectorView> view = PrepareProjectorView(
      calibration.projector, calibration.table_from_projector->Inverse(), scene.Bounds());
  if (!view.ok()) return view.status();
  if (view->projector.width_px != projector_->size().width ||
      view->projector.height_px != projector_->size().height) {
    return InvalidArgumentError(
        "render: the calibration's projector is " + std::to_string(view->projector.width_px) + "x" +
        std::to_string(view->projector.height_px) + " px, the output " +
        std::to_string(projector_->size().width) + "x" + std::to_string(projector_->size().height));
  }
  // The traces lie on the model where this calibration places it, from the first frame on.
  std::shared_ptr<const std::vector<DrapedTrack>> draped;
  if (tracks_)
    draped = std::make_shared<const std::vector<DrapedTrack>>(DrapeTracks(*tracks_, &scene));
  uint64_t generation = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    pending_view_ = std::move(*view);
    pending_scene_ = std::move(scene);
    pending_tracks_ = std::move(draped);
    display_gamma_ = calibration.projector_response ? calibration.projector_response->gamma
                                                    : options_.renderer.display_gamma;
    suspended_ = false;
    // The blend belongs to the calibration it was computed with.
    DropStandby();
    if (!blend_factor_.empty()) {
      blend_factor_.release();
      blend_lift_.release();
      pending_mask_ = ComposedMask();
      pending_prepared_.reset();
      mask_posted_ = Clock::now();
    }
    generation = ++generation_;
    summary_.calibrated = true;
  }
  changed_.notify_all();
  return WaitForShown(generation, timeout);
}

namespace {

// A join's blanking times the blend (factor, lift): the mask the renderer takes.
cv::Mat ComposeMask(const cv::Mat& blank_factor, const cv::Mat& blend_factor,
                    const cv::Mat& blend_lift) {
  cv::Mat factor, lift;
  if (blank_factor.empty()) {
    factor = blend_factor.clone();
    lift = blend_lift.clone();
  } else if (blend_factor.empty() || blend_factor.size() != blank_factor.size()) {
    return blank_factor.clone();
  } else {
    factor = blank_factor.mul(blend_factor);
    if (!blend_lift.empty()) lift = blank_factor.mul(blend_lift);  // blanked: no light at all
  }
  if (factor.empty() || lift.empty()) return factor;
  cv::Mat both;
  cv::merge(std::vector<cv::Mat>{factor, lift}, both);
  return both;
}

}  // namespace

cv::Mat RenderLoop::ComposedMask() const {
  return ComposeMask(blank_factor_, blend_factor_, blend_lift_);
}

Status RenderLoop::ShowMask(const cv::Mat& mask, std::chrono::milliseconds timeout) {
  uint64_t generation = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (mask.empty()) {
      blank_factor_.release();
    } else if (mask.type() == CV_8UC1) {
      mask.convertTo(blank_factor_, CV_32FC1, 1.0 / 255.0);
    } else {
      blank_factor_ = mask.clone();
    }
    DropStandby();  // composed with the blanking before
    PostMask();
    generation = generation_;
  }
  changed_.notify_all();
  return WaitForShown(generation, timeout);
}

void RenderLoop::DropStandby() {
  if (standby_.empty()) return;
  standby_.clear();
  ++standby_version_;
}

void RenderLoop::PostMask() {
  pending_mask_ = ComposedMask();
  pending_prepared_.reset();
  mask_posted_ = Clock::now();
  ++generation_;
}

namespace {

// Byte for byte (both empty: equal).
bool SameMat(const cv::Mat& a, const cv::Mat& b) {
  if (a.empty() || b.empty()) return a.empty() && b.empty();
  if (a.size() != b.size() || a.type() != b.type() || !a.isContinuous() || !b.isContinuous()) {
    return false;
  }
  return std::memcmp(a.data, b.data, a.total() * a.elemSize()) == 0;
}

}  // namespace

void RenderLoop::PrepareBlends(uint64_t generation,
                               std::map<NodeId, std::pair<cv::Mat, cv::Mat>> masks) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (generation != blend_generation_ || blend_factor_.empty()) return;  // a newer blend
    standby_ = std::move(masks);
    ++standby_version_;
  }
  changed_.notify_all();
}

bool RenderLoop::ShowPreparedBlend(NodeId left, uint64_t* generation) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = standby_.find(left);
    if (it == standby_.end()) return false;
    blend_factor_ = it->second.first;
    blend_lift_ = it->second.second;
    const uint64_t version = standby_version_;
    DropStandby();  // made for the blend before this one
    PostMask();
    pending_prepared_ = PreparedKey{left, version};
    blend_generation_ = generation_;
    if (generation) *generation = generation_;
  }
  changed_.notify_all();
  return true;
}

Expected<int64_t> RenderLoop::ShowBlend(const cv::Mat& factor, const cv::Mat& lift,
                                        std::chrono::milliseconds timeout,
                                        uint64_t* generation_out) {
  if (!factor.empty() && factor.type() != CV_32FC1) {
    return InvalidArgumentError("render: a blend factor must be CV_32FC1");
  }
  if (!lift.empty() && (lift.type() != CV_32FC1 || lift.size() != factor.size())) {
    return InvalidArgumentError("render: a black-level lift must be CV_32FC1 of the factor's size");
  }
  // The blend already shown (a re-blend whose prepared mask went first): nothing to post. The
  // comparison runs outside the lock on the shown blend's buffers (never written in place).
  cv::Mat shown_factor, shown_lift;
  uint64_t shown_generation = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    shown_factor = blend_factor_;
    shown_lift = blend_lift_;
    shown_generation = blend_generation_;
  }
  const bool same = !factor.empty() && SameMat(factor, shown_factor) && SameMat(lift, shown_lift);
  uint64_t generation = 0;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (same && blend_generation_ == shown_generation && !blend_factor_.empty()) {
      generation = shown_generation;
    } else {
      blend_factor_ = factor.clone();
      blend_lift_ = lift.clone();
      DropStandby();
      PostMask();
      generation = blend_generation_ = generation_;
    }
  }
  if (generation_out) *generation_out = generation;
  changed_.notify_all();
  ST_RETURN_IF_ERROR(WaitForShown(generation, timeout));
  std::lock_guard<std::mutex> lock(mutex_);
  if (last_mask_frame_.generation == generation) return last_mask_frame_.shown_ns;
  return last_shown_ns_;
}

bool RenderLoop::MaskPending() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return pending_mask_.has_value();
}

MaskFrameTimes RenderLoop::LastMaskFrame() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return last_mask_frame_;
}

Status RenderLoop::WaitForShown(uint64_t generation, std::chrono::milliseconds timeout) {
  std::unique_lock<std::mutex> lock(mutex_);
  // Suspended (calibration has the projector), nothing is shown until it resumes: a caller on
  // the node's worker must not hold it for the timeout meanwhile (the round's own steps wait
  // behind it). What was posted is shown once the loop resumes.
  if (!shown_cv_.wait_for(lock, timeout,
                          [&] { return shown_generation_ >= generation || stop_ || suspended_; })) {
    return UnavailableError("render: no frame shown within " + std::to_string(timeout.count()) +
                            " ms");
  }
  if (shown_generation_ < generation && suspended_) {
    return UnavailableError(
        "render: suspended while the projector calibrates; shown once it resumes");
  }
  return OkStatus();
}

void RenderLoop::Suspend() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    suspended_ = true;
  }
  shown_cv_.notify_all();  // a wait for a frame ends: none comes while suspended
  std::lock_guard<std::mutex> showing(show_mutex_);  // a frame being shown finishes first
}

void RenderLoop::Resume() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    suspended_ = false;
    ++inputs_version_;
    ++frame_inputs_version_;
  }
  changed_.notify_all();
}

RenderSummary RenderLoop::Summary() const {
  std::lock_guard<std::mutex> lock(mutex_);
  RenderSummary s = summary_;
  s.frame_ms_p50 = Percentile(frame_ms_, 0.5);
  s.frame_ms_p99 = Percentile(frame_ms_, 0.99);
  s.show_ms_p50 = Percentile(show_ms_, 0.5);
  return s;
}

std::pair<uint64_t, std::string> RenderLoop::ShownPattern() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return {summary_.frames_shown, summary_.pattern};
}

// What only the render thread touches: the renderer, what it drew last, the masks it holds.
struct RenderLoop::ThreadState {
  GlContext* context = nullptr;
  WindowProjectorOutput* window = nullptr;  // drawing into this window's back buffer
  std::unique_ptr<Renderer> renderer;
  uint64_t drawn_version = ~uint64_t{0}, drawn_frame_version = ~uint64_t{0};
  double drawn_media_time_s = 0.0;  // of the frame last drawn
  Clock::time_point last_frame{};
  Clock::time_point last_flush = Clock::now();
  std::ofstream log;  // options_.frame_log_path
  // Prepared masks (PrepareBlends) in the renderer: of standby set `prepared_version`, these
  // neighbours'; `prepared_complete` once every one the set holds (up to the limit) is.
  uint64_t prepared_version = ~uint64_t{0};
  std::set<NodeId> prepared_keys;
  bool prepared_complete = true;
};

// One frame: its inputs, taken under the lock, and what drawing and showing it gave.
struct RenderLoop::FrameWork {
  ShowInputs inputs;
  TimelineView timeline;
  uint64_t version = 0, frame_version = 0, generation = 0;
  std::optional<ProjectorView> view;
  std::optional<Scene> scene;
  std::optional<cv::Mat> mask;
  std::optional<PreparedKey> prepared;  // mask is the one prepared for this neighbour
  MaskFrameTimes mask_frame;
  Status status = OkStatus();
  bool rewarp = false;  // the last frame again under a new mask (the warp pass alone)
  int64_t draw_ns = 0;
  double media_time_s = 0.0;
  std::optional<FrameStats> late_stats;  // a late mask's rewarp over the frame just drawn
  bool shown = false, unchanged = false;
  double show_ms = 0.0;
};

void RenderLoop::PublishPrepared(const ThreadState& t) {
  std::lock_guard<std::mutex> lock(mutex_);
  summary_.masks_prepared = static_cast<int>(t.prepared_keys.size());
}

void RenderLoop::ForgetPrepared(ThreadState& t) {
  t.prepared_keys.clear();
  t.prepared_version = ~uint64_t{0};
  t.prepared_complete = false;
  PublishPrepared(t);
}

// One mask a call is prepared, so a mask that comes meanwhile waits for one upload at most.
void RenderLoop::PrepareStandby(ThreadState& t) {
  if (!t.renderer || !t.renderer->has_view()) return;
  std::pair<cv::Mat, cv::Mat> next;
  NodeId key = kInvalidNodeId;
  cv::Mat blank;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (pending_mask_ || pending_view_ || stop_) return;
    if (standby_version_ != t.prepared_version) {
      t.renderer->ClearPreparedMasks();
      t.prepared_keys.clear();
      t.prepared_version = standby_version_;
      summary_.masks_prepared = 0;
    }
    t.prepared_complete = true;
    if (static_cast<int>(t.prepared_keys.size()) >= options_.max_prepared_masks) return;
    for (const auto& [left, masks] : standby_) {
      if (t.prepared_keys.count(left)) continue;
      key = left;
      next = masks;
      break;
    }
    if (key == kInvalidNodeId) return;
    blank = blank_factor_;
    t.prepared_complete = false;
  }
  const cv::Mat mask = ComposeMask(blank, next.first, next.second);
  if (Status done = t.renderer->PrepareMask(key, mask); !done.ok()) {
    ST_LOG(kWarning) << "render: " << done.ToString();
    t.prepared_complete = true;  // not tried again for this set
    return;
  }
  t.prepared_keys.insert(key);
  PublishPrepared(t);
}

RenderLoop::Taken RenderLoop::TakeWork(ThreadState& t, FrameWork* work) {
  {
    std::unique_lock<std::mutex> lock(mutex_);
    changed_.wait_for(lock, std::chrono::milliseconds(20), [&] {
      return stop_ ||
             (!suspended_ &&
              (pending_view_ || pending_mask_ ||
               (t.renderer && (inputs_version_ != t.drawn_version || timeline_.playing ||
                               (t.renderer->has_view() && (standby_version_ != t.prepared_version ||
                                                           !t.prepared_complete))))));
    });
    if (stop_) return Taken::kStop;
    if (suspended_ || (!pending_view_ && !t.renderer)) return Taken::kNothing;
    if (pending_view_) draped_tracks_ = std::move(pending_tracks_);
    work->view = std::move(pending_view_);
    work->scene = std::move(pending_scene_);
    work->mask = std::move(pending_mask_);
    work->prepared = pending_prepared_;
    pending_view_.reset();
    pending_scene_.reset();
    pending_mask_.reset();
    pending_prepared_.reset();
    work->inputs = inputs_;
    if (draped_tracks_) work->inputs.tracks = draped_tracks_;
    work->timeline = timeline_;
    work->version = inputs_version_;
    work->frame_version = frame_inputs_version_;
    work->generation = generation_;
    if (!work->view && !work->mask && work->version == t.drawn_version && !work->timeline.playing) {
      return Taken::kIdle;
    }
    if (work->mask) work->mask_frame.wait_ms = MsBetween(mask_posted_, Clock::now());
  }
  // At most max_fps; a new mask (a re-blend after a neighbour left) is not held back.
  const auto period = std::chrono::duration<double>(1.0 / options_.max_fps);
  const Clock::time_point next = t.last_frame + std::chrono::duration_cast<Clock::duration>(period);
  if (!work->mask && Clock::now() < next) {
    // Until the next frame is due, or a new mask comes (taken at once, not after this frame).
    std::unique_lock<std::mutex> lock(mutex_);
    if (changed_.wait_until(lock, next, [&] { return stop_ || pending_mask_.has_value(); })) {
      if (stop_) return Taken::kStop;
      work->mask = std::move(pending_mask_);
      work->prepared = pending_prepared_;
      pending_mask_.reset();
      pending_prepared_.reset();
      work->generation = generation_;
      work->mask_frame.wait_ms = MsBetween(mask_posted_, Clock::now());
    }
  }
  return Taken::kFrame;
}

bool RenderLoop::MakeRenderer(ThreadState& t, const Scene& scene) {
  RendererOptions renderer_options = options_.renderer;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (display_gamma_ > 0) renderer_options.display_gamma = display_gamma_;
  }
  Expected<std::unique_ptr<Renderer>> made = Renderer::Create(t.context, scene, renderer_options);
  if (!made.ok()) {
    ST_LOG(kError) << "render: " << made.status().ToString();
    std::lock_guard<std::mutex> lock(mutex_);
    ++summary_.frames_failed;
    return false;
  }
  t.renderer = std::move(*made);
  ForgetPrepared(t);
  if (options_.floor_samples > 0) {
    std::vector<double> floor;
    for (int i = 0; i < options_.floor_samples; ++i) {
      Expected<double> ms = t.renderer->RenderFloor();
      if (ms.ok()) floor.push_back(*ms);
    }
    std::lock_guard<std::mutex> lock(mutex_);
    summary_.floor_ms = Percentile(std::deque<double>(floor.begin(), floor.end()), 0.5);
  }
  return true;
}

// A new mask into the renderer (timed) and kept as the current one: the one prepared for it
// swapped in when the renderer holds it, else encoded and uploaded.
void RenderLoop::SetMask(ThreadState& t, FrameWork& work, const cv::Mat& mask) {
  if (work.status.ok()) {
    const Clock::time_point t0 = Clock::now();
    const std::optional<PreparedKey>& key = work.prepared;
    const bool ready =
        key && key->version == t.prepared_version && t.prepared_keys.count(key->left) > 0;
    work.mask_frame.prepared = ready && t.renderer->UseMask(key->left).ok();
    if (!work.mask_frame.prepared) work.status = t.renderer->SetMask(mask);
    work.mask_frame.set_mask_ms = MsBetween(t0, Clock::now());
    ForgetPrepared(t);
  }
  std::lock_guard<std::mutex> lock(mutex_);
  current_mask_ = mask;
}

Expected<FrameStats> RenderLoop::Draw(ThreadState& t, FrameWork& work) {
  // Only the mask changed (a re-blend, a join's blanking), or the overlay besides (strokes
  // being painted): the frame already drawn goes out again under it, the warp pass alone,
  // instead of waiting for a whole frame; the new strokes follow in the next frame, drawn as
  // usual. Other new inputs (a pattern, the sun) are drawn whole: a caller of ShowBlend or
  // ShowMask expects what it set to show under the mask.
  work.rewarp = work.status.ok() && work.mask && !work.view && !work.scene &&
                work.frame_version == t.drawn_frame_version && t.renderer->CanRewarp();
  work.draw_ns = NowNs();
  work.media_time_s = work.rewarp ? t.drawn_media_time_s : work.timeline.MediaTimeAt(work.draw_ns);
  Expected<FrameStats> stats =
      !work.status.ok() ? Expected<FrameStats>(work.status)
      : work.rewarp     ? t.renderer->Rewarp()
                        : t.renderer->Render(BuildContent(work.inputs, work.media_time_s));
  if (stats.ok()) t.drawn_media_time_s = work.media_time_s;
  if (work.rewarp || !stats.ok()) return stats;
  // A new mask that came while this whole frame was drawn (a re-blend after a neighbour left):
  // the frame does not go out under the old mask first (its read back and show, 10-20 ms
  // on a loaded machine); the new mask goes over it at once, as a rewarp.
  if (options_.after_render_for_test) options_.after_render_for_test();
  std::optional<cv::Mat> late;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (pending_mask_ && !pending_view_ && !pending_scene_ && t.renderer->CanRewarp()) {
      late = std::move(pending_mask_);
      work.prepared = pending_prepared_;
      pending_mask_.reset();
      pending_prepared_.reset();
      work.generation = generation_;
      work.mask_frame = MaskFrameTimes{};
      work.mask_frame.wait_ms = MsBetween(mask_posted_, Clock::now());
    }
  }
  if (!late) return stats;
  SetMask(t, work, *late);
  Expected<FrameStats> again =
      work.status.ok() ? t.renderer->Rewarp() : Expected<FrameStats>(work.status);
  if (again.ok()) {
    work.late_stats = *again;
  } else {
    stats = again.status();
  }
  work.mask = std::move(late);
  work.mask_frame.late = true;
  return stats;
}

// The frame in the window's back buffer swapped in (no read back), unless calibration has the
// projector: it then draws its own frames over it.
bool RenderLoop::Suspended() const {
  std::lock_guard<std::mutex> lock(mutex_);
  return suspended_;
}

void RenderLoop::MarkDrawn(ThreadState& t, const FrameWork& work) {
  if (work.rewarp) return;
  t.last_frame = Clock::now();
  t.drawn_version = work.version;
  t.drawn_frame_version = work.frame_version;
}

void RenderLoop::PresentFrame(ThreadState& t, FrameWork& work, const Expected<FrameStats>& stats) {
  MarkDrawn(t, work);
  if (!stats.ok()) {
    work.status = stats.status();
    return;
  }
  const Clock::time_point show_start = Clock::now();
  std::lock_guard<std::mutex> showing(show_mutex_);
  last_shown_hash_.reset();
  if (!Suspended()) {
    Expected<ShownFrame> done = t.context->Present();
    if (done.ok()) {
      work.shown = true;
    } else {
      work.status = done.status();
    }
  }
  work.show_ms = MsBetween(show_start, Clock::now());
}

void RenderLoop::ShowFrame(ThreadState& t, FrameWork& work, const Expected<FrameStats>& stats) {
  if (t.window) {
    PresentFrame(t, work, stats);
    return;
  }
  const Clock::time_point read_start = Clock::now();
  Expected<cv::Mat> frame =
      stats.ok() ? t.context->ReadOutput() : Expected<cv::Mat>(stats.status());
  MarkDrawn(t, work);
  work.mask_frame.read_ms = MsBetween(read_start, Clock::now());
  const Clock::time_point show_start = Clock::now();
  if (frame.ok()) {
    std::lock_guard<std::mutex> showing(show_mutex_);
    const uint64_t hash = FrameHash(*frame);
    if (Suspended()) {
      last_shown_hash_.reset();  // calibration shows its own frames meanwhile
    } else if (last_shown_hash_ == hash) {
      work.shown = true;  // the projector already shows exactly this
      work.unchanged = true;
    } else {
      Expected<ShownFrame> done = projector_->Show(*frame);
      if (!done.ok()) {
        work.status = done.status();
        last_shown_hash_.reset();
      } else {
        work.shown = true;
        last_shown_hash_ = hash;
      }
    }
  } else {
    work.status = frame.status();
  }
  work.show_ms = MsBetween(show_start, Clock::now());
}

void RenderLoop::RecordFrame(FrameWork& work, const Expected<FrameStats>& stats) {
  std::lock_guard<std::mutex> lock(mutex_);
  if (!work.status.ok()) {
    ++summary_.frames_failed;
    ST_LOG(kWarning) << "render: frame not shown: " << work.status.ToString();
  }
  if (!work.shown) return;
  if (work.unchanged) {
    ++summary_.frames_unchanged;
  } else {
    ++summary_.frames_shown;
    // A re-warped frame is one pass, not a frame's work: kept out of the frame times.
    if (work.rewarp || work.late_stats) ++summary_.frames_rewarped;
    if (!work.rewarp) {
      if (!first_frame_kept_) {
        summary_.first_frame_ms = stats->frame_ms;  // compiles and caches: not a frame's cost
        first_frame_kept_ = true;
      } else {
        Keep(&frame_ms_, stats->frame_ms);
      }
    }
    Keep(&show_ms_, work.show_ms);
    for (int p = 0; p < kPassCount; ++p) summary_.pass_runs[p] += stats->ran[p] ? 1 : 0;
    summary_.groups_culled += static_cast<uint64_t>(stats->groups_culled);
  }
  summary_.pattern = TestPatternName(work.inputs.pattern);
  shown_generation_ = std::max(shown_generation_, work.generation);
  // The steady clock itself: the blend reports it to the lab, which compares it with its own.
  last_shown_ns_ =
      std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now().time_since_epoch()).count();
  if (work.mask) {
    work.mask_frame.generation = work.generation;
    work.mask_frame.render_ms = work.late_stats ? work.late_stats->frame_ms : stats->frame_ms;
    work.mask_frame.rewarped = work.rewarp || work.late_stats.has_value();
    work.mask_frame.show_ms = work.show_ms;
    work.mask_frame.shown_ns = last_shown_ns_;
    last_mask_frame_ = work.mask_frame;
  }
}

void RenderLoop::LogFrame(ThreadState& t, const FrameWork& work, const FrameStats& stats) {
  if (!t.log.is_open()) return;
  t.log << work.draw_ns << "," << work.media_time_s << "," << (work.timeline.playing ? 1 : 0) << ","
        << stats.frame_ms << "," << work.timeline.rate << "\n";
  if (Clock::now() - t.last_flush > std::chrono::seconds(1)) {
    t.log.flush();
    t.last_flush = Clock::now();
  }
}

// The render thread: takes what changed, draws it (a whole frame, or the last one again under a
// new mask), reads it back and shows it, and records the frame.
void RenderLoop::Run(std::promise<Status>* started) {
  // A window (a real projector): the frames are drawn into its back buffer and swapped, no read
  // back; anything else: a headless context, read back and shown.
  WindowProjectorOutput* window =
      options_.draw_into_window ? dynamic_cast<WindowProjectorOutput*>(projector_) : nullptr;
  Expected<std::unique_ptr<GlContext>> context = std::unique_ptr<GlContext>();
  if (window) {
    WindowProjectorOutput::ContextHold hold(window);
    context = CreateWindowContext(window);
  } else {
    context = CreateEglContext(projector_->size());
  }
  if (!context.ok()) {
    started->set_value(context.status().WithContext("render"));
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    summary_.context = (*context)->description();
  }
  started->set_value(OkStatus());
  ThreadState t;
  t.context = context->get();
  t.window = window;
  if (!options_.frame_log_path.empty()) {
    t.log.open(options_.frame_log_path);
    t.log << "node_steady_ns,media_time_s,playing,frame_ms,rate\n";
  }
  while (true) {
    FrameWork work;
    const Taken taken = TakeWork(t, &work);
    if (taken == Taken::kStop) break;
    if (taken == Taken::kNothing) continue;
    // The window's context is this thread's while it draws; calibration's Show() waits.
    std::optional<WindowProjectorOutput::ContextHold> hold;
    if (window) hold.emplace(window);
    if (taken == Taken::kIdle) PrepareStandby(t);
    if (taken != Taken::kFrame) continue;
    if (work.scene) {
      if (!MakeRenderer(t, *work.scene)) continue;
      // A new renderer starts without a mask: the current one (the join's blanking) applies.
      std::lock_guard<std::mutex> lock(mutex_);
      if (!work.mask && !current_mask_.empty()) work.mask = current_mask_;
    }
    if (work.view) {
      work.status = t.renderer->SetView(*work.view);
      ForgetPrepared(t);
    }
    if (work.mask) SetMask(t, work, *work.mask);
    const Expected<FrameStats> stats = Draw(t, work);
    ShowFrame(t, work, stats);
    RecordFrame(work, stats);
    if (work.shown) shown_cv_.notify_all();
    PrepareStandby(t);  // while the timeline plays the loop is never idle
    if (work.shown && !work.unchanged) LogFrame(t, work, *stats);
  }
  std::optional<WindowProjectorOutput::ContextHold> hold;
  if (window) hold.emplace(window);
  t.renderer.reset();  // GL objects go while the context is current
}

}  // namespace sandtable::node
