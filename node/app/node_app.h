// NodeApp: one projector unit as one application. It owns the unit's devices (projector,
// camera), its NodeRuntime (the network thread, the workers), the render loop (its own thread)
// and the services on the runtime: the coordinator's events, the show, the blend and the
// self-calibration.
//
// Start order (Create, then Run): the inputs the config names are loaded (factory calibration,
// true pose, saved calibration, timeline, model, CURVE keys); the projector opens and shows
// black; the render loop starts (its GL context); the services are made and added to the
// runtime; the runtime starts (sockets, membership); the camera opens on a worker (a world
// camera's first capture builds the world's light transport: seconds) and is handed to the
// self-calibration; the ready line is written. Stop (Run returns, then the destructor): the
// runtime says goodbye and its network thread ends; the camera, the show's service, the
// runtime (joining its workers), the blend, the self-calibration, the render loop and the
// projector are destroyed in that order, so no worker job outlives what it uses.
//
// Lines on stdout (docs/lab.md): ready, calibrated, calibration_failed, render, blend,
// messages; see node/main.cc.
#pragma once

#include <atomic>
#include <functional>
#include <memory>
#include <optional>
#include <string>

#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>

#include "cluster/personnel_tracks.h"
#include "cluster/report_lines.h"
#include "common/base/status.h"
#include "common/io/unit_calibration_file.h"
#include "common/scene/scene.h"
#include "node/app/node_config.h"
#include "node/app/self_calibration_service.h"
#include "node/app/unit_status_service.h"
#include "node/blend/blend_service.h"
#include "node/devices/device_factory.h"
#include "node/events/event_state_service.h"
#include "node/net/node_runtime.h"
#include "node/net/worker_pool.h"
#include "node/render/render_loop.h"
#include "node/render/render_service.h"

namespace sandtable::node {

// Where the node's report lines go (main: stdout, cluster/report_lines.h).
using LineSink = std::function<void(const report::ReportLine&)>;

// What the node does with each calibration a round (or a saved calibration's check) gives it.
// Called on the network thread.
class CalibrationHandoff {
 public:
  virtual ~CalibrationHandoff() = default;
  virtual void OnCalibrated(const SelfCalibrationOutcome& outcome) = 0;
};

// The node's hand-off. The blend starts at once (`start_blend`, on the network thread, which
// keeps answering the neighbours' fields); the export (unit files, and on the runner its report
// and site.mpcdi) runs on a worker, never on the network thread; once written, back on the
// network thread, `exported` is called and the `calibrated` line goes to `out`. An export that
// fails is logged (no line). Without an export directory nothing is written and `exported` is
// called at once.
class ExportAndBlend : public CalibrationHandoff {
 public:
  using OnOutcome = std::function<void(const SelfCalibrationOutcome&)>;
  ExportAndBlend(NodeId id, std::string export_dir, WorkerPool* workers, OnOutcome start_blend,
                 OnOutcome exported, LineSink out);
  void OnCalibrated(const SelfCalibrationOutcome& outcome) override;

 private:
  NodeId id_;
  std::string export_dir_;
  WorkerPool* workers_;
  OnOutcome start_blend_, exported_;
  LineSink out_;
};

// OK when the camera's images are the size its factory calibration is of; INVALID_ARGUMENT
// naming both sizes otherwise (`camera`: its description, for the message).
Status CheckCameraMatchesFactory(cv::Size camera_size, const std::string& camera,
                                 const CameraModel& factory_camera);

class NodeApp {
 public:
  // INVALID_ARGUMENT naming the flag: the config does not check, or a file it names does not
  // load or is another unit's (main: exit 2). Any other code: a device or the show that cannot
  // start (exit 1). `out` receives the node's JSON lines.
  static Expected<std::unique_ptr<NodeApp>> Create(NodeConfig config, LineSink out);
  ~NodeApp();
  NodeApp(const NodeApp&) = delete;
  NodeApp& operator=(const NodeApp&) = delete;

  // Starts the runtime and the camera, writes the ready line, runs until `stop` is set, writes
  // the exit lines. Returns the process's exit status (0, or 1 when it could not start or
  // export).
  int Run(const std::atomic<bool>& stop);

 private:
  NodeApp(NodeConfig config, LineSink out);
  Status LoadInputs();
  Status OpenProjector();
  Status StartRenderLoop();
  Status MakeServices();
  void MakeSelfCalibration();
  void OpenCamera(const std::atomic<bool>& stop);
  Status ExportHeldCalibration();
  void ShowHeldCalibration();
  void WriteExitLines();

  NodeConfig config_;
  // Before out_, which feeds it every line, and before runtime_, which steps it.
  std::unique_ptr<UnitStatusService> unit_status_;
  LineSink out_;
  NodeOptions options_;
  std::string projector_spec_, camera_spec_;  // --world applied
  std::optional<UnitCalibration> calibration_;
  std::optional<UnitCalibration> saved_;
  std::shared_ptr<const cluster::PersonnelTracks> tracks_;
  std::shared_ptr<const Scene> model_;
  DeviceOptions device_options_;
  // Destroyed in reverse: see the header comment.
  std::unique_ptr<ProjectorOutput> projector_;
  std::unique_ptr<RenderLoop> render_loop_;
  std::unique_ptr<SelfCalibrationService> self_calibration_;
  std::unique_ptr<BlendService> blend_;
  std::unique_ptr<CalibrationHandoff> handoff_;
  std::unique_ptr<NodeRuntime> runtime_;
  EventStateService events_;
  std::unique_ptr<RenderService> render_service_;
  std::unique_ptr<CameraInput> camera_;
};

}  // namespace sandtable::node
