#include "node/devices/device_factory.h"

#include <charconv>

#include "node/devices/replay_camera_input.h"
#include "node/devices/video_camera_input.h"
#include "node/devices/window_projector_output.h"
#include "node/devices/world_camera_input.h"
#include "node/devices/world_link.h"
#include "node/devices/world_projector_output.h"

namespace sandtable::node {
namespace {

std::optional<int> ParseInt(std::string_view text) {
  int value = 0;
  const char* end = text.data() + text.size();
  auto [ptr, error] = std::from_chars(text.data(), end, value);
  if (text.empty() || error != std::errc() || ptr != end || value < 0) return std::nullopt;
  return value;
}

// "1280x800" -> (1280, 800).
std::optional<cv::Size> ParseSize(std::string_view text) {
  const size_t x = text.find('x');
  if (x == std::string_view::npos) return std::nullopt;
  const std::optional<int> w = ParseInt(text.substr(0, x)), h = ParseInt(text.substr(x + 1));
  if (!w || !h || *w <= 0 || *h <= 0) return std::nullopt;
  return cv::Size(*w, *h);
}

// Splits "kind:rest" at the first colon.
bool SplitKind(std::string_view spec, std::string_view* kind, std::string_view* rest) {
  const size_t colon = spec.find(':');
  if (colon == std::string_view::npos) return false;
  *kind = spec.substr(0, colon);
  *rest = spec.substr(colon + 1);
  return true;
}

Status BadSpec(std::string_view role, std::string_view spec, std::string_view forms,
               std::string_view why = {}) {
  return InvalidArgumentError(std::string(role) + " '" + std::string(spec) +
                              "': " + (why.empty() ? std::string() : std::string(why) + "; ") +
                              "expected " + std::string(forms));
}

Expected<std::shared_ptr<WorldLink>> LinkFor(const DeviceSpec& spec, const DeviceOptions& options) {
  WorldLinkOptions link;
  link.endpoint = spec.target;
  link.node_id = options.node_id;
  link.connect_timeout = options.world_connect_timeout;
  link.reply_timeout = options.world_reply_timeout;
  link.curve = options.world_curve;
  return WorldLink::Shared(link);
}

}  // namespace

Expected<DeviceSpec> ParseProjectorSpec(std::string_view spec) {
  constexpr std::string_view kRole = "projector";
  std::string_view kind, rest;
  if (!SplitKind(spec, &kind, &rest)) return BadSpec(kRole, spec, kProjectorSpecForms);
  DeviceSpec parsed;
  if (kind == "world") {
    if (rest.empty()) return BadSpec(kRole, spec, kProjectorSpecForms, "no endpoint");
    parsed.kind = DeviceSpec::Kind::kWorld;
    parsed.target = std::string(rest);
    return parsed;
  }
  if (kind != "window") return BadSpec(kRole, spec, kProjectorSpecForms, "unknown kind");
  parsed.kind = DeviceSpec::Kind::kWindow;
  const size_t colon = rest.find(':');
  const std::optional<int> monitor = ParseInt(rest.substr(0, colon));
  if (!monitor) return BadSpec(kRole, spec, kProjectorSpecForms, "monitor N is a number >= 0");
  parsed.monitor_index = *monitor;
  if (colon == std::string_view::npos) return parsed;
  std::string_view mode = rest.substr(colon + 1);
  const size_t size_colon = mode.find(':');
  if (mode.substr(0, size_colon) != "windowed") {
    return BadSpec(kRole, spec, kProjectorSpecForms, "after the monitor only 'windowed'");
  }
  parsed.windowed = true;
  if (size_colon != std::string_view::npos) {
    parsed.window_size_px = ParseSize(mode.substr(size_colon + 1));
    if (!parsed.window_size_px) {
      return BadSpec(kRole, spec, kProjectorSpecForms, "window size is WxH, e.g. 1280x800");
    }
  }
  return parsed;
}

Expected<DeviceSpec> ParseCameraSpec(std::string_view spec) {
  constexpr std::string_view kRole = "camera";
  std::string_view kind, rest;
  if (!SplitKind(spec, &kind, &rest)) return BadSpec(kRole, spec, kCameraSpecForms);
  if (rest.empty()) return BadSpec(kRole, spec, kCameraSpecForms, "nothing after the colon");
  DeviceSpec parsed;
  parsed.target = std::string(rest);
  if (kind == "world") {
    parsed.kind = DeviceSpec::Kind::kWorld;
  } else if (kind == "video") {
    parsed.kind = DeviceSpec::Kind::kVideo;
  } else if (kind == "replay") {
    parsed.kind = DeviceSpec::Kind::kReplay;
  } else {
    return BadSpec(kRole, spec, kCameraSpecForms, "unknown kind");
  }
  return parsed;
}

Expected<std::unique_ptr<ProjectorOutput>> MakeProjectorOutput(std::string_view spec,
                                                               const DeviceOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  Expected<DeviceSpec> parsed = ParseProjectorSpec(spec);
  if (!parsed.ok()) return parsed.status();
  if (parsed->kind == DeviceSpec::Kind::kWorld) {
    if (!options.projector_size_px) {
      return InvalidArgumentError("projector '" + std::string(spec) +
                                  "': the unit's projector size is unknown (give the unit's "
                                  "factory calibration)");
    }
    Expected<std::shared_ptr<WorldLink>> link = LinkFor(*parsed, options);
    if (!link.ok()) return link.status();
    Expected<std::unique_ptr<WorldProjectorOutput>> output =
        WorldProjectorOutput::Create(*link, options.node_id, *options.projector_size_px);
    if (!output.ok()) return output.status();
    return std::unique_ptr<ProjectorOutput>(std::move(*output));
  }
  WindowOptions window;
  window.monitor_index = parsed->monitor_index;
  window.windowed = parsed->windowed;
  if (parsed->window_size_px) {
    window.windowed_size_px = *parsed->window_size_px;
  } else if (options.projector_size_px) {
    window.windowed_size_px = *options.projector_size_px;
  }
  Expected<std::unique_ptr<WindowProjectorOutput>> output = WindowProjectorOutput::Open(window);
  if (!output.ok()) return output.status();
  return std::unique_ptr<ProjectorOutput>(std::move(*output));
}

Expected<std::unique_ptr<CameraInput>> MakeCameraInput(std::string_view spec,
                                                       const DeviceOptions& options) {
  ST_RETURN_IF_ERROR(options.Check());
  Expected<DeviceSpec> parsed = ParseCameraSpec(spec);
  if (!parsed.ok()) return parsed.status();
  switch (parsed->kind) {
    case DeviceSpec::Kind::kWorld: {
      Expected<std::shared_ptr<WorldLink>> link = LinkFor(*parsed, options);
      if (!link.ok()) return link.status();
      WorldCameraOptions camera;
      camera.camera_id = options.node_id;
      camera.size_px = options.camera_size_px;
      camera.bit_depth = options.camera_bit_depth;
      Expected<std::unique_ptr<WorldCameraInput>> input = WorldCameraInput::Create(*link, camera);
      if (!input.ok()) return input.status();
      return std::unique_ptr<CameraInput>(std::move(*input));
    }
    case DeviceSpec::Kind::kVideo: {
      VideoCameraOptions video;
      video.device = parsed->target;
      video.size_px = options.camera_size_px;
      Expected<std::unique_ptr<VideoCameraInput>> input = VideoCameraInput::Open(video);
      if (!input.ok()) return input.status();
      return std::unique_ptr<CameraInput>(std::move(*input));
    }
    case DeviceSpec::Kind::kReplay: {
      Expected<std::unique_ptr<ReplayCameraInput>> input = ReplayCameraInput::Open(parsed->target);
      if (!input.ok()) return input.status();
      return std::unique_ptr<CameraInput>(std::move(*input));
    }
    case DeviceSpec::Kind::kWindow:
      break;  // not a camera kind (ParseCameraSpec never returns it)
  }
  return InternalError("camera '" + std::string(spec) + "': unhandled kind");
}

Status DeviceOptions::Check() const {
  auto positive = [](const std::optional<cv::Size>& s) {
    return !s || (s->width > 0 && s->height > 0);
  };
  if (!positive(projector_size_px) || !positive(camera_size_px)) {
    return InvalidArgumentError("devices: projector and camera sizes must be positive");
  }
  if (camera_bit_depth && (*camera_bit_depth < 1 || *camera_bit_depth > 16)) {
    return InvalidArgumentError("devices: camera_bit_depth must be 1-16");
  }
  if (world_connect_timeout.count() <= 0 || world_reply_timeout.count() <= 0) {
    return InvalidArgumentError("devices: world timeouts must be > 0");
  }
  return OkStatus();
}

}  // namespace sandtable::node
