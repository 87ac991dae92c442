#include "node/app/node_config.h"

#include <algorithm>
#include <map>

#include "common/cli/command_line.h"
#include "node/devices/device_factory.h"

namespace sandtable::node {
namespace {

Status Bad(const std::string& why) { return InvalidArgumentError(why); }

template <typename T>
bool Within(T v, T lo, T hi) {
  return v >= lo && v <= hi;
}

template <typename E>
CLI::Option* AddEnum(CLI::App& app, const std::string& name, E& value,
                     const std::map<std::string, E>& names, const std::string& help) {
  return app.add_option(name, value, help)->transform(CLI::CheckedTransformer(names));
}

void AddSiteFlags(CLI::App& app, NodeConfig& c) {
  app.add_option("--id", c.id, "this unit's node id (below 4294967280)")
      ->check(cli::Integer<uint32_t>(0, kFirstReservedSenderId - 1));
  app.add_option_function<std::string>(
         "--coordinator",
         [&c](const std::string& v) {
           const size_t comma = v.find(',');
           c.coordinator_requests = v.substr(0, comma);
           c.coordinator_events = v.substr(comma + 1);
         },
         "the coordinator's REQUESTS,EVENTS endpoints (its ready line)")
      ->check([](const std::string& v) {
        return v.find(',') == std::string::npos ? std::string("needs REQUESTS,EVENTS") : "";
      });
  app.add_option("--bind", c.peer_bind, "own ROUTER for peers")->check(cli::Endpoint());
  app.add_option("--curve-keys", c.curve_keys_path,
                 "site CURVE key file (sandtable-coordinator "
                 "--generate-curve-keys)")
      ->check(CLI::ExistingFile);
  app.add_option("--heartbeat-ms", c.heartbeat_ms, "heartbeat period in ms")
      ->check(cli::Integer(1, 60000));
  app.add_option("--workers", c.worker_threads, "worker threads for long work")
      ->check(cli::Integer(1, 64));
  app.add_option("--fault-drop-share", c.faults.drop_share,
                 "LAB CHAOS ONLY: drop this share of the messages the node sends")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--fault-corrupt-share", c.faults.corrupt_share,
                 "LAB CHAOS ONLY: corrupt this share of the messages the node sends")
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--fault-seed", c.faults.seed, "seed of the injected faults");
}

void AddUnitFlags(CLI::App& app, NodeConfig& c) {
  app.add_option("--world", c.world,
                 "the simulated world's endpoint: projector and camera are "
                 "world-backed")
      ->check(cli::Endpoint());
  app.add_option("--projector", c.projector_spec,
                 "the projector: " + std::string(kProjectorSpecForms) +
                     " (default with --world: world:ENDPOINT)");
  app.add_option(
      "--camera", c.camera_spec,
      "the camera: " + std::string(kCameraSpecForms) + " (default with --world: world:ENDPOINT)");
  app.add_option("--factory", c.factory_path, "the unit's factory calibration file")
      ->check(CLI::ExistingFile);
  app.add_option("--true-pose", c.true_pose_path,
                 "LAB TEST MODE: the unit's true pose (source factory+true_pose); needs --factory")
      ->check(CLI::ExistingFile);
  app.add_option("--export-dir", c.export_dir, "where unit-<id>.json and .yaml are written");
  app.add_option("--model", c.model_path,
                 "the glTF model on the table: self-calibration finds where it stands")
      ->check(CLI::ExistingFile);
  app.add_option("--saved-calibration", c.saved_calibration_path,
                 "a calibration this unit saved in an earlier run (unit-<id>.json, source "
                 "structured_light): checked with two frames and kept when it holds")
      ->check(CLI::ExistingFile);
}

// The knobs `sandtable-lab sweep` turns (docs/lab.md, "Sweep"): run time against error.
void AddCalibrationFlags(CLI::App& app, NodeConfig& c) {
  app.add_option("--expect-units", c.expected_units,
                 "self-calibration: the site's number of units; the first round waits (at most "
                 "3 min) until that many are members")
      ->check(cli::Integer(0, 4096));
  AddEnum<SelfCalibrationOptions::Path>(
      app, "--calibration-path", c.calibration_path,
      {{"auto", SelfCalibrationOptions::Path::kAuto},
       {"full", SelfCalibrationOptions::Path::kFull}},
      "self-calibration: auto (the planar path when every footprint is planar) or full");
  app.add_option("--grid-step-px", c.grid_step_px,
                 "self-calibration: projector grid spacing of the correspondences, px")
      ->check(cli::Integer(4, 256));
  app.add_option("--phase-steps", c.phase_steps,
                 "self-calibration: phase-shift steps per direction (fewer: fewer frames, more "
                 "projector-gamma ripple)")
      ->check(cli::Integer(3, 64));
  app.add_option("--gray-cell-px", c.gray_cell_px,
                 "self-calibration: the finest Gray cell projected covers at least this many "
                 "camera px (larger: fewer Gray frames)")
      ->check(CLI::Range(0.5, 64.0));
  app.add_option("--bundle-iterations", c.bundle_iterations,
                 "self-calibration: joint refinement iterations per round at most")
      ->check(cli::Integer(1, 1000));
  AddEnum<BundleFree>(app, "--bundle-free", c.bundle_free,
                      {{"all", BundleFree::kAll}, {"poses", BundleFree::kPoses}},
                      "self-calibration: what the joint refinement frees: all (poses, mounts, "
                      "intrinsics, distortion) or poses (the factory models held)");
}

void AddShowFlags(CLI::App& app, NodeConfig& c) {
  AddEnum<RenderMode>(
      app, "--render", c.render,
      {{"auto", RenderMode::kAuto}, {"on", RenderMode::kOn}, {"off", RenderMode::kOff}},
      "the show: auto (when there is a projector), on (an error without GL), off");
  app.add_option("--timeline", c.timeline_path,
                 "personnel tracks (CSV, as the coordinator's --timeline) drawn as traces")
      ->check(CLI::ExistingFile);
  AddEnum<bool>(app, "--sun", c.sun.enabled, {{"on", true}, {"off", false}},
                "the virtual sun's light and shadows");
  app.add_option("--sun-start-h", c.sun.start_hour, "time of day at media time 0, h")
      ->check(CLI::Range(0.0, 24.0));
  app.add_option("--sun-hours-per-s", c.sun.hours_per_media_s, "hours of the day per media second")
      ->check(CLI::Range(0.0, 3600.0));
  app.add_option("--render-max-fps", c.render_max_fps, "frames a second at most")
      ->check(CLI::Range(0.1, 1000.0));
  app.add_option("--render-log", c.render_log_path,
                 "CSV of every shown frame: steady ns, media time (the lab's skew)");
  AddEnum<bool>(app, "--blend", c.blend, {{"on", true}, {"off", false}},
                "blend with the overlapping units (with a show): on, or off (no mask)");
  app.add_option("--blend-step-px", c.blend_step_px, "the blend's distance field grid step, px")
      ->check(cli::Integer(1, 64));
  app.add_option("--blend-fill-limit", c.blend_fill_limit,
                 "past the correction limit the others make up a projector's shortfall, each at "
                 "most this many times its share (1: it clips alone)")
      ->check(CLI::Range(1.0, 100.0));
  app.add_option("--blend-edge-soft-mm", c.blend_edge_soft_mm,
                 "within this distance of its edge a projector's alpha leaves 0 with zero slope "
                 "(0: Algorithm 1's plain distance), mm")
      ->check(CLI::Range(0.0, 100.0));
  app.add_option("--blend-soft-face-m2", c.blend_soft_face_m2,
                 "the blend's face-area threshold: soft edges (--blend-edge-soft-mm) only on "
                 "planar faces of at least this area, m^2 (0: every face)")
      ->check(CLI::Range(0.0, 1e6));
  AddEnum<bool>(app, "--black-match", c.black_match, {{"on", true}, {"off", false}},
                "raise the black where fewer projectors overlap to the site's highest (needs "
                "the black level measured in self-calibration): on or off");
}

}  // namespace

Status NodeConfig::Check() const {
  if (id == kInvalidNodeId) return Bad("--id is required");
  if (id >= kFirstReservedSenderId) return Bad("--id must be below 4294967280");
  if (coordinator_requests.empty() || coordinator_events.empty()) {
    return Bad("--coordinator is required (REQUESTS,EVENTS)");
  }
  if (!true_pose_path.empty() && factory_path.empty()) {
    return Bad("--true-pose needs --factory (the pose goes beside the factory intrinsics)");
  }
  if (!saved_calibration_path.empty() && factory_path.empty()) {
    return Bad("--saved-calibration needs --factory");
  }
  if (!Within(heartbeat_ms, 1, 60000)) return Bad("--heartbeat-ms must be 1-60000");
  if (!Within(worker_threads, 1, 64)) return Bad("--workers must be 1-64");
  if (!Within(faults.drop_share, 0.0, 1.0) || !Within(faults.corrupt_share, 0.0, 1.0)) {
    return Bad("--fault-drop-share and --fault-corrupt-share must be 0-1");
  }
  if (!Within(grid_step_px, 4, 256)) return Bad("--grid-step-px must be 4-256");
  if (!Within(expected_units, 0, 4096)) return Bad("--expect-units must be 0-4096");
  if (!Within(phase_steps, 3, 64)) return Bad("--phase-steps must be 3-64");
  if (!Within(gray_cell_px, 0.5, 64.0)) return Bad("--gray-cell-px must be 0.5-64");
  if (!Within(bundle_iterations, 1, 1000)) return Bad("--bundle-iterations must be 1-1000");
  if (!Within(render_max_fps, 0.1, 1000.0)) return Bad("--render-max-fps must be 0.1-1000");
  if (!Within(blend_step_px, 1, 64)) return Bad("--blend-step-px must be 1-64");
  if (!Within(blend_fill_limit, 1.0, 100.0)) return Bad("--blend-fill-limit must be 1-100");
  if (!Within(blend_edge_soft_mm, 0.0, 100.0)) return Bad("--blend-edge-soft-mm must be 0-100");
  if (!Within(blend_soft_face_m2, 0.0, 1e6)) return Bad("--blend-soft-face-m2 must be 0-1e6");
  if (Status sun_ok = sun.Check(); !sun_ok.ok()) return Bad("--sun-*: " + sun_ok.message());
  if (Status sc = SelfCalibration().Check(); !sc.ok()) return Bad(sc.message());
  const std::string projector =
      projector_spec.empty() && !world.empty() ? "world:" + world : projector_spec;
  const std::string camera = camera_spec.empty() && !world.empty() ? "world:" + world : camera_spec;
  if (!projector.empty()) {
    if (Expected<DeviceSpec> p = ParseProjectorSpec(projector); !p.ok()) {
      return Bad("--projector: " + p.status().message());
    }
  }
  if (!camera.empty()) {
    if (Expected<DeviceSpec> p = ParseCameraSpec(camera); !p.ok()) {
      return Bad("--camera: " + p.status().message());
    }
  }
  return OkStatus();
}

NodeOptions NodeConfig::RuntimeOptions() const {
  NodeOptions o;
  o.id = id;
  o.coordinator_requests = coordinator_requests;
  o.coordinator_events = coordinator_events;
  o.peer_bind = peer_bind;
  o.heartbeat_period = std::chrono::milliseconds(heartbeat_ms);
  o.coordinator_timeout = std::max(o.coordinator_timeout, 5 * o.heartbeat_period);
  o.time_sync_period = std::max(o.time_sync_period, o.heartbeat_period);
  o.peer_timeout = std::max(o.peer_timeout, 5 * o.heartbeat_period);
  o.worker_threads = worker_threads;
  o.faults = faults;
  return o;
}

SelfCalibrationOptions NodeConfig::SelfCalibration() const {
  SelfCalibrationOptions sc;
  sc.plan.phase_steps = phase_steps;
  sc.plan.min_gray_cell_camera_px = gray_cell_px;
  sc.solve.bundle.max_iterations = bundle_iterations;
  if (bundle_free == BundleFree::kPoses) {
    BundleOptions& b = sc.solve.bundle;
    b.free_projector_intrinsics = b.free_projector_distortion = false;
    b.free_camera_intrinsics = b.free_camera_distortion = b.free_mounts = false;
  }
  sc.grid_step_px = grid_step_px;
  sc.expected_units = expected_units;
  sc.path = calibration_path;
  return sc;
}

void AddNodeFlags(CLI::App& app, NodeConfig& config) {
  AddSiteFlags(app, config);
  AddUnitFlags(app, config);
  AddCalibrationFlags(app, config);
  AddShowFlags(app, config);
}

}  // namespace sandtable::node
