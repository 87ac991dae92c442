// The unit's side of the cluster's self-calibration (self_calibration_service.h): it serves
// the steps a round's runner sends (SHOW, RESPONSE, CAPTURE, DECODE, LOCAL, BLANK), checks a
// saved calibration, takes the round's result and shows the calibration it holds. Internal to
// node/app; the service owns it and routes its messages.
#pragma once

#include <chrono>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include <opencv2/core.hpp>

#include "node/app/calibration_link.h"
#include "node/app/self_calibration_service.h"

namespace sandtable::node {

class CalibrationUnit {
 public:
  // `projector` is not owned and must outlive the unit; `options`, `link` and `ledger` are the
  // service's.
  CalibrationUnit(UnitCalibration factory, ProjectorOutput* projector,
                  std::shared_ptr<const Scene> model, const SelfCalibrationOptions& options,
                  CalibrationLink* link, CalibrationLedger* ledger,
                  SelfCalibrationService::OnCalibrated on_calibrated,
                  SelfCalibrationService::OnFailed on_failed);

  void SetCamera(std::unique_ptr<CameraInput> camera) {
    camera_ = std::make_unique<PacedCamera>(std::move(camera));
  }
  void SetRenderLoop(RenderLoop* loop) { render_loop_ = loop; }
  void SetSavedCalibration(UnitCalibration saved,
                           SelfCalibrationService::OnVerification on_verification);

  // Messages for this side (the service routes them).
  void HandleStep(const wire::CalibrationStep& step, NodeId from, NodeRuntime& node);
  void HandleCorrespondences(const wire::CorrespondenceSet& set);
  void HandleResult(const wire::CalibrationResult& result, NodeId from, NodeRuntime& node);
  // Every step of the node: deferred steps, and the saved calibration's check when its turn
  // comes.
  void OnStep(NodeRuntime& node);

  // What the round policy reads of this unit.
  bool has_camera() const { return camera_ != nullptr; }
  bool calibrated() const { return calibrated_; }
  NodeId calibrated_by() const { return calibrated_by_; }  // the runner of its round
  // When another unit's round last sent this unit a step.
  std::optional<std::chrono::steady_clock::time_point> last_step_from_other() const {
    return last_step_from_other_;
  }
  // A round is calibrating this unit's projector (it measured its response, its result has not
  // come), and a step of it came within kRoundSilence.
  bool being_calibrated() const;

 private:
  // One function per action (HandleStep's switch); each answers `done` when the step is done.
  void StepShow(const wire::CalibrationStep& step, NodeId from, wire::CalibrationStepDone done,
                NodeRuntime& node);
  void StepResponse(const wire::CalibrationStep& step, NodeId from, wire::CalibrationStepDone done,
                    NodeRuntime& node);
  void StepCapture(const wire::CalibrationStep& step, NodeId from, wire::CalibrationStepDone done,
                   NodeRuntime& node);
  void StepDecode(const wire::CalibrationStep& step, NodeId from, wire::CalibrationStepDone done,
                  NodeRuntime& node);
  void StepBlank(const wire::CalibrationStep& step, NodeId from, wire::CalibrationStepDone done,
                 NodeRuntime& node);
  // Answers `done` as failed with `why` (logged).
  void FailStep(NodeId from, wire::CalibrationStepDone done, NodeRuntime& node,
                const std::string& why);
  void RunDeferred(NodeRuntime& node);
  void Answer(NodeId to, wire::CalibrationStepDone done, NodeRuntime& node);
  void RunLocal(const wire::CalibrationStep& step, NodeId from, NodeRuntime& node);
  const std::vector<cv::Mat>* PatternFrames(const wire::PatternPlan& plan);

  void MaybeVerify(NodeRuntime& node);
  // An outcome holding `calibration` with this node's compute and traffic so far.
  SelfCalibrationOutcome Outcome(const UnitCalibration& calibration) const;

  // Shows the display of `calibration` (on a worker), then runs `then`.
  void StartDisplay(const UnitCalibration& calibration, NodeRuntime& node,
                    std::function<void()> then);

  UnitCalibration factory_;
  ProjectorOutput* projector_;
  RenderLoop* render_loop_ = nullptr;
  std::unique_ptr<PacedCamera> camera_;  // captures paced to the devices' timing
  std::shared_ptr<const Scene> model_;
  const SelfCalibrationOptions& options_;
  CalibrationLink* link_;
  CalibrationLedger* ledger_;
  SelfCalibrationService::OnCalibrated on_calibrated_;
  SelfCalibrationService::OnFailed on_failed_;

  // State of the current round.
  uint64_t round_ = 0;
  std::map<uint32_t, cv::Mat> slots_;                // captures (8 bit)
  std::map<NodeId, cv::Mat> lit_masks_;              // per projector, from the pre-pass
  bool muted_ok_ = true;                             // the last SHOW muted did cut the light
  std::optional<ProjectorResponseRecord> response_;  // the own projector's, last measured
  std::map<std::string, std::vector<cv::Mat>> pattern_cache_;
  std::map<NodeId, wire::CorrespondenceSet> received_;  // by camera, for own projector
  // This round's answers to the runner by step (sent again when the step comes again) and the
  // steps still being worked on (a repeated one is ignored).
  std::map<uint32_t, std::vector<wire::Envelope>> replies_;
  std::set<uint32_t> working_;
  std::deque<std::pair<wire::CalibrationStep, NodeId>> deferred_;
  std::optional<std::pair<wire::CalibrationStep, NodeId>> pending_local_;
  std::chrono::steady_clock::time_point pending_local_since_{};
  bool calibrated_ = false;
  std::optional<UnitCalibration> saved_;
  // What the unit shows between calibrations (display_frames.h: the table grid of the
  // calibration it holds), and that calibration; empty until it holds one.
  cv::Mat display_;
  std::optional<UnitCalibration> holding_;
  SelfCalibrationService::OnVerification on_verification_;
  bool verify_started_ = false;
  NodeId calibrated_by_ = kInvalidNodeId;
  std::optional<std::chrono::steady_clock::time_point> last_step_from_other_;
  bool projecting_ = false;  // see being_calibrated()
  std::chrono::steady_clock::time_point last_step_{};
};

}  // namespace sandtable::node
