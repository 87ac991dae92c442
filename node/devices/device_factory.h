// The node's devices from a command-line string, so that `sandtable-node --projector SPEC
// --camera SPEC` chooses them and nothing above ProjectorOutput / CameraInput knows which.
//
// Projector specs:
//   world:ENDPOINT            the simulated world's projector of this unit (e.g.
//                             world:tcp://127.0.0.1:5555)
//   window:N                  fullscreen GLFW window on monitor N (0 = primary)
//   window:N:windowed[:WxH]   an undecorated WxH window on monitor N (default: the unit's
//                             projector size if known, else 1280x800)
// Camera specs:
//   world:ENDPOINT            the simulated world's camera of this unit
//   video:N                   V4L2 device /dev/videoN through OpenCV
//   video:URL                 any stream or file OpenCV opens (rtsp://..., http://..., a.mp4)
//   replay:DIR                a recorded capture folder played back as a live camera
// A projector and a camera of the same world share one connection (WorldLink::Shared).
// Errors: a malformed spec is INVALID_ARGUMENT listing the forms above; a device that is not
// there is the implementation's one-line error (UNAVAILABLE / NOT_FOUND naming it).
#pragma once

#include <chrono>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "common/base/ids.h"
#include "net/curve.h"
#include "node/devices/camera_input.h"
#include "node/devices/projector_output.h"

namespace sandtable::node {

// What the unit knows about itself that devices need.
struct DeviceOptions {
  NodeId node_id = kInvalidNodeId;  // world: the sender id and the projector / camera id
  // The unit's projector resolution (its factory calibration). world: required; a windowed
  // window: its size unless the spec gives one. Fullscreen windows use the monitor's mode.
  std::optional<cv::Size> projector_size_px;
  // The unit's camera resolution and bit depth. world: checked against every capture (learnt
  // by one probe capture when absent); video: asked of the device.
  std::optional<cv::Size> camera_size_px;
  std::optional<int> camera_bit_depth;
  std::chrono::milliseconds world_connect_timeout{2000};
  std::chrono::milliseconds world_reply_timeout{60000};
  std::optional<net::CurveKeyPair> world_curve;  // world: connect with CURVE (site keys)
  Status Check() const;
};

// A parsed spec (exposed for tests and for --help texts).
struct DeviceSpec {
  enum class Kind { kWorld, kWindow, kVideo, kReplay };
  Kind kind = Kind::kWorld;
  std::string target;                      // world endpoint, video device, replay folder
  int monitor_index = 0;                   // window
  bool windowed = false;                   // window
  std::optional<cv::Size> window_size_px;  // window:N:windowed:WxH
};

inline constexpr std::string_view kProjectorSpecForms =
    "world:ENDPOINT, window:N or window:N:windowed[:WxH]";
inline constexpr std::string_view kCameraSpecForms =
    "world:ENDPOINT, video:N, video:URL or replay:DIR";

Expected<DeviceSpec> ParseProjectorSpec(std::string_view spec);
Expected<DeviceSpec> ParseCameraSpec(std::string_view spec);

Expected<std::unique_ptr<ProjectorOutput>> MakeProjectorOutput(std::string_view spec,
                                                               const DeviceOptions& options);
Expected<std::unique_ptr<CameraInput>> MakeCameraInput(std::string_view spec,
                                                       const DeviceOptions& options);

}  // namespace sandtable::node
