// SelfCalibrationService: the node's part in the cluster's structured-light self-calibration
// (docs/calibration.md), over the peer sockets, with no process outside the nodes deciding.
//
// Two classes do the work, and this service routes each message to one of them: the unit's side
// (calibration_unit.h), on every node, and the runner's (calibration_runner.h), which acts on
// the node the round policy elects. Every node serves the steps of a round: SHOW (black, white or a
// pattern frame on its projector), CAPTURE (a picture with its camera, kept under a slot; with a
// reference slot it answers how many pixels are lit against it), DECODE (its captures of one
// projector's sequence -> projector-grid correspondences, sent to the projecting node, neighbours
// only), LOCAL (the correspondences of its own projector -> its triangulated footprint and its pose
// relative to the cameras that share its points, sent to the runner). Device calls and long
// work run on the node's workers; the network thread never blocks.
//
// Who runs a round and when is the round policy (round_policy.h): the lowest id among the
// members that have a projector and a camera, once the member list has not changed for
// `settle` and every member is a linked peer, a rule every node applies to the same member
// list. The runner runs the pre-pass (one black reference, then each projector white alone: which
// cameras see which projectors), colours the conflict graph (schedule.h), plans each projector's
// patterns from what its cameras resolve (structured_light_plan.h), runs the colour classes'
// sequences, collects the projecting nodes' inputs, solves the site on a worker (site_solve.h) and
// sends each node its CalibrationResult. A node that has not answered a step when the stage has
// made no progress (no answer from any unit) for step_timeout is left out of the rest of the round
// (its log line and the report name it); the others finish.
// Lost messages (a lossy link): the runner sends a step again every step_retry while it is
// unanswered; a node answers a step it has already answered with the same messages again (its
// done, and for LOCAL its CalibrationInput) and ignores one it is still working on.
#pragma once

#include <chrono>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "cluster/report_lines.h"
#include "common/io/mpcdi.h"
#include "common/io/unit_calibration_file.h"
#include "common/scene/scene.h"
#include "node/app/calibration_link.h"
#include "node/app/round_policy.h"
#include "node/calibration/calibration_check.h"
#include "node/calibration/cluster_solver.h"
#include "node/calibration/planar_solver.h"
#include "node/calibration/structured_light_plan.h"
#include "node/devices/camera_input.h"
#include "node/devices/paced_camera.h"
#include "node/devices/projector_output.h"
#include "node/net/node_runtime.h"
#include "node/render/render_loop.h"
#include "proto/envelope.pb.h"

namespace sandtable::node {

struct SelfCalibrationOptions {
  std::chrono::milliseconds settle{1500};
  // The site's size when known (--expect-units; 0: not known): the first round waits until
  // that many units are members, at most expect_wait from the runner's start (64 processes
  // starting on two cores register over more than `settle`; a round begun with 56 of 64 left
  // 8 to a join round).
  int expected_units = 0;
  std::chrono::milliseconds expect_wait{180000};
  // The lowest id of a site whose other units are calibrated waits this long for their
  // runner's join round before it runs a round itself (that runner may have left); so does
  // the lowest unit of a site whose runner left before calibrating a unit that joined.
  std::chrono::milliseconds join_wait{15000};
  std::chrono::milliseconds step_timeout{60000};
  // A unit awaited by the runner that is out of the member list this long has left the round.
  std::chrono::milliseconds member_grace{3000};
  std::chrono::milliseconds step_retry{1500};
  // Modeled device time: frames x (frame period + capture latency). The latency is that of a
  // hardware-triggered camera whose exposure fits inside the frame period: trigger and readout
  // overlap beyond the frame, stated as 2 ms.
  double frame_period_s = 1.0 / 60.0;
  double capture_latency_s = 0.002;
  PatternPlanOptions plan;
  // Cameras other than the projector's own see its footprint obliquely: the plan assumes
  // they resolve this factor worse than the own camera's measured resolution.
  double neighbour_resolution_factor = 1.4;
  // Each projector's response (projector_response.h), measured by its own camera in the
  // pre-pass: these grey levels, then the light cut (muted) for the black level. Empty: not
  // measured (the renderer assumes 2.2).
  std::vector<int> response_levels{64, 128, 192};
  int grid_step_px = 16;     // projector grid spacing (docs/calibration.md: error against step)
  int lit_threshold = 20;    // 8-bit levels, white - black
  int min_lit_pixels = 500;  // a camera "sees" a projector above this
  // Two projectors conflict (cannot share a colour) when one camera's lit masks of them come
  // within mask_margin_px of each other on more than min_overlap_pixels pixels.
  int mask_margin_px = 6;
  int min_overlap_pixels = 50;
  ClusterSolveOptions solve;
  CalibrationCheckOptions check;  // the restart check of a saved calibration
  // Which solve (docs/calibration.md, "Planar sites"): kAuto takes the planar path when every
  // unit's planarity probe finds its footprint planar, else the full path; kFull always the
  // full path (for comparison).
  enum class Path { kAuto, kFull };
  Path path = Path::kAuto;
  PlanarSolveOptions planar;
  Status Check() const;
  RoundPolicyOptions RoundPolicy() const;
};

// What a node holds once a round ends, and the figures the lab reports.
struct SelfCalibrationOutcome {
  UnitCalibration calibration;
  nlohmann::json report;   // the runner's cluster report (docs/calibration.md)
  double compute_s = 0.0;  // this node's thread CPU time in the round
  uint64_t messages_sent = 0, messages_received = 0;
  uint64_t bytes_sent = 0, bytes_received = 0;
  CaptureTimingStats capture;  // its camera's timing so far
  // The runner only: the site as MPCDI (common/io/mpcdi_builder.h; the warp cast on the found
  // model, or on the table plane when there is none), ready for WriteMpcdi.
  std::shared_ptr<const MpcdiSite> site_mpcdi;
  uint64_t round = 0;  // the round that calibrated it; 0 for a saved calibration that held
  // The units whose footprints overlap this one's (from the round; nullopt: not known, e.g. a
  // saved calibration that held).
  std::optional<std::set<NodeId>> overlapping;
  bool verified = false;  // a saved calibration that held its check (no round)
};

// Writes what a node holds after a round (or a check that held) into `export_dir`:
// unit-<id>.json and .yaml (ExportCalibration), and on the runner self_calibration_report.json
// and site.mpcdi; returns the node's `calibrated` line (docs/lab.md). A report or MPCDI file that
// cannot be written is logged and left out of the line; the unit files are the error.
Expected<report::Calibrated> ExportSelfCalibration(const SelfCalibrationOutcome& outcome, NodeId id,
                                                   const std::string& export_dir);

class CalibrationUnit;
class CalibrationRunner;

// The node's self-calibration: its unit's side (calibration_unit.h) and, on the unit that runs
// a round, the runner's (calibration_runner.h), over one link to the peers.
class SelfCalibrationService : public NodeService, private CalibrationLink {
 public:
  using OnCalibrated = std::function<void(const SelfCalibrationOutcome&)>;
  using OnFailed = std::function<void(const std::string&)>;

  // `factory` is the unit's own factory calibration; `projector` is not owned and must outlive
  // the service; `model` (may be null) is the glTF model to find on the table.
  SelfCalibrationService(UnitCalibration factory, ProjectorOutput* projector,
                         std::shared_ptr<const Scene> model, SelfCalibrationOptions options,
                         OnCalibrated on_calibrated, OnFailed on_failed);
  ~SelfCalibrationService() override;

  // The camera, once opened (on a worker at start).
  void SetCamera(std::unique_ptr<CameraInput> camera);
  // The node's renderer (node/render/render_loop.h): once calibrated the unit shows the
  // renderer's frames (not the table grid), blanks through its mask during a neighbour's join,
  // and suspends it whenever calibration needs the projector. Set before the runtime starts.
  void SetRenderLoop(RenderLoop* loop);

  // A calibration saved by an earlier run (this unit's, with its table pose): checked with two
  // frames (calibration_check.h) once the camera is open and no lower-id unit is checking its
  // own; when it holds, it is the unit's calibration (on_calibrated with verified = true) and
  // the unit needs no round. `on_verification` gets the check's figures either way. Before the
  // runtime starts; the caller sets the runtime's calibration state to SAVED.
  using OnVerification = std::function<void(const report::Verification&)>;
  void SetSavedCalibration(UnitCalibration saved, OnVerification on_verification);

  const char* name() const override { return "self-calibration"; }
  // Where the runner's progress lines go (report::RoundProgress; none until set). Set before
  // the runtime starts.
  using OnProgress = std::function<void(const report::RoundProgress&)>;
  void SetOnProgress(OnProgress on_progress) { on_progress_ = std::move(on_progress); }

  bool ServesPeer(wire::Envelope::BodyCase body) const override;
  void OnPeerMessage(net::Incoming request, NodeRuntime& node) override;
  // The coordinator's recalibrate_ask (an operator's "calibrate again"): for the runner.
  bool ServesCoordinator(wire::Envelope::BodyCase body) const override;
  void OnCoordinatorMessage(const wire::Envelope& message, NodeRuntime& node) override;
  Status OnStep(NodeRuntime& node) override;

  bool calibrated() const;
  // A round is calibrating this unit's projector now (CalibrationUnit::being_calibrated).
  bool being_calibrated() const;

 private:
  bool Send(NodeId to, wire::Envelope envelope, NodeRuntime& node) override;
  void Progress(const report::RoundProgress& progress) override {
    if (on_progress_) on_progress_(progress);
  }
  void Deliver(NodeId from, const wire::Envelope& envelope, NodeRuntime& node);

  SelfCalibrationOptions options_;
  OnProgress on_progress_;
  CalibrationLedger ledger_;
  std::unique_ptr<CalibrationUnit> unit_;
  std::unique_ptr<CalibrationRunner> runner_;
};

}  // namespace sandtable::node
