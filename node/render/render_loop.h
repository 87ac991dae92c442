// RenderLoop: the node's renderer running continuously on its own thread (docs/render.md).
// It owns a headless GL context (EGL; Mesa's llvmpipe without a GPU), renders what the show puts
// on the model (show_content.h) at each frame's media time, reads the frame back and gives it to
// the node's projector through ProjectorOutput (the world, or a window), so any projector the
// node drives shows it.
//
// Frames are drawn only when something changed: the calibration or mask, the inputs (pattern,
// strokes, cursor), or the media time while the timeline plays; a static show costs nothing
// after its first frame. At most max_fps frames a second. A drawn frame equal (byte for byte,
// by a 64-bit hash) to the one the projector shows is not sent again.
//
// Calibration and masks swap in between frames: ShowCalibration prepares the projector view
// (the distortion map, ~0.1 s) on the calling thread, hands it over and waits until a frame
// drawn with it is shown. Self-calibration takes the projector with Suspend() (returns once no
// frame is being shown; none is until the next ShowCalibration or Resume).
//
// Media time: the timeline clock the coordinator publishes, converted to this node's steady
// clock with the node's offset estimate, evaluated at the moment the frame is drawn; every
// shown frame's (steady time, media time) goes to frame_log_path when set (the lab's skew).
// Threading: every public method may be called from any thread.
#pragma once

#include <array>
#include <chrono>
#include <condition_variable>
#include <cstdint>
#include <deque>
#include <fstream>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>

#include "common/base/ids.h"
#include "common/io/unit_calibration_file.h"
#include "common/scene/scene.h"
#include "node/devices/projector_output.h"
#include "node/render/renderer.h"
#include "node/render/show_content.h"

namespace sandtable::node {

struct RenderLoopOptions {
  double max_fps = 30.0;
  RendererOptions renderer;
  std::string frame_log_path;  // CSV of shown frames (empty: none)
  int floor_samples = 30;      // full-screen passes timed once at start (the floor)
  // Tests: called on the render thread after each whole frame is drawn, before the loop looks
  // for a mask that came meanwhile (may block: a slow frame).
  std::function<void()> after_render_for_test;
  // Prepared masks kept in the renderer (PrepareBlends): one texture of the output's size each.
  int max_prepared_masks = 8;
  // When the projector is a window (node/devices/window_projector_output.h), the renderer draws
  // into its back buffer and swaps it: no read back, no second upload. False: a headless
  // context whose frames are read back and shown like any projector's (for comparison).
  bool draw_into_window = true;
  Status Check() const;
};

// The coordinator's timeline as this node sees it.
struct TimelineView {
  bool known = false;
  double media_time_s = 0.0;  // at anchor_coordinator_ns
  double rate = 0.0;
  bool playing = false;
  int64_t anchor_coordinator_ns = 0;
  double duration_s = 0.0;
  int64_t coordinator_minus_node_ns = 0;  // the node's clock offset estimate
  // Media time at node steady time `node_ns` (clamped to [0, duration]).
  double MediaTimeAt(int64_t node_ns) const;
};

struct RenderSummary {
  std::string context;  // the GL context's description
  uint64_t frames_shown = 0;
  uint64_t frames_failed = 0;     // render or show errors (logged)
  uint64_t frames_unchanged = 0;  // drawn, equal to what the projector shows: not sent again
  uint64_t frames_rewarped = 0;   // a new mask over the last frame (Renderer::Rewarp)
  int masks_prepared = 0;         // prepared masks the renderer holds now (PrepareBlends)
  double frame_ms_p50 = 0.0, frame_ms_p99 = 0.0;  // rendering, GL work finished
  // The first frame drawn (shaders compiled, surface cache filled): kept out of the percentiles.
  double first_frame_ms = 0.0;
  double show_ms_p50 = 0.0;  // read back and projector's Show
  double floor_ms = 0.0;     // one full-screen textured pass (median)
  std::array<uint64_t, kPassCount> pass_runs{};
  uint64_t groups_culled = 0;
  std::string pattern = "none";
  bool calibrated = false;
};

// Where the time went for the first frame drawn with a new mask (a re-blend's frame), ms:
// from the mask's hand-over to the render thread taking it (a frame in progress finishes
// first), its upload (Renderer::SetMask), the frame's passes (only the warp pass when the
// frame already drawn was re-warped under the new mask), the read back, the projector's Show.
struct MaskFrameTimes {
  uint64_t generation = 0;  // 0: no mask frame shown yet
  double wait_ms = 0.0, set_mask_ms = 0.0, render_ms = 0.0, read_ms = 0.0, show_ms = 0.0;
  bool rewarped = false;  // the last frame under the new mask (the warp pass alone)
  // The mask came while a whole frame was being drawn: that frame went out under it (rewarped)
  // instead of first under the old mask.
  bool late = false;
  // The mask was one prepared ahead of time (PrepareBlends): swapped in, not uploaded.
  bool prepared = false;
  int64_t shown_ns = 0;  // steady time the frame was shown
};

class RenderLoop {
 public:
  // `projector` outlives the loop. `model`: the glTF model in its own frame (placed with each
  // calibration's table_from_model; without a placement only a table plane is drawn); may be
  // null. `tracks` (may be null): the personnel tracks, draped on the placed model with each
  // calibration before its first frame (show_content.h). UNAVAILABLE when no GL context can be
  // made.
  static Expected<std::unique_ptr<RenderLoop>> Start(
      ProjectorOutput* projector, std::shared_ptr<const Scene> model,
      const RenderLoopOptions& options,
      std::shared_ptr<const cluster::PersonnelTracks> tracks = nullptr);
  ~RenderLoop();
  RenderLoop(const RenderLoop&) = delete;
  RenderLoop& operator=(const RenderLoop&) = delete;

  void SetInputs(ShowInputs inputs);
  void SetTimeline(const TimelineView& timeline);

  // Swaps the calibration in, resumes, and waits (up to `timeout`) until a frame drawn with it
  // is shown. A measured projector response (calibration.projector_response) sets the gamma
  // the frames are encoded with. Errors: the calibration's (no table_from_projector, a projector of
  // another size), UNAVAILABLE when no frame was shown in time.
  Status ShowCalibration(const UnitCalibration& calibration,
                         std::chrono::milliseconds timeout = std::chrono::seconds(10));
  // Multiplies the frame by `mask` (renderer.h SetMask; empty: none; a join's blanking) and
  // waits until it is shown.
  Status ShowMask(const cv::Mat& mask,
                  std::chrono::milliseconds timeout = std::chrono::seconds(10));
  // The blend factor (node/blend: alpha x intensity correction, CV_32FC1 linear; empty: none),
  // multiplied with ShowMask's; waits until a frame drawn with it is shown (not held back by
  // max_fps) and returns that frame's steady time (ns). A new calibration drops it. `lift`
  // (CV_32FC1 of the same size, linear; empty: none): the black-level lift added after it
  // (renderer.h SetMask), blanked with it.
  // A factor and lift equal to the blend already shown change nothing: it waits for the frame
  // that showed them and returns that frame's time. `generation` (may be null): the blend's, for
  // PrepareBlends. ShowMask and ShowBlend answer UNAVAILABLE at once while the loop is
  // suspended (Suspend: calibration has the projector), and the mask is shown once it resumes.
  Expected<int64_t> ShowBlend(const cv::Mat& factor, const cv::Mat& lift = cv::Mat(),
                              std::chrono::milliseconds timeout = std::chrono::seconds(10),
                              uint64_t* generation = nullptr);
  // Prepared masks (docs/blend.md, "Prepared masks"): per neighbour, the factor and lift the
  // blend shown (`generation`, from ShowBlend; an older one is dropped) becomes if that
  // neighbour leaves. The render thread encodes and uploads them between frames
  // (Renderer::PrepareMask, at most options.max_prepared_masks). ShowPreparedBlend(left) then
  // posts the one for `left` without waiting and returns false when there is none: its frame
  // swaps the mask in (no compose, no upload: MaskFrameTimes::prepared) and goes out as a rewarp.
  // Any other new mask, blanking or calibration drops them.
  void PrepareBlends(uint64_t generation, std::map<NodeId, std::pair<cv::Mat, cv::Mat>> masks);
  bool ShowPreparedBlend(NodeId left, uint64_t* generation = nullptr);
  // The times of the last frame shown with a new mask (ShowMask, ShowBlend).
  MaskFrameTimes LastMaskFrame() const;
  // A mask (ShowBlend, ShowMask) waits for the render thread to take it.
  bool MaskPending() const;
  void Suspend();
  void Resume();

  RenderSummary Summary() const;  // with percentiles over the kept frames (not per step)
  // Frames shown and the last shown frame's pattern, cheaply (the service polls it every step).
  std::pair<uint64_t, std::string> ShownPattern() const;
  // The scene the loop draws for `calibration` (the model placed, or a table plane holding
  // 3 x 3 m about the origin and the projector's footprint).
  static Scene SceneFor(const Scene* model, const UnitCalibration& calibration);

 private:
  RenderLoop(ProjectorOutput* projector, std::shared_ptr<const Scene> model,
             const RenderLoopOptions& options,
             std::shared_ptr<const cluster::PersonnelTracks> tracks)
      : projector_(projector),
        model_(std::move(model)),
        tracks_(std::move(tracks)),
        options_(options) {}
  // The render thread (render_loop.cc): its own state, one frame's work, and Run's steps.
  struct ThreadState;
  struct FrameWork;
  enum class Taken { kStop, kNothing, kIdle, kFrame };
  void Run(std::promise<Status>* started);
  Taken TakeWork(ThreadState& t, FrameWork* work);
  bool MakeRenderer(ThreadState& t, const Scene& scene);  // false: logged, counted as failed
  void SetMask(ThreadState& t, FrameWork& work, const cv::Mat& mask);
  Expected<FrameStats> Draw(ThreadState& t, FrameWork& work);
  void ShowFrame(ThreadState& t, FrameWork& work, const Expected<FrameStats>& stats);
  void PresentFrame(ThreadState& t, FrameWork& work, const Expected<FrameStats>& stats);
  // The frame's inputs as drawn, and when (not for a re-warp of the last frame).
  void MarkDrawn(ThreadState& t, const FrameWork& work);
  bool Suspended() const;  // under mutex_
  void RecordFrame(FrameWork& work, const Expected<FrameStats>& stats);
  void LogFrame(ThreadState& t, const FrameWork& work, const FrameStats& stats);
  void PrepareStandby(ThreadState& t);
  void ForgetPrepared(ThreadState& t);
  void PublishPrepared(const ThreadState& t);
  Status WaitForShown(uint64_t generation, std::chrono::milliseconds timeout);

  ProjectorOutput* projector_;
  std::shared_ptr<const Scene> model_;
  std::shared_ptr<const cluster::PersonnelTracks> tracks_;
  RenderLoopOptions options_;
  std::thread thread_;

  mutable std::mutex mutex_;
  std::condition_variable changed_;   // to the render thread
  std::condition_variable shown_cv_;  // to waiters
  bool stop_ = false;
  bool suspended_ = false;
  uint64_t generation_ = 0;        // bumped by every change a waiter waits for
  uint64_t shown_generation_ = 0;  // the generation of the last shown frame
  ShowInputs inputs_;
  uint64_t inputs_version_ = 0;
  // Bumped by every change of the inputs but the overlay's (strokes, cursor): what a frame
  // re-warped under a new mask may not leave out (a pattern, the sun, the timeline); new strokes
  // follow in the next whole frame.
  uint64_t frame_inputs_version_ = 0;
  TimelineView timeline_;
  std::optional<ProjectorView> pending_view_;
  std::optional<Scene> pending_scene_;
  // The display gamma of the calibration shown (its measured projector response; else
  // options_.renderer's): the renderer is made with it.
  double display_gamma_ = 0.0;
  std::shared_ptr<const std::vector<DrapedTrack>> pending_tracks_, draped_tracks_;
  std::optional<cv::Mat> pending_mask_;
  // pending_mask_ is the one prepared for this neighbour in this set (standby_version_).
  struct PreparedKey {
    NodeId left = kInvalidNodeId;
    uint64_t version = 0;
  };
  std::optional<PreparedKey> pending_prepared_;
  std::chrono::steady_clock::time_point mask_posted_;  // when pending_mask_ was set
  uint64_t blend_generation_ = 0;  // the generation at which blend_factor_ was posted
  // PrepareBlends' masks for the current blend, by the neighbour whose leaving they are for.
  std::map<NodeId, std::pair<cv::Mat, cv::Mat>> standby_;
  uint64_t standby_version_ = 0;  // bumped whenever standby_ is replaced or dropped
  void DropStandby();             // under mutex_
  void PostMask();                // under mutex_: pending_mask_ = ComposedMask(), a new generation
  MaskFrameTimes last_mask_frame_;
  cv::Mat blank_factor_, blend_factor_,
      blend_lift_;                           // CV_32FC1 or empty; their product is the mask
  cv::Mat current_mask_;                     // the composed mask (re-applied to a new renderer)
  int64_t last_shown_ns_ = 0;                // steady time of the last shown frame
  cv::Mat ComposedMask() const;              // under mutex_
  std::mutex show_mutex_;                    // held while a frame is given to the projector
  std::optional<uint64_t> last_shown_hash_;  // render thread only

  // Stats (under mutex_).
  RenderSummary summary_;
  std::deque<double> frame_ms_, show_ms_;
  bool first_frame_kept_ = false;  // summary_.first_frame_ms holds the first frame's time
};

}  // namespace sandtable::node
