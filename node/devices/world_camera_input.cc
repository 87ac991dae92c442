#include "node/devices/world_camera_input.h"

#include <cmath>
#include <cstring>

#include "common/base/log.h"

namespace sandtable::node {
namespace {

std::string SizeText(cv::Size s) {
  return std::to_string(s.width) + "x" + std::to_string(s.height);
}

DeviceClock::time_point FromNs(int64_t ns) {
  return DeviceClock::time_point(
      std::chrono::duration_cast<DeviceClock::duration>(std::chrono::nanoseconds(ns)));
}

}  // namespace

Expected<std::unique_ptr<WorldCameraInput>> WorldCameraInput::Create(
    std::shared_ptr<WorldLink> link, const WorldCameraOptions& options) {
  if (!link) return InvalidArgumentError("world camera: no world link");
  ST_RETURN_IF_ERROR(options.Check());
  if (options.camera_id == kInvalidCameraId) {
    return InvalidArgumentError("world camera: invalid camera id");
  }
  std::unique_ptr<WorldCameraInput> camera(new WorldCameraInput(link, options.camera_id));
  if (options.size_px && (options.size_px->width <= 0 || options.size_px->height <= 0)) {
    return InvalidArgumentError(camera->description() + ": size " + SizeText(*options.size_px) +
                                " must be positive");
  }
  if (options.bit_depth && (*options.bit_depth < 1 || *options.bit_depth > 16)) {
    return InvalidArgumentError(camera->description() + ": bit depth " +
                                std::to_string(*options.bit_depth) + " must be in 1..16");
  }
  if (options.size_px && options.bit_depth) {
    camera->size_px_ = *options.size_px;
    camera->bit_depth_ = *options.bit_depth;
    return camera;
  }
  // Probe: one capture tells the size and depth (and warms the world's transport map).
  int depth = 0;
  Expected<CapturedFrame> probe = camera->Request(Seconds(0.0), &depth);
  if (!probe.ok()) return probe.status().WithContext("probing the camera's size");
  camera->size_px_ = options.size_px.value_or(probe->image.size());
  camera->bit_depth_ = options.bit_depth.value_or(depth);
  if (probe->image.size() != camera->size_px_ || depth != camera->bit_depth_) {
    return InvalidArgumentError(camera->description() + ": the world's camera is " +
                                SizeText(probe->image.size()) + " " + std::to_string(depth) +
                                " bit, the unit expects " + SizeText(camera->size_px_) + " " +
                                std::to_string(camera->bit_depth_) + " bit");
  }
  return camera;
}

std::string WorldCameraInput::description() const {
  return "world " + link_->endpoint() + " camera " + std::to_string(camera_id_);
}

Expected<CapturedFrame> WorldCameraInput::Request(Seconds exposure, int* bit_depth) {
  if (!std::isfinite(exposure.count()) || exposure.count() < 0.0) {
    return InvalidArgumentError(description() + ": exposure " + std::to_string(exposure.count()) +
                                " s must be finite and >= 0 (0 = the camera's own)");
  }
  wire::Envelope request;
  request.mutable_capture_request()->set_camera_id(camera_id_);
  request.mutable_capture_request()->set_exposure_s(exposure.count());
  const DeviceClock::time_point sent = DeviceClock::now();
  Expected<wire::Envelope> reply = link_->Ask(std::move(request), wire::Envelope::kCaptureReply);
  const DeviceClock::time_point received = DeviceClock::now();
  if (!reply.ok()) return reply.status();
  const wire::CaptureReply& answer = reply->capture_reply();
  if (!answer.ok())
    return InvalidArgumentError("world " + link_->endpoint() + ": " + answer.message());
  if (answer.camera_id() != camera_id_) {
    return InternalError(description() + ": the world answered for camera " +
                         std::to_string(answer.camera_id()));
  }
  int type = 0;
  size_t bytes_per_pixel = 0;
  switch (answer.encoding()) {
    case wire::PIXEL_ENCODING_GRAY8:
      type = CV_8UC1;
      bytes_per_pixel = 1;
      break;
    case wire::PIXEL_ENCODING_GRAY16:
      type = CV_16UC1;
      bytes_per_pixel = 2;
      break;
    default:
      return InternalError(description() + ": capture encoding " +
                           std::to_string(answer.encoding()) + " is not GRAY8 or GRAY16");
  }
  const cv::Size size(static_cast<int>(answer.width_px()), static_cast<int>(answer.height_px()));
  const size_t expected_bytes =
      static_cast<size_t>(answer.width_px()) * answer.height_px() * bytes_per_pixel;
  if (size.width <= 0 || size.height <= 0 || answer.pixels().size() != expected_bytes) {
    return InternalError(description() + ": capture of " + SizeText(size) + " carries " +
                         std::to_string(answer.pixels().size()) + " pixel bytes (expected " +
                         std::to_string(expected_bytes) + ")");
  }
  const int depth = static_cast<int>(answer.bit_depth());
  if (depth < 1 || depth > 16 || (type == CV_8UC1) != (depth <= 8)) {
    return InternalError(description() + ": capture bit depth " + std::to_string(depth) +
                         " does not fit its encoding");
  }
  CapturedFrame frame;
  frame.image.create(size, type);
  // GRAY16 is little endian on the wire, as on every machine this runs on (x86-64, arm64).
  std::memcpy(frame.image.data, answer.pixels().data(), expected_bytes);
  const DeviceClock::time_point stamped = FromNs(answer.capture_time_ns());
  // A camera with a driver queue delivers exposures older than the request (up to its queue's
  // length of frames); the world's stamp is taken back to kQueuedStampWindow before it.
  constexpr auto kQueuedStampWindow = std::chrono::seconds(2);
  frame.capture_time = (stamped >= sent - kQueuedStampWindow && stamped <= received)
                           ? stamped
                           : sent + (received - sent) / 2;
  *bit_depth = depth;
  return frame;
}

Expected<CapturedFrame> WorldCameraInput::Capture(Seconds exposure) {
  int depth = 0;
  Expected<CapturedFrame> frame = Request(exposure, &depth);
  if (!frame.ok()) return frame.status();
  if (frame->image.size() != size_px_ || depth != bit_depth_) {
    return InternalError(description() + ": captured " + SizeText(frame->image.size()) + " " +
                         std::to_string(depth) + " bit, expected " + SizeText(size_px_) + " " +
                         std::to_string(bit_depth_) +
                         " bit (the unit's factory camera and the "
                         "world's disagree)");
  }
  frame->index = ++captures_;
  ST_LOG(kDebug) << description() << ": capture " << frame->index;
  return frame;
}

Status WorldCameraOptions::Check() const {
  if (size_px && (size_px->width <= 0 || size_px->height <= 0)) {
    return InvalidArgumentError("world camera: size_px must be positive");
  }
  if (bit_depth && (*bit_depth < 1 || *bit_depth > 16)) {
    return InvalidArgumentError("world camera: bit_depth must be 1-16");
  }
  return OkStatus();
}

}  // namespace sandtable::node
