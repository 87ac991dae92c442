#include "node/app/node_app.h"

#include <filesystem>
#include <system_error>
#include <thread>
#include <utility>

#include "common/base/log.h"
#include "common/scene/gltf_loader.h"
#include "net/site_enrollment.h"
#include "node/app/calibration_service.h"

namespace sandtable::node {
namespace {

// A world busy with a large site's captures (grid-64) may not answer the camera's size probe
// in time: UNAVAILABLE is tried again, this many attempts in all; anything else (a bad spec, a
// refused request) fails at once.
constexpr int kCameraOpenAttempts = 5;
// The wait before the second attempt; it doubles for each later one (0.25 + 0.5 + 1 + 2 s).
constexpr std::chrono::milliseconds kCameraRetryFirstWait{250};

// Sleeps `wait`, or less when `stop` is set.
void SleepUnlessStopped(std::chrono::milliseconds wait, const std::atomic<bool>& stop) {
  const auto until = std::chrono::steady_clock::now() + wait;
  while (!stop && std::chrono::steady_clock::now() < until) {
    std::this_thread::sleep_for(std::chrono::milliseconds(10));
  }
}

// A file flag's error: INVALID_ARGUMENT naming the flag, whatever the loader's code.
Status FlagError(const std::string& flag, const Status& status) {
  return InvalidArgumentError(flag + ": " + status.ToString());
}

// A loaded calibration must be this unit's (or name no unit).
Status SameUnit(const std::string& flag, const std::string& path, NodeId file_unit, NodeId id) {
  if (file_unit == kInvalidNodeId || file_unit == id) return OkStatus();
  return InvalidArgumentError(flag + ": " + path + " is unit " + std::to_string(file_unit) +
                              "'s, this node is " + std::to_string(id));
}

}  // namespace

Status CheckCameraMatchesFactory(cv::Size camera_size, const std::string& camera,
                                 const CameraModel& factory_camera) {
  if (camera_size.width == factory_camera.width_px &&
      camera_size.height == factory_camera.height_px) {
    return OkStatus();
  }
  return InvalidArgumentError("camera " + camera + " gives " + std::to_string(camera_size.width) +
                              "x" + std::to_string(camera_size.height) +
                              " images but the factory calibration (--factory) is of a " +
                              std::to_string(factory_camera.width_px) + "x" +
                              std::to_string(factory_camera.height_px) +
                              " camera: another camera, or another unit's factory file");
}

ExportAndBlend::ExportAndBlend(NodeId id, std::string export_dir, WorkerPool* workers,
                               OnOutcome start_blend, OnOutcome exported, LineSink out)
    : id_(id),
      export_dir_(std::move(export_dir)),
      workers_(workers),
      start_blend_(std::move(start_blend)),
      exported_(std::move(exported)),
      out_(std::move(out)) {}

void ExportAndBlend::OnCalibrated(const SelfCalibrationOutcome& outcome) {
  start_blend_(outcome);
  if (export_dir_.empty()) {
    exported_(outcome);
    return;
  }
  auto held = std::make_shared<const SelfCalibrationOutcome>(outcome);
  workers_->Run<Expected<report::Calibrated>>(
      [held, id = id_, dir = export_dir_] { return ExportSelfCalibration(*held, id, dir); },
      [this, held](Expected<report::Calibrated> line) {
        exported_(*held);
        if (!line.ok()) {
          ST_LOG(kError) << "cannot export the calibration: " << line.status().ToString();
          return;
        }
        out_(*line);
      });
}

NodeApp::NodeApp(NodeConfig config, LineSink out)
    : config_(std::move(config)),
      unit_status_(std::make_unique<UnitStatusService>(net::ThisHostName())),
      out_([status = unit_status_.get(), out = std::move(out)](const report::ReportLine& line) {
        status->OnLine(line);
        out(line);
      }),
      options_(config_.RuntimeOptions()) {}

NodeApp::~NodeApp() = default;

Expected<std::unique_ptr<NodeApp>> NodeApp::Create(NodeConfig config, LineSink out) {
  ST_RETURN_IF_ERROR(config.Check());
  std::unique_ptr<NodeApp> app(new NodeApp(std::move(config), std::move(out)));
  ST_RETURN_IF_ERROR(app->LoadInputs());
  ST_RETURN_IF_ERROR(app->OpenProjector());
  ST_RETURN_IF_ERROR(app->StartRenderLoop());
  ST_RETURN_IF_ERROR(app->MakeServices());
  return app;
}

Status NodeApp::LoadInputs() {
  const NodeConfig& c = config_;
  if (!c.curve_keys_path.empty()) {
    Expected<net::CurveKeyPair> keys = net::ReadCurveKeyFile(c.curve_keys_path);
    if (!keys.ok()) return FlagError("--curve-keys", keys.status());
    options_.curve = *keys;
  }
  // What the unit knows of itself: its factory calibration, and in the lab's test mode its
  // true pose.
  if (!c.factory_path.empty()) {
    Expected<UnitCalibration> factory = LoadUnitCalibration(c.factory_path);
    if (!factory.ok()) return FlagError("--factory", factory.status());
    ST_RETURN_IF_ERROR(SameUnit("--factory", c.factory_path, factory->unit_id, c.id));
    factory->unit_id = c.id;
    calibration_ = *factory;
    if (!c.true_pose_path.empty()) {
      Expected<TruePose> pose = LoadTruePose(c.true_pose_path);
      if (!pose.ok()) return FlagError("--true-pose", pose.status());
      Expected<UnitCalibration> composed = ComposeTruePoseCalibration(*factory, *pose);
      if (!composed.ok()) return FlagError("--true-pose", composed.status());
      calibration_ = *composed;
      ST_LOG(kWarning) << "TEST MODE: holding the true pose handed by the lab (source "
                       << calibration_->source << ")";
    }
    NodeCapabilities& caps = options_.capabilities;
    caps.projector_width_px = calibration_->projector.width_px;
    caps.projector_height_px = calibration_->projector.height_px;
    caps.camera_width_px = calibration_->camera.width_px;
    caps.camera_height_px = calibration_->camera.height_px;
  }
  std::error_code no_file;
  if (!c.saved_calibration_path.empty() &&
      !std::filesystem::exists(c.saved_calibration_path, no_file)) {
    // A unit's first start: the file its calibration will be exported to is not there yet.
    ST_LOG(kInfo) << "--saved-calibration: no " << c.saved_calibration_path
                  << " yet; the unit calibrates with the site";
  } else if (!c.saved_calibration_path.empty()) {
    Expected<UnitCalibration> loaded = LoadUnitCalibration(c.saved_calibration_path);
    if (!loaded.ok()) return FlagError("--saved-calibration", loaded.status());
    ST_RETURN_IF_ERROR(
        SameUnit("--saved-calibration", c.saved_calibration_path, loaded->unit_id, c.id));
    if (loaded->source != kSourceStructuredLight || !loaded->table_from_projector) {
      return InvalidArgumentError("--saved-calibration: " + c.saved_calibration_path +
                                  " is not a site calibration (source structured_light with "
                                  "table_from_projector)");
    }
    loaded->unit_id = c.id;
    saved_ = *loaded;
  }
  if (!c.timeline_path.empty()) {
    Expected<cluster::PersonnelTracks> loaded = cluster::PersonnelTracks::Load(c.timeline_path);
    if (!loaded.ok()) return FlagError("--timeline", loaded.status());
    tracks_ = std::make_shared<const cluster::PersonnelTracks>(std::move(*loaded));
  }
  if (!c.model_path.empty()) {
    Expected<Scene> loaded = LoadGltfScene(c.model_path);
    if (!loaded.ok()) return FlagError("--model", loaded.status());
    model_ = std::make_shared<const Scene>(std::move(*loaded));
  }
  projector_spec_ = c.ProjectorSpec();
  camera_spec_ = c.CameraSpec();
  auto kind = [](const std::string& spec) {
    return spec.empty() ? std::string("none") : spec.substr(0, spec.find(':'));
  };
  options_.capabilities.projector_output = kind(projector_spec_);
  options_.capabilities.camera_input = kind(camera_spec_);
  if (saved_ && !(c.true_pose_path.empty() && !projector_spec_.empty() && !camera_spec_.empty())) {
    return InvalidArgumentError(
        "--saved-calibration needs self-calibration: a projector, a camera, no --true-pose");
  }
  device_options_.node_id = c.id;
  device_options_.world_curve = options_.curve;  // the site key also admits the node to the world
  if (calibration_) {
    device_options_.projector_size_px =
        cv::Size(calibration_->projector.width_px, calibration_->projector.height_px);
    device_options_.camera_size_px =
        cv::Size(calibration_->camera.width_px, calibration_->camera.height_px);
  }
  return OkStatus();
}

// The projector opens now (a missing display is one clear line and exit 1) and starts black.
Status NodeApp::OpenProjector() {
  if (projector_spec_.empty()) return OkStatus();
  Expected<std::unique_ptr<ProjectorOutput>> opened =
      MakeProjectorOutput(projector_spec_, device_options_);
  if (!opened.ok()) {
    return UnavailableError("projector " + projector_spec_ + ": " + opened.status().message());
  }
  projector_ = std::move(*opened);
  const cv::Size size = projector_->size();
  options_.capabilities.projector_width_px = size.width;
  options_.capabilities.projector_height_px = size.height;
  Expected<ShownFrame> shown = projector_->Show(cv::Mat::zeros(size, CV_8UC1));
  if (!shown.ok()) {
    return UnavailableError("projector " + projector_->description() + ": " +
                            shown.status().message());
  }
  return OkStatus();
}

// The show: the renderer on its own thread, drawing once the unit holds a calibration.
Status NodeApp::StartRenderLoop() {
  if (!projector_ || config_.render == RenderMode::kOff) return OkStatus();
  RenderLoopOptions render_options;
  render_options.max_fps = config_.render_max_fps;
  render_options.frame_log_path = config_.render_log_path;
  Expected<std::unique_ptr<RenderLoop>> started =
      RenderLoop::Start(projector_.get(), model_, render_options, tracks_);
  if (!started.ok()) {
    if (config_.render == RenderMode::kOn) {
      return UnavailableError("render: " + started.status().message());
    }
    ST_LOG(kWarning) << "no show (--render auto): " << started.status().message();
    out_(report::RenderUnavailable{config_.id, started.status().message()});
    return OkStatus();
  }
  render_loop_ = std::move(*started);
  ST_LOG(kInfo) << "render: " << render_loop_->Summary().context;
  return OkStatus();
}

Status NodeApp::MakeServices() {
  runtime_ = std::make_unique<NodeRuntime>(options_);
  runtime_->AddService(&events_);
  runtime_->AddService(unit_status_.get());
  if (calibration_ && calibration_->table_from_projector) {
    unit_status_->SetCalibration(*calibration_, std::nullopt);  // held at start (true pose)
  }
  if (render_loop_) {
    RenderServiceOptions render_service_options;
    render_service_options.sun = config_.sun;
    ST_RETURN_IF_ERROR(render_service_options.Check());
    render_service_ =
        std::make_unique<RenderService>(&events_, render_loop_.get(), render_service_options, out_);
    runtime_->AddService(render_service_.get());
  }
  if (render_loop_ && config_.blend) {
    BlendServiceOptions blend_options;
    blend_options.blend.grid_step_px = config_.blend_step_px;
    blend_options.blend.fill_limit = config_.blend_fill_limit;
    blend_options.blend.edge_soft_m = 1e-3 * config_.blend_edge_soft_mm;
    blend_options.blend.edge_soft_min_face_m2 = config_.blend_soft_face_m2;
    blend_options.export_dir = config_.export_dir;
    blend_options.black_match = config_.black_match;
    ST_RETURN_IF_ERROR(blend_options.Check());
    blend_ = std::make_unique<BlendService>(model_, render_loop_.get(), blend_options, out_);
    runtime_->AddService(blend_.get());
  }
  MakeSelfCalibration();
  return OkStatus();
}

// Self-calibration (structured light with the neighbours) when the unit has its factory
// calibration, a projector and a camera, and is not in the lab's true-pose test mode.
void NodeApp::MakeSelfCalibration() {
  if (!calibration_ && projector_ && !camera_spec_.empty()) {
    const std::string why =
        "no factory calibration (--factory): this unit cannot calibrate itself and shows black "
        "until it has one (sandtable-node calibrate-unit, docs/unit-calibration.md)";
    ST_LOG(kWarning) << why;
    unit_status_->SetProblem("no factory calibration", why);
  }
  if (!calibration_ || !config_.true_pose_path.empty() || !projector_ || camera_spec_.empty()) {
    return;
  }
  // The runner's blend rewrites site.mpcdi with each alpha map: it holds those writes until
  // the export has written the file.
  handoff_ = std::make_unique<ExportAndBlend>(
      config_.id, config_.export_dir, &runtime_->workers(),
      [this](const SelfCalibrationOutcome& outcome) {
        calibration_ = outcome.calibration;
        unit_status_->SetCalibration(outcome.calibration, outcome.overlapping);
        if (!blend_) return;
        if (outcome.site_mpcdi && !config_.export_dir.empty()) {
          blend_->SetSiteMpcdi(outcome.site_mpcdi, config_.export_dir + "/site.mpcdi");
          blend_->HoldSiteMpcdiWrites();
        }
        blend_->SetCalibration(outcome.calibration, outcome.round, outcome.overlapping, *runtime_,
                               outcome.report.value("runner", kInvalidNodeId));
      },
      [this](const SelfCalibrationOutcome& outcome) {
        if (blend_ && outcome.site_mpcdi && !config_.export_dir.empty()) {
          blend_->ReleaseSiteMpcdiWrites(*runtime_);
        }
      },
      out_);
  self_calibration_ = std::make_unique<SelfCalibrationService>(
      *calibration_, projector_.get(), model_, config_.SelfCalibration(),
      [this](const SelfCalibrationOutcome& outcome) { handoff_->OnCalibrated(outcome); },
      [this](const std::string& reason) {
        out_(report::CalibrationFailed{config_.id, reason});
      });
  runtime_->set_calibration_state(saved_ ? wire::CALIBRATION_STATE_SAVED
                                         : wire::CALIBRATION_STATE_NONE);
  if (saved_) self_calibration_->SetSavedCalibration(*saved_, out_);
  self_calibration_->SetOnProgress(out_);
  if (render_loop_) self_calibration_->SetRenderLoop(render_loop_.get());
  unit_status_->SetCalibratingProbe(
      [service = self_calibration_.get()] { return service->being_calibrated(); });
  runtime_->AddService(self_calibration_.get());
}

// The camera opens on a worker and goes to the self-calibration (or is held).
void NodeApp::OpenCamera(const std::atomic<bool>& stop) {
  if (camera_spec_.empty()) return;
  runtime_->workers().Run<Expected<std::unique_ptr<CameraInput>>>(
      [spec = camera_spec_, device_options = device_options_, id = config_.id, &stop] {
        Expected<std::unique_ptr<CameraInput>> opened = MakeCameraInput(spec, device_options);
        std::chrono::milliseconds wait = kCameraRetryFirstWait;
        for (int attempt = 2; attempt <= kCameraOpenAttempts && !opened.ok() &&
                              opened.status().code() == StatusCode::kUnavailable && !stop;
             ++attempt, wait *= 2) {
          ST_LOG(kWarning) << "unit " << id << ": camera " << spec << ": "
                           << opened.status().message() << "; trying again in " << wait.count()
                           << " ms (attempt " << attempt << " of " << kCameraOpenAttempts << ")";
          SleepUnlessStopped(wait, stop);
          if (!stop) opened = MakeCameraInput(spec, device_options);
        }
        return opened;
      },
      [this](Expected<std::unique_ptr<CameraInput>> opened) {
        if (opened.ok() && calibration_) {
          const Status matches = CheckCameraMatchesFactory(
              (*opened)->size(), (*opened)->description(), calibration_->camera);
          if (!matches.ok()) opened = matches;
        }
        if (!opened.ok()) {
          const std::string why = "camera " + camera_spec_ + ": " + opened.status().message();
          ST_LOG(kError) << why << " (the unit cannot calibrate itself)";
          if (self_calibration_) {
            out_(report::CalibrationFailed{config_.id,
                                           "unit " + std::to_string(config_.id) + ": " + why});
          } else {
            unit_status_->SetProblem("no camera", why);
          }
          return;
        }
        ST_LOG(kInfo) << "camera " << (*opened)->description() << " " << (*opened)->size().width
                      << "x" << (*opened)->size().height << ", " << (*opened)->bit_depth()
                      << " bit";
        if (self_calibration_) {
          self_calibration_->SetCamera(std::move(*opened));
        } else {
          camera_ = std::move(*opened);
        }
      });
}

// A unit without self-calibration exports what it holds at start (factory, or the lab's
// true pose).
Status NodeApp::ExportHeldCalibration() {
  if (!calibration_ || config_.export_dir.empty() || self_calibration_) return OkStatus();
  Expected<ExportedCalibration> exported = ExportCalibration(*calibration_, config_.export_dir);
  if (!exported.ok()) return exported.status();
  report::Calibrated line;
  line.id = config_.id;
  line.source = calibration_->source;
  line.json = exported->json_path;
  line.yaml = exported->yaml_path;
  out_(line);
  return OkStatus();
}

// A unit that starts calibrated (the lab's true-pose mode) shows at once.
void NodeApp::ShowHeldCalibration() {
  if (!calibration_ || !render_loop_ || self_calibration_ || !calibration_->table_from_projector) {
    return;
  }
  runtime_->workers().Run<Status>(
      [loop = render_loop_.get(), c = *calibration_] { return loop->ShowCalibration(c); },
      [this, c = *calibration_](Status shown) {
        if (!shown.ok()) {
          ST_LOG(kWarning) << "render: " << shown.message();
          return;
        }
        // Neighbours unknown (no round): the field goes to every linked peer.
        if (blend_) blend_->SetCalibration(c, 0, std::nullopt, *runtime_);
      });
}

void NodeApp::WriteExitLines() {
  if (render_service_) out_(render_service_->Summary(config_.id));
  const net::ChannelFaultCounts faults = runtime_->fault_counts();
  out_(report::Messages{config_.id, runtime_->counters().accepted(),
                        runtime_->counters().total_rejected(), faults.dropped, faults.corrupted});
  if (auto offset = runtime_->clock_offset()) {
    ST_LOG(kInfo) << "clock offset to coordinator " << offset->offset_s * 1e3
                  << " ms, error <= " << offset->error_bound_s * 1e3 << " ms over "
                  << offset->samples << " samples";
  }
  ST_LOG(kInfo) << "stopping; messages " << runtime_->counters().ToString() << "; annotations "
                << events_.annotations().strokes().size() << " strokes";
}

int NodeApp::Run(const std::atomic<bool>& stop) {
  Status started = runtime_->Start();
  if (!started.ok()) {
    ST_LOG(kError) << "cannot start: " << started.ToString();
    return 1;
  }
  OpenCamera(stop);
  out_(report::NodeReady{config_.id, runtime_->peer_endpoint()});
  if (Status exported = ExportHeldCalibration(); !exported.ok()) {
    ST_LOG(kError) << "cannot export the calibration: " << exported.ToString();
    runtime_->SayGoodbye("export failed");
    return 1;
  }
  ShowHeldCalibration();
  Status ran = runtime_->Run(stop);
  WriteExitLines();
  return ran.ok() ? 0 : 1;
}

}  // namespace sandtable::node
