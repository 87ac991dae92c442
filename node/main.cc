// sandtable-node: one projector unit. Composes the node's services on its NodeRuntime:
// membership, clock offset and the peer mesh (node/net), the coordinator's events kept for the
// renderer (node/events), and the calibration it holds and exports (node/app).
//
//   sandtable-node --id N --coordinator REQUESTS,EVENTS [--world ENDPOINT] [--factory FILE]
//                  [--true-pose FILE] [--export-dir DIR] [--projector SPEC] [--camera SPEC]
//                  [--model FILE] [--saved-calibration FILE] [--grid-step-px N]
//                  [--calibration-path auto|full] [--expect-units N] [--phase-steps N]
//                  [--gray-cell-px X]
//                  [--bundle-iterations N] [--bundle-free all|poses]
//                  [--render auto|on|off] [--timeline TRACKS.csv] [--sun on|off]
//                  [--sun-start-h H] [--sun-hours-per-s R] [--render-max-fps F]
//                  [--render-log FILE] [--blend on|off] [--blend-step-px N]
//                  [--blend-fill-limit X] [--blend-edge-soft-mm E] [--black-match on|off]
//                  [--bind ENDPOINT] [--curve-keys FILE] [--heartbeat-ms N] [--workers N]
//                  [--fault-drop-share P] [--fault-corrupt-share P] [--fault-seed N] (lab chaos)
//   (--world E is short for --projector world:E --camera world:E; node/devices/device_factory.h)
//   sandtable-node calibrate-unit --poses DIR -o unit.json ...   (the unit's factory calibration)
//   sandtable-node render-frame --calibration unit.json -o frame.png ...  (one frame of the show)
//
// On start it prints one JSON line on stdout (common/base/ready_line.h):
//   {"ready":"sandtable-node","id":3,"peer":"tcp://127.0.0.1:40123"}
// and, once it holds an exported calibration:
//   {"calibrated":3,"source":"factory+true_pose","json":"DIR/unit-3.json","yaml":"DIR/unit-3.yaml"}
// (self-calibration adds report, mpcdi, round, verified and its compute and traffic figures);
// with --saved-calibration, the check's figures first: {"verification":3,"holds":true,...}.
// On exit: {"messages":ID,"accepted":N,"rejected":N,"faults_dropped":N,"faults_corrupted":N}.
// The show (node/render, docs/render.md): once the unit holds a calibration it renders the
// --model where it stands, the annotations, the wand's cursor and the --timeline's personnel
// tracks at the coordinator's media time, under a virtual sun, into its projector; it prints
// {"render":ID,"pattern":NAME} when an operator's test pattern is first shown and a summary
// {"render":ID,"frames":N,"frame_ms_p50":...} every 2 s. --render auto renders when there is a
// projector and, when no GL context can be made, says so ({"render":ID,"unavailable":WHY}) and
// runs without a show; --render on makes that an error (exit 1).
// The blend (node/blend, docs/blend.md): with a show, once calibrated the unit blends with the
// units whose footprints overlap its own and prints {"blend":ID,"blended":true,...} each time a
// new mask is shown, {"blend":ID,"reblend":"left","peer":K,...} when a neighbour left.
// Exit status: 0 after SIGINT/SIGTERM (Goodbye said), 1 when it cannot start, 2 for a bad flag
// or a bad input file.
#include <csignal>
#include <iostream>
#include <string>
#include <vector>

#include "cluster/personnel_tracks.h"
#include "common/base/log.h"
#include "common/base/main_guard.h"
#include "common/base/ready_line.h"
#include "common/cli/command_line.h"
#include "common/io/unit_calibration_file.h"
#include "common/scene/gltf_loader.h"
#include "node/app/calibration_service.h"
#include "node/app/self_calibration_service.h"
#include "node/blend/blend_service.h"
#include "node/calibration/calibrate_unit_command.h"
#include "node/devices/device_factory.h"
#include "node/events/event_state_service.h"
#include "node/net/node_runtime.h"
#include "node/render/render_frame_command.h"
#include "node/render/render_loop.h"
#include "node/render/render_service.h"

namespace {

std::atomic<bool> g_stop{false};
void OnSignal(int) { g_stop = true; }
constexpr int kCameraOpenAttempts = 5;

}  // namespace

static int Run(int argc, char** argv) {
  using namespace sandtable;
  CLI::App app{"sandtable-node: one projector unit of a Sandtable site", "sandtable-node"};
  cli::Configure(app);
  app.require_subcommand(0, 1);
  CLI::App* calibrate =
      app.add_subcommand("calibrate-unit",
                         "the unit's factory calibration from chessboard + Gray-code poses "
                         "(sandtable-node calibrate-unit --help)");
  calibrate->prefix_command();  // its own parser (node/calibration/calibrate_unit_command.h)
  calibrate->set_help_flag();
  CLI::App* render_frame = app.add_subcommand(
      "render-frame", "one frame of the unit's show to a PNG (sandtable-node render-frame --help)");
  render_frame->prefix_command();  // its own parser (node/render/render_frame_command.h)
  render_frame->set_help_flag();

  node::NodeOptions options;
  uint32_t id = 0;
  std::string coordinator, curve_keys, world, factory_path, true_pose_path, export_dir;
  std::string saved_path;
  std::string projector_spec, camera_spec, model_path;
  int grid_step_px = 16;
  std::string calibration_path = "auto";
  // The knobs `sandtable-lab sweep` turns (docs/lab.md, "Sweep"): run time against error.
  node::SelfCalibrationOptions calibration_knobs;
  std::string bundle_free = "all";
  int heartbeat_ms = 100;
  std::string render_mode = "auto", timeline_path, sun = "on", render_log;
  node::SunOptions sun_options;
  double render_max_fps = 30.0;
  std::string blend_mode = "on";
  int blend_step_px = node::BlendOptions{}.grid_step_px;
  double blend_fill_limit = node::BlendOptions{}.fill_limit;
  double blend_edge_soft_mm = 1e3 * node::BlendOptions{}.edge_soft_m;
  double blend_soft_face_m2 = node::BlendOptions{}.edge_soft_min_face_m2;
  std::string black_match = "off";
  app.add_option("--id", id, "this unit's node id (below 4294967280)")
      ->check(cli::Integer<uint32_t>(0, kFirstReservedSenderId - 1));
  app.add_option("--coordinator", coordinator,
                 "the coordinator's REQUESTS,EVENTS endpoints (its ready line)")
      ->check([](const std::string& v) {
        return v.find(',') == std::string::npos ? std::string("needs REQUESTS,EVENTS") : "";
      });
  app.add_option("--bind", options.peer_bind, "own ROUTER for peers")->check(cli::Endpoint());
  app.add_option("--curve-keys", curve_keys,
                 "site CURVE key file (sandtable-coordinator "
                 "--generate-curve-keys)")
      ->check(CLI::ExistingFile);
  app.add_option("--heartbeat-ms", heartbeat_ms, "heartbeat period in ms")
      ->check(cli::Integer(1, 60000));
  app.add_option("--workers", options.worker_threads, "worker threads for long work")
      ->check(cli::Integer(1, 64));
  app.add_option("--fault-drop-share", options.faults.drop_share,
                 "LAB CHAOS ONLY: drop this share of the messages the node sends")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--fault-corrupt-share", options.faults.corrupt_share,
                 "LAB CHAOS ONLY: corrupt this share of the messages the node sends")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--fault-seed", options.faults.seed, "seed of the injected faults");
  app.add_option("--world", world,
                 "the simulated world's endpoint: projector and camera are "
                 "world-backed")
      ->check(cli::Endpoint());
  app.add_option("--projector", projector_spec,
                 "the projector: " + std::string(node::kProjectorSpecForms) +
                     " (default with --world: world:ENDPOINT)");
  app.add_option("--camera", camera_spec,
                 "the camera: " + std::string(node::kCameraSpecForms) +
                     " (default with --world: world:ENDPOINT)");
  app.add_option("--factory", factory_path, "the unit's factory calibration file")
      ->check(CLI::ExistingFile);
  app.add_option("--true-pose", true_pose_path,
                 "LAB TEST MODE: the unit's true pose (source factory+true_pose); needs --factory")
      ->check(CLI::ExistingFile);
  app.add_option("--export-dir", export_dir, "where unit-<id>.json and .yaml are written");
  app.add_option("--model", model_path,
                 "the glTF model on the table: self-calibration finds where it stands")
      ->check(CLI::ExistingFile);
  app.add_option("--saved-calibration", saved_path,
                 "a calibration this unit saved in an earlier run (unit-<id>.json, source "
                 "structured_light): checked with two frames and kept when it holds")
      ->check(CLI::ExistingFile);
  app.add_option("--expect-units", calibration_knobs.expected_units,
                 "self-calibration: the site's number of units; the first round waits (at most "
                 "3 min) until that many are members")
      ->check(cli::Integer(0, 4096));
  app.add_option("--calibration-path", calibration_path,
                 "self-calibration: auto (the planar path when every footprint is planar) or "
                 "full")
      ->check(CLI::IsMember({"auto", "full"}));
  app.add_option("--grid-step-px", grid_step_px,
                 "self-calibration: projector grid spacing of the correspondences, px")
      ->check(cli::Integer(4, 256));
  app.add_option("--phase-steps", calibration_knobs.plan.phase_steps,
                 "self-calibration: phase-shift steps per direction (fewer: fewer frames, more "
                 "projector-gamma ripple)")
      ->check(cli::Integer(3, 64));
  app.add_option("--gray-cell-px", calibration_knobs.plan.min_gray_cell_camera_px,
                 "self-calibration: the finest Gray cell projected covers at least this many "
                 "camera px (larger: fewer Gray frames)")
      ->check(CLI::Range(0.5, 64.0));
  app.add_option("--bundle-iterations", calibration_knobs.solve.bundle.max_iterations,
                 "self-calibration: joint refinement iterations per round at most")
      ->check(cli::Integer(1, 1000));
  app.add_option("--bundle-free", bundle_free,
                 "self-calibration: what the joint refinement frees: all (poses, mounts, "
                 "intrinsics, distortion) or poses (the factory models held)")
      ->check(CLI::IsMember({"all", "poses"}));

  app.add_option("--render", render_mode,
                 "the show: auto (when there is a projector), on (an error without GL), off")
      ->check(CLI::IsMember({"auto", "on", "off"}));
  app.add_option("--timeline", timeline_path,
                 "personnel tracks (CSV, as the coordinator's --timeline) drawn as traces")
      ->check(CLI::ExistingFile);
  app.add_option("--sun", sun, "the virtual sun's light and shadows")
      ->check(CLI::IsMember({"on", "off"}));
  app.add_option("--sun-start-h", sun_options.start_hour, "time of day at media time 0, h")
      ->check(CLI::Range(0.0, 24.0));
  app.add_option("--sun-hours-per-s", sun_options.hours_per_media_s,
                 "hours of the day per media second")
      ->check(CLI::Range(0.0, 3600.0));
  app.add_option("--render-max-fps", render_max_fps, "frames a second at most")
      ->check(CLI::Range(0.1, 1000.0));
  app.add_option("--render-log", render_log,
                 "CSV of every shown frame: steady ns, media time (the lab's skew)");
  app.add_option("--blend", blend_mode,
                 "blend with the overlapping units (with a show): on, or off (no mask)")
      ->check(CLI::IsMember({"on", "off"}));
  app.add_option("--blend-step-px", blend_step_px, "the blend's distance field grid step, px")
      ->check(cli::Integer(1, 64));
  app.add_option("--blend-fill-limit", blend_fill_limit,
                 "past the correction limit the others make up a projector's shortfall, each at "
                 "most this many times its share (1: it clips alone)")
      ->check(CLI::Range(1.0, 100.0));
  app.add_option("--blend-edge-soft-mm", blend_edge_soft_mm,
                 "within this distance of its edge a projector's alpha leaves 0 with zero slope "
                 "(0: Algorithm 1's plain distance), mm")
      ->check(CLI::Range(0.0, 100.0));
  app.add_option("--blend-soft-face-m2", blend_soft_face_m2,
                 "the blend's face-area threshold: soft edges (--blend-edge-soft-mm) only on "
                 "planar faces of at least this area, m^2 (0: every face)")
      ->check(CLI::Range(0.0, 1e6));
  app.add_option("--black-match", black_match,
                 "raise the black where fewer projectors overlap to the site's highest (needs "
                 "the black level measured in self-calibration): on or off")
      ->check(CLI::IsMember({"on", "off"}));
  if (std::optional<int> exit = cli::Parse(app, argc, argv)) return *exit;
  if (calibrate->parsed()) return node::RunCalibrateUnit(calibrate->remaining());
  if (render_frame->parsed()) return node::RunRenderFrame(render_frame->remaining());
  auto usage = [&](const std::string& why) { return cli::UsageError(app, why); };
  if (app.count("--id") == 0) return usage("--id is required");
  if (coordinator.empty()) return usage("--coordinator is required");
  if (!true_pose_path.empty() && factory_path.empty()) {
    return usage("--true-pose needs --factory (the pose goes beside the factory intrinsics)");
  }
  options.id = id;
  const size_t comma = coordinator.find(',');
  options.coordinator_requests = coordinator.substr(0, comma);
  options.coordinator_events = coordinator.substr(comma + 1);
  options.heartbeat_period = std::chrono::milliseconds(heartbeat_ms);
  options.coordinator_timeout = std::max(options.coordinator_timeout, 5 * options.heartbeat_period);
  options.time_sync_period = std::max(options.time_sync_period, options.heartbeat_period);
  options.peer_timeout = std::max(options.peer_timeout, 5 * options.heartbeat_period);
  if (!curve_keys.empty()) {
    Expected<net::CurveKeyPair> keys = net::ReadCurveKeyFile(curve_keys);
    if (!keys.ok()) return usage("--curve-keys: " + keys.status().ToString());
    options.curve = *keys;
  }
  SetLogTag("node-" + std::to_string(options.id));

  // What the unit knows of itself: its factory calibration, and in the lab's test mode its
  // true pose.
  std::optional<UnitCalibration> calibration;
  if (!factory_path.empty()) {
    Expected<UnitCalibration> factory = LoadUnitCalibration(factory_path);
    if (!factory.ok()) return usage("--factory: " + factory.status().ToString());
    if (factory->unit_id != kInvalidNodeId && factory->unit_id != options.id) {
      return usage("--factory: " + factory_path + " is unit " + std::to_string(factory->unit_id) +
                   "'s, this node is " + std::to_string(options.id));
    }
    factory->unit_id = options.id;
    calibration = *factory;
    if (!true_pose_path.empty()) {
      Expected<node::TruePose> pose = node::LoadTruePose(true_pose_path);
      if (!pose.ok()) return usage("--true-pose: " + pose.status().ToString());
      Expected<UnitCalibration> composed = node::ComposeTruePoseCalibration(*factory, *pose);
      if (!composed.ok()) return usage("--true-pose: " + composed.status().ToString());
      calibration = *composed;
      ST_LOG(kWarning) << "TEST MODE: holding the true pose handed by the lab (source "
                       << calibration->source << ")";
    }
    node::NodeCapabilities& caps = options.capabilities;
    caps.projector_width_px = calibration->projector.width_px;
    caps.projector_height_px = calibration->projector.height_px;
    caps.camera_width_px = calibration->camera.width_px;
    caps.camera_height_px = calibration->camera.height_px;
  }
  std::optional<UnitCalibration> saved;
  if (!saved_path.empty()) {
    Expected<UnitCalibration> loaded = LoadUnitCalibration(saved_path);
    if (!loaded.ok()) return usage("--saved-calibration: " + loaded.status().ToString());
    if (loaded->unit_id != kInvalidNodeId && loaded->unit_id != options.id) {
      return usage("--saved-calibration: " + saved_path + " is unit " +
                   std::to_string(loaded->unit_id) + "'s, this node is " +
                   std::to_string(options.id));
    }
    if (loaded->source != kSourceStructuredLight || !loaded->table_from_projector) {
      return usage("--saved-calibration: " + saved_path +
                   " is not a site calibration (source structured_light with "
                   "table_from_projector)");
    }
    if (factory_path.empty()) return usage("--saved-calibration needs --factory");
    loaded->unit_id = options.id;
    saved = *loaded;
  }
  std::shared_ptr<const cluster::PersonnelTracks> tracks;
  if (!timeline_path.empty()) {
    Expected<cluster::PersonnelTracks> loaded = cluster::PersonnelTracks::Load(timeline_path);
    if (!loaded.ok()) return usage("--timeline: " + loaded.status().ToString());
    tracks = std::make_shared<const cluster::PersonnelTracks>(std::move(*loaded));
  }
  sun_options.enabled = sun == "on";
  std::shared_ptr<const Scene> model;
  if (!model_path.empty()) {
    Expected<Scene> loaded = LoadGltfScene(model_path);
    if (!loaded.ok()) return usage("--model: " + loaded.status().ToString());
    model = std::make_shared<const Scene>(std::move(*loaded));
  }
  if (!world.empty()) {
    if (projector_spec.empty()) projector_spec = "world:" + world;
    if (camera_spec.empty()) camera_spec = "world:" + world;
  }
  if (!projector_spec.empty()) {
    if (Expected<node::DeviceSpec> p = node::ParseProjectorSpec(projector_spec); !p.ok()) {
      return usage("--projector: " + p.status().message());
    }
  }
  if (!camera_spec.empty()) {
    if (Expected<node::DeviceSpec> c = node::ParseCameraSpec(camera_spec); !c.ok()) {
      return usage("--camera: " + c.status().message());
    }
  }
  auto kind = [](const std::string& spec) {
    return spec.empty() ? std::string("none") : spec.substr(0, spec.find(':'));
  };
  options.capabilities.projector_output = kind(projector_spec);
  options.capabilities.camera_input = kind(camera_spec);

  // The devices, through their interfaces only. The projector opens now (a missing display
  // is one clear line and exit 1) and starts black; the camera opens on a worker, since the
  // first capture of a world camera builds the world's light transport (seconds).
  node::DeviceOptions device_options;
  device_options.node_id = options.id;
  device_options.world_curve = options.curve;  // the site key also admits the node to the world
  if (calibration) {
    device_options.projector_size_px =
        cv::Size(calibration->projector.width_px, calibration->projector.height_px);
    device_options.camera_size_px =
        cv::Size(calibration->camera.width_px, calibration->camera.height_px);
  }
  std::unique_ptr<node::ProjectorOutput> projector;
  if (!projector_spec.empty()) {
    Expected<std::unique_ptr<node::ProjectorOutput>> opened =
        node::MakeProjectorOutput(projector_spec, device_options);
    if (!opened.ok()) {
      std::cerr << "sandtable-node: projector " << projector_spec << ": "
                << opened.status().message() << "\n";
      return cli::kExitFailure;
    }
    projector = std::move(*opened);
    const cv::Size size = projector->size();
    options.capabilities.projector_width_px = size.width;
    options.capabilities.projector_height_px = size.height;
    Expected<node::ShownFrame> shown = projector->Show(cv::Mat::zeros(size, CV_8UC1));
    if (!shown.ok()) {
      std::cerr << "sandtable-node: projector " << projector->description() << ": "
                << shown.status().message() << "\n";
      return cli::kExitFailure;
    }
  }

  // The show: the renderer on its own thread, drawing once the unit holds a calibration.
  std::unique_ptr<node::RenderLoop> render_loop;
  if (projector && render_mode != "off") {
    node::RenderLoopOptions render_options;
    render_options.max_fps = render_max_fps;
    render_options.frame_log_path = render_log;
    Expected<std::unique_ptr<node::RenderLoop>> started =
        node::RenderLoop::Start(projector.get(), model, render_options, tracks);
    if (!started.ok()) {
      if (render_mode == "on") {
        std::cerr << "sandtable-node: render: " << started.status().message() << "\n";
        return cli::kExitFailure;
      }
      ST_LOG(kWarning) << "no show (--render auto): " << started.status().message();
      WriteJsonLine(std::cout,
                    {{"render", options.id}, {"unavailable", started.status().message()}});
    } else {
      render_loop = std::move(*started);
      ST_LOG(kInfo) << "render: " << render_loop->Summary().context;
    }
  }

  struct sigaction action {};
  action.sa_handler = OnSignal;
  sigaction(SIGINT, &action, nullptr);
  sigaction(SIGTERM, &action, nullptr);

  // Declared before the runtime: destroyed after it, so no worker job outlives the service's
  // camera.
  std::unique_ptr<node::SelfCalibrationService> self_calibration;
  std::unique_ptr<node::BlendService> blend;
  node::NodeRuntime runtime(options);
  node::EventStateService events;
  runtime.AddService(&events);
  std::unique_ptr<node::RenderService> render_service;
  if (render_loop) {
    node::RenderServiceOptions render_service_options;
    render_service_options.sun = sun_options;
    render_service = std::make_unique<node::RenderService>(
        &events, render_loop.get(), render_service_options,
        [](const nlohmann::json& line) { WriteJsonLine(std::cout, line); });
    runtime.AddService(render_service.get());
  }
  if (render_loop && blend_mode == "on") {
    node::BlendServiceOptions blend_options;
    blend_options.blend.grid_step_px = blend_step_px;
    blend_options.blend.fill_limit = blend_fill_limit;
    blend_options.blend.edge_soft_m = 1e-3 * blend_edge_soft_mm;
    blend_options.blend.edge_soft_min_face_m2 = blend_soft_face_m2;
    blend_options.export_dir = export_dir;
    blend_options.black_match = black_match == "on";
    blend = std::make_unique<node::BlendService>(
        model, render_loop.get(), blend_options,
        [](const nlohmann::json& line) { WriteJsonLine(std::cout, line); });
    runtime.AddService(blend.get());
  }
  // Self-calibration (structured light with the neighbours) when the unit has its factory
  // calibration, a projector and a camera, and is not in the lab's true-pose test mode.
  if (calibration && true_pose_path.empty() && projector && !camera_spec.empty()) {
    node::SelfCalibrationOptions sc;
    sc.plan = calibration_knobs.plan;
    sc.solve.bundle.max_iterations = calibration_knobs.solve.bundle.max_iterations;
    if (bundle_free == "poses") {
      node::BundleOptions& b = sc.solve.bundle;
      b.free_projector_intrinsics = b.free_projector_distortion = false;
      b.free_camera_intrinsics = b.free_camera_distortion = b.free_mounts = false;
    }
    sc.grid_step_px = grid_step_px;
    sc.expected_units = calibration_knobs.expected_units;
    sc.path = calibration_path == "full" ? node::SelfCalibrationOptions::Path::kFull
                                         : node::SelfCalibrationOptions::Path::kAuto;
    self_calibration = std::make_unique<node::SelfCalibrationService>(
        *calibration, projector.get(), model, sc,
        [&, id = options.id](const node::SelfCalibrationOutcome& outcome) {
          calibration = outcome.calibration;
          // The blend starts once the export is written (the runner then rewrites its MPCDI
          // export with every unit's alpha map).
          auto start_blend = [&] {
            if (!blend) return;
            if (outcome.site_mpcdi && !export_dir.empty()) {
              blend->SetSiteMpcdi(outcome.site_mpcdi, export_dir + "/site.mpcdi");
            }
            blend->SetCalibration(outcome.calibration, outcome.round, outcome.overlapping, runtime,
                                  outcome.report.value("runner", kInvalidNodeId));
          };
          if (export_dir.empty()) {
            start_blend();
            return;
          }
          Expected<nlohmann::json> line = node::ExportSelfCalibration(outcome, id, export_dir);
          start_blend();
          if (!line.ok()) {
            ST_LOG(kError) << "cannot export the calibration: " << line.status().ToString();
            return;
          }
          WriteJsonLine(std::cout, *line);
        },
        [id = options.id](const std::string& reason) {
          WriteJsonLine(std::cout, {{"calibration_failed", id}, {"reason", reason}});
        });
    runtime.set_calibration_state(saved ? wire::CALIBRATION_STATE_SAVED
                                        : wire::CALIBRATION_STATE_NONE);
    if (saved) {
      self_calibration->SetSavedCalibration(
          *saved, [](const nlohmann::json& line) { WriteJsonLine(std::cout, line); });
    }
    if (render_loop) self_calibration->SetRenderLoop(render_loop.get());
    runtime.AddService(self_calibration.get());
  }
  if (saved && !self_calibration) {
    return usage(
        "--saved-calibration needs self-calibration: a projector, a camera, no --true-pose");
  }
  Status started = runtime.Start();
  if (!started.ok()) {
    ST_LOG(kError) << "cannot start: " << started.ToString();
    return cli::kExitFailure;
  }
  std::unique_ptr<node::CameraInput> camera;
  if (!camera_spec.empty()) {
    runtime.workers().Run<Expected<std::unique_ptr<node::CameraInput>>>(
        [camera_spec, device_options, id = options.id] {
          // A world busy with a large site's captures (grid-64) may not answer the size probe
          // in time: UNAVAILABLE is tried again (kCameraOpenAttempts in all); anything else
          // (a bad spec, a refused request) fails at once.
          Expected<std::unique_ptr<node::CameraInput>> opened =
              node::MakeCameraInput(camera_spec, device_options);
          for (int attempt = 2; attempt <= kCameraOpenAttempts && !opened.ok() &&
                                opened.status().code() == StatusCode::kUnavailable && !g_stop;
               ++attempt) {
            ST_LOG(kWarning) << "unit " << id << ": camera " << camera_spec << ": "
                             << opened.status().message() << "; trying again (attempt " << attempt
                             << " of " << kCameraOpenAttempts << ")";
            opened = node::MakeCameraInput(camera_spec, device_options);
          }
          return opened;
        },
        [&camera, &self_calibration, camera_spec,
         id = options.id](Expected<std::unique_ptr<node::CameraInput>> opened) {
          if (!opened.ok()) {
            ST_LOG(kError) << "camera " << camera_spec << ": " << opened.status().message();
            if (self_calibration) {
              WriteJsonLine(std::cout,
                            {{"calibration_failed", id},
                             {"reason", "unit " + std::to_string(id) + ": camera " + camera_spec +
                                            ": " + opened.status().message()}});
            }
            return;
          }
          ST_LOG(kInfo) << "camera " << (*opened)->description() << " " << (*opened)->size().width
                        << "x" << (*opened)->size().height << ", " << (*opened)->bit_depth()
                        << " bit";
          if (self_calibration) {
            self_calibration->SetCamera(std::move(*opened));
          } else {
            camera = std::move(*opened);
          }
        });
  }
  WriteJsonLine(
      std::cout,
      {{"ready", "sandtable-node"}, {"id", options.id}, {"peer", runtime.peer_endpoint()}});
  if (calibration && !export_dir.empty() && !self_calibration) {
    Expected<node::ExportedCalibration> exported =
        node::ExportCalibration(*calibration, export_dir);
    if (!exported.ok()) {
      ST_LOG(kError) << "cannot export the calibration: " << exported.status().ToString();
      runtime.SayGoodbye("export failed");
      return cli::kExitFailure;
    }
    WriteJsonLine(std::cout, {{"calibrated", options.id},
                              {"source", calibration->source},
                              {"json", exported->json_path},
                              {"yaml", exported->yaml_path}});
  }
  if (calibration && render_loop && !self_calibration && calibration->table_from_projector) {
    // A unit that starts calibrated (the lab's true-pose mode) shows at once.
    runtime.workers().Run<Status>(
        [loop = render_loop.get(), c = *calibration] { return loop->ShowCalibration(c); },
        [&blend, &runtime, c = *calibration](Status shown) {
          if (!shown.ok()) {
            ST_LOG(kWarning) << "render: " << shown.message();
            return;
          }
          // Neighbours unknown (no round): the field goes to every linked peer.
          if (blend) blend->SetCalibration(c, 0, std::nullopt, runtime);
        });
  }
  Status ran = runtime.Run(g_stop);
  if (render_service) WriteJsonLine(std::cout, render_service->SummaryJson(options.id));
  {
    const net::ChannelFaultCounts faults = runtime.fault_counts();
    WriteJsonLine(std::cout, {{"messages", options.id},
                              {"accepted", runtime.counters().accepted()},
                              {"rejected", runtime.counters().total_rejected()},
                              {"faults_dropped", faults.dropped},
                              {"faults_corrupted", faults.corrupted}});
  }
  if (auto offset = runtime.clock_offset()) {
    ST_LOG(kInfo) << "clock offset to coordinator " << offset->offset_s * 1e3
                  << " ms, error <= " << offset->error_bound_s * 1e3 << " ms over "
                  << offset->samples << " samples";
  }
  ST_LOG(kInfo) << "stopping; messages " << runtime.counters().ToString() << "; annotations "
                << events.annotations().strokes().size() << " strokes";
  return ran.ok() ? 0 : cli::kExitFailure;
}

int main(int argc, char** argv) {
  return sandtable::GuardedMain(argc, argv, "sandtable-node", Run);
}
