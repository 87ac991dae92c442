#include "node/app/node_config.h"

#include <algorithm>
#include <map>
#include <sstream>

#include "common/cli/command_line.h"
#include "net/endpoint.h"
#include "node/devices/device_factory.h"

namespace sandtable::node {
namespace {

Status Bad(const std::string& why) { return InvalidArgumentError(why); }

// A flag's range: checked as it parses (a configuration file's values too: they are read into
// flags), shown in --help, and again by NodeConfig::Check for a NodeConfig filled in code.
template <typename T>
struct Limit {
  const char* flag;
  T lo, hi;
};
constexpr Limit<int> kHeartbeatMs{"--heartbeat-ms", 1, 60000};
constexpr Limit<int> kWorkers{"--workers", 1, 64};
constexpr Limit<double> kDropShare{"--fault-drop-share", 0.0, 1.0};
constexpr Limit<double> kCorruptShare{"--fault-corrupt-share", 0.0, 1.0};
constexpr Limit<double> kDelayMs{"--fault-delay-ms", 0.0, 10000.0};
constexpr Limit<double> kJitterMs{"--fault-jitter-ms", 0.0, 10000.0};
constexpr Limit<double> kClockOffsetS{"--test-clock-offset-s", -86400.0, 86400.0};
constexpr Limit<int> kExpectUnits{"--expect-units", 0, 4096};
constexpr Limit<int> kGridStepPx{"--grid-step-px", 4, 256};
constexpr Limit<int> kPhaseSteps{"--phase-steps", 3, 64};
constexpr Limit<double> kGrayCellPx{"--gray-cell-px", 0.5, 64.0};
constexpr Limit<int> kBundleIterations{"--bundle-iterations", 1, 1000};
constexpr Limit<double> kSunStartH{"--sun-start-h", 0.0, 24.0};
constexpr Limit<double> kSunHoursPerS{"--sun-hours-per-s", 0.0, 3600.0};
constexpr Limit<double> kRenderMaxFps{"--render-max-fps", 0.1, 1000.0};
constexpr Limit<int> kBlendStepPx{"--blend-step-px", 1, 64};
constexpr Limit<double> kBlendFillLimit{"--blend-fill-limit", 1.0, 100.0};
constexpr Limit<double> kBlendEdgeSoftMm{"--blend-edge-soft-mm", 0.0, 100.0};
constexpr Limit<double> kBlendSoftFaceM2{"--blend-soft-face-m2", 0.0, 1e6};

CLI::Validator Validator(const Limit<int>& l) { return cli::Integer(l.lo, l.hi); }
CLI::Validator Validator(const Limit<double>& l) { return cli::Real(l.lo, l.hi); }

template <typename T>
Status InRange(const Limit<T>& l, T v) {
  if (v >= l.lo && v <= l.hi) return OkStatus();
  std::ostringstream out;
  out << l.flag << " must be in [" << l.lo << ", " << l.hi << "]";
  return Bad(out.str());
}

// Adds `limit.flag` writing into `value`, checked against the limit.
template <typename T>
void AddLimited(CLI::App& app, const Limit<T>& limit, T& value, const std::string& help) {
  app.add_option(limit.flag, value, help)->check(Validator(limit));
}

template <typename E>
CLI::Option* AddEnum(CLI::App& app, const std::string& name, E& value,
                     const std::map<std::string, E>& names, const std::string& help) {
  return app.add_option(name, value, help)->transform(CLI::CheckedTransformer(names));
}

void AddSiteFlags(CLI::App& app, NodeConfig& c) {
  cli::NoDefaultShown(
      app.add_option("--id", c.id, "this unit's node id (required; below 4294967280)")
          ->check(cli::Integer<uint32_t>(0, kFirstReservedSenderId - 1)));
  app.add_option_function<std::string>(
         "--coordinator",
         [&c](const std::string& v) {
           if (v == kDiscover) {
             c.coordinator_requests = kDiscover;
             c.coordinator_events.clear();
             return;
           }
           const size_t comma = v.find(',');
           c.coordinator_requests = v.substr(0, comma);
           c.coordinator_events = v.substr(comma + 1);
         },
         "the coordinator's REQUESTS,EVENTS endpoints (its ready line), or 'discover': its "
         "beacon on the LAN (--discovery-port, --site-name)")
      ->check([](const std::string& v) {
        return v == kDiscover || v.find(',') != std::string::npos
                   ? std::string()
                   : std::string("needs REQUESTS,EVENTS or discover");
      });
  app.add_option("--site-name", c.site_name,
                 "with --coordinator discover: join only the site of this name");
  app.add_option("--discovery-port", c.discovery_port,
                 "with --coordinator discover: the UDP port of the coordinator's beacon")
      ->check(cli::Integer(1, 65535));
  app.add_option("--bind", c.peer_bind, "own ROUTER for peers")->check(cli::Endpoint());
  app.add_option("--advertise", c.peer_advertise,
                 "the host (name or address) peers connect to; default: the bound address, or "
                 "with tcp://*:PORT the interface facing the coordinator");
  app.add_option("--curve-keys", c.curve_keys_path,
                 "site CURVE key file (sandtable-coordinator "
                 "--generate-curve-keys)")
      ->check(CLI::ExistingFile);
  app.add_option("--enroll", c.enroll_keys_path,
                 "with --coordinator discover: the site's key file; while it does not exist, ask "
                 "the site's operator to accept this unit and write the key handed over there "
                 "(docs/deploy.md, \"Accepting a new unit\")")
      ->excludes("--curve-keys");
  app.add_flag("--insecure", c.insecure,
               "allow --bind beyond loopback without --curve-keys (an open site: anyone on the "
               "network may talk to the node; logged every minute)");
  AddLimited(app, kHeartbeatMs, c.heartbeat_ms, "heartbeat period in ms");
  AddLimited(app, kWorkers, c.worker_threads, "worker threads for long work");
  AddLimited(app, kDropShare, c.faults.drop_share,
             "LAB CHAOS ONLY: drop this share of the messages the node sends");
  AddLimited(app, kCorruptShare, c.faults.corrupt_share,
             "LAB CHAOS ONLY: corrupt this share of the messages the node sends");
  AddLimited(app, kDelayMs, c.fault_delay_ms,
             "LAB CHAOS ONLY: every message the node sends leaves this many ms later (in order)");
  AddLimited(app, kJitterMs, c.fault_jitter_ms,
             "LAB CHAOS ONLY: the delay varies by up to this many ms either way (<= the delay)");
  app.add_option("--fault-seed", c.faults.seed, "seed of the injected faults");
  AddLimited(app, kClockOffsetS, c.test_clock_offset_s,
             "LAB TEST ONLY: this node's clock reads this many seconds from the machine's (as "
             "another host's clock would)");
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
                 "structured_light): checked with two frames and kept when it holds; when the "
                 "file does not exist yet (a unit's first start) the unit calibrates");
}

// The knobs `sandtable-lab sweep` turns (docs/lab.md, "Sweep"): run time against error.
void AddCalibrationFlags(CLI::App& app, NodeConfig& c) {
  AddLimited(app, kExpectUnits, c.expected_units,
             "self-calibration: the site's number of units; the first round waits (at most "
             "3 min) until that many are members");
  AddEnum<SelfCalibrationOptions::Path>(
      app, "--calibration-path", c.calibration_path,
      {{"auto", SelfCalibrationOptions::Path::kAuto},
       {"full", SelfCalibrationOptions::Path::kFull}},
      "self-calibration: auto (the planar path when every footprint is planar) or full");
  AddLimited(app, kGridStepPx, c.grid_step_px,
             "self-calibration: projector grid spacing of the correspondences, px");
  AddLimited(app, kPhaseSteps, c.phase_steps,
             "self-calibration: phase-shift steps per direction (fewer: fewer frames, more "
             "projector-gamma ripple)");
  AddLimited(app, kGrayCellPx, c.gray_cell_px,
             "self-calibration: the finest Gray cell projected covers at least this many "
             "camera px (larger: fewer Gray frames)");
  AddLimited(app, kBundleIterations, c.bundle_iterations,
             "self-calibration: joint refinement iterations per round at most");
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
  AddLimited(app, kSunStartH, c.sun.start_hour, "time of day at media time 0, h");
  AddLimited(app, kSunHoursPerS, c.sun.hours_per_media_s, "hours of the day per media second");
  AddLimited(app, kRenderMaxFps, c.render_max_fps, "frames a second at most");
  app.add_option("--render-log", c.render_log_path,
                 "CSV of every shown frame: steady ns, media time (the lab's skew)");
  AddEnum<bool>(app, "--blend", c.blend, {{"on", true}, {"off", false}},
                "blend with the overlapping units (with a show): on, or off (no mask)");
  AddLimited(app, kBlendStepPx, c.blend_step_px, "the blend's distance field grid step, px");
  AddLimited(app, kBlendFillLimit, c.blend_fill_limit,
             "past the correction limit the others make up a projector's shortfall, each at "
             "most this many times its share (1: it clips alone)");
  AddLimited(app, kBlendEdgeSoftMm, c.blend_edge_soft_mm,
             "within this distance of its edge a projector's alpha leaves 0 with zero slope "
             "(0: Algorithm 1's plain distance), mm");
  AddLimited(app, kBlendSoftFaceM2, c.blend_soft_face_m2,
             "the blend's face-area threshold: soft edges (--blend-edge-soft-mm) only on "
             "planar faces of at least this area, m^2 (0: every face)");
  AddEnum<bool>(app, "--black-match", c.black_match, {{"on", true}, {"off", false}},
                "raise the black where fewer projectors overlap to the site's highest (needs "
                "the black level measured in self-calibration): on or off");
}

}  // namespace

Status NodeConfig::Check() const {
  if (id == kInvalidNodeId) return Bad("--id is required");
  if (id >= kFirstReservedSenderId) return Bad("--id must be below 4294967280");
  if (coordinator_requests != kDiscover &&
      (coordinator_requests.empty() || coordinator_events.empty())) {
    return Bad("--coordinator is required (REQUESTS,EVENTS, or discover)");
  }
  if (!true_pose_path.empty() && factory_path.empty()) {
    return Bad("--true-pose needs --factory (the pose goes beside the factory intrinsics)");
  }
  if (!saved_calibration_path.empty() && factory_path.empty()) {
    return Bad("--saved-calibration needs --factory");
  }
  if (!enroll_keys_path.empty() && coordinator_requests != kDiscover) {
    return Bad("--enroll needs --coordinator discover (the beacon names the site to ask)");
  }
  if (curve_keys_path.empty() && enroll_keys_path.empty() && !insecure &&
      net::BeyondLoopback(peer_bind)) {
    return Bad("--bind " + peer_bind +
               " is beyond loopback: it needs --curve-keys (or --insecure for an open site anyone "
               "on the network may talk to)");
  }
  for (const Status& s :
       {InRange(kHeartbeatMs, heartbeat_ms), InRange(kWorkers, worker_threads),
        InRange(kDropShare, faults.drop_share), InRange(kCorruptShare, faults.corrupt_share),
        InRange(kDelayMs, fault_delay_ms), InRange(kJitterMs, fault_jitter_ms),
        InRange(kClockOffsetS, test_clock_offset_s), InRange(kExpectUnits, expected_units),
        InRange(kGridStepPx, grid_step_px), InRange(kPhaseSteps, phase_steps),
        InRange(kGrayCellPx, gray_cell_px), InRange(kBundleIterations, bundle_iterations),
        InRange(kRenderMaxFps, render_max_fps), InRange(kSunStartH, sun.start_hour),
        InRange(kSunHoursPerS, sun.hours_per_media_s), InRange(kBlendStepPx, blend_step_px),
        InRange(kBlendFillLimit, blend_fill_limit), InRange(kBlendEdgeSoftMm, blend_edge_soft_mm),
        InRange(kBlendSoftFaceM2, blend_soft_face_m2)}) {
    if (!s.ok()) return s;
  }
  if (Status sun_ok = sun.Check(); !sun_ok.ok()) return Bad("--sun-*: " + sun_ok.message());
  if (Status sc = SelfCalibration().Check(); !sc.ok()) return Bad(sc.message());
  const std::string projector = ProjectorSpec();
  const std::string camera = CameraSpec();
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

std::string NodeConfig::ProjectorSpec() const {
  return projector_spec.empty() && !world.empty() ? "world:" + world : projector_spec;
}

std::string NodeConfig::CameraSpec() const {
  return camera_spec.empty() && !world.empty() ? "world:" + world : camera_spec;
}

NodeOptions NodeConfig::RuntimeOptions() const {
  NodeOptions o;
  o.id = id;
  o.coordinator_requests = coordinator_requests;
  o.coordinator_events = coordinator_events;
  o.peer_bind = peer_bind;
  o.peer_advertise_host = peer_advertise;
  o.insecure = insecure;
  o.heartbeat_period = std::chrono::milliseconds(heartbeat_ms);
  o.coordinator_timeout = std::max(o.coordinator_timeout, 5 * o.heartbeat_period);
  o.time_sync_period = std::max(o.time_sync_period, o.heartbeat_period);
  o.peer_timeout = std::max(o.peer_timeout, 5 * o.heartbeat_period);
  o.worker_threads = worker_threads;
  o.faults = faults;
  o.faults.delay = std::chrono::microseconds(static_cast<int64_t>(fault_delay_ms * 1000.0));
  o.faults.jitter = std::chrono::microseconds(static_cast<int64_t>(fault_jitter_ms * 1000.0));
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
