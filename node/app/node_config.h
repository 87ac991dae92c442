// NodeConfig: everything a sandtable-node process is told at start, as plain values (paths,
// endpoints, numbers, enums). The command line fills it (AddNodeFlags), the site's and the
// unit's configuration files read into the same flags first (common/cli/config_file.h,
// docs/config-file.md). Check() says what is wrong, naming the flag, before anything is opened;
// NodeApp (node_app.h) loads the files it names and opens the devices.
#pragma once

#include <cstdint>
#include <string>

#include "common/base/ids.h"
#include "common/base/status.h"
#include "net/channel.h"
#include "node/app/self_calibration_service.h"
#include "node/blend/blend_field.h"
#include "node/net/node_runtime.h"
#include "node/render/show_content.h"

namespace CLI {
class App;
}

namespace sandtable::node {

// The show: kAuto renders when there is a projector and says why not when no GL context can be
// made; kOn makes that an error; kOff never renders.
enum class RenderMode { kAuto, kOn, kOff };
// What the joint refinement frees: kAll (poses, mounts, intrinsics, distortion) or kPoses (the
// factory models held).
enum class BundleFree { kAll, kPoses };

// --coordinator's value that asks for discovery instead of an address.
inline constexpr char kDiscover[] = "discover";

struct NodeConfig {
  // The site and the network (node/net/node_runtime.h).
  NodeId id = kInvalidNodeId;                            // required, below kFirstReservedSenderId
  std::string coordinator_requests, coordinator_events;  // required, or kDiscover
  // --coordinator discover: found on the LAN by its beacon (net/discovery.h) before the app
  // starts; only a site of this name (empty: any) on this UDP port.
  std::string site_name;
  int discovery_port = 5670;
  std::string peer_bind = NodeOptions{}.peer_bind;
  std::string peer_advertise;   // the host peers connect to (empty: chosen; docs/deploy.md)
  std::string curve_keys_path;  // the site's CURVE key file (empty: no CURVE)
  // --enroll: where the site's key file is (used as curve_keys_path) or, while it does not
  // exist, is written once the site's operator accepts this unit (net/site_enrollment.h).
  std::string enroll_keys_path;
  bool insecure = false;  // --bind beyond loopback without CURVE allowed (an open site)
  int heartbeat_ms = 100;
  int worker_threads = NodeOptions{}.worker_threads;
  net::ChannelFaults faults;                           // lab chaos only
  double fault_delay_ms = 0.0, fault_jitter_ms = 0.0;  // into faults.delay / jitter
  // LAB TEST ONLY: this process's clock reads this far from the machine's (common/base/
  // host_clock.h), as another host's would.
  double test_clock_offset_s = 0.0;

  // The unit: its devices (node/devices/device_factory.h; empty: none) and what it knows.
  std::string world;  // short for projector and camera world:ENDPOINT
  std::string projector_spec, camera_spec;
  std::string factory_path;            // the unit's factory calibration
  std::string true_pose_path;          // lab test mode: the true pose (needs factory_path)
  std::string saved_calibration_path;  // checked and kept when it holds (needs factory_path)
  std::string model_path;              // the glTF model on the table
  std::string export_dir;              // unit-<id>.json/.yaml (empty: nothing written)

  // Self-calibration (node/app/self_calibration_service.h).
  int grid_step_px = 16;
  SelfCalibrationOptions::Path calibration_path = SelfCalibrationOptions::Path::kAuto;
  int expected_units = 0;
  int phase_steps = PatternPlanOptions{}.phase_steps;
  double gray_cell_px = PatternPlanOptions{}.min_gray_cell_camera_px;
  int bundle_iterations = BundleOptions{}.max_iterations;
  BundleFree bundle_free = BundleFree::kAll;

  // The show and the blend (docs/render.md, docs/blend.md).
  RenderMode render = RenderMode::kAuto;
  std::string timeline_path;  // personnel tracks CSV
  SunOptions sun;
  double render_max_fps = 30.0;
  std::string render_log_path;
  bool blend = true;
  int blend_step_px = BlendOptions{}.grid_step_px;
  double blend_fill_limit = BlendOptions{}.fill_limit;
  double blend_edge_soft_mm = 1e3 * BlendOptions{}.edge_soft_m;
  double blend_soft_face_m2 = BlendOptions{}.edge_soft_min_face_m2;
  bool black_match = false;

  // INVALID_ARGUMENT naming the flag: a required value missing, a value out of its range, a
  // device spec that does not parse, a file flag that needs another.
  Status Check() const;

  // The devices' specs, --world applied (empty: none).
  std::string ProjectorSpec() const;
  std::string CameraSpec() const;
  // The runtime's options (heartbeat-derived timeouts at least 5 periods; CURVE keys not read:
  // NodeApp reads them).
  NodeOptions RuntimeOptions() const;
  // The self-calibration options these values set over the defaults.
  SelfCalibrationOptions SelfCalibration() const;
};

// Registers the node's flags (sandtable-node --help) on `app`, each writing into `config`
// (which must outlive the parse). The values are checked by range as they parse; the rest by
// NodeConfig::Check().
void AddNodeFlags(CLI::App& app, NodeConfig& config);

}  // namespace sandtable::node
