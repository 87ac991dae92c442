// WorldCameraInput: a camera of the simulated world. Capture() sends a CaptureRequest for this
// unit's camera over the node's WorldLink and turns the CaptureReply (GRAY8, or GRAY16 little
// endian for bit depths above 8) into a CapturedFrame.
//
// Size and bit depth: given (the unit's factory camera size) or, when either is not given,
// learnt by one probe capture in Create() (which also makes the world build its transport map
// for this camera, the slow part of a first capture). Every capture is checked against them:
// a reply of another size, depth or camera is INTERNAL naming both. A capture the world
// refuses is INVALID_ARGUMENT with the world's message; a dead world is UNAVAILABLE.
// Capture time: the world stamps its capture with the exposure's start on its steady clock; on
// one host (the lab) that is this process's clock too, and it is used when it lies within the
// request's round trip or up to 2 s before it (a queued exposure, sim/site/device_timing.h).
// Otherwise (another host) the middle of the round trip stands in for it.
#pragma once

#include <memory>
#include <optional>
#include <string>

#include "common/base/ids.h"
#include "node/devices/camera_input.h"
#include "node/devices/world_link.h"

namespace sandtable::node {

struct WorldCameraOptions {
  CameraId camera_id = kInvalidCameraId;  // the unit's id in the site (today its node id)
  std::optional<cv::Size> size_px;        // the unit's factory camera size; probed if absent
  std::optional<int> bit_depth;           // 1..16; probed if absent
  Status Check() const;
};

class WorldCameraInput : public CameraInput {
 public:
  static Expected<std::unique_ptr<WorldCameraInput>> Create(std::shared_ptr<WorldLink> link,
                                                            const WorldCameraOptions& options);

  cv::Size size() const override { return size_px_; }
  int bit_depth() const override { return bit_depth_; }
  std::string description() const override;
  Expected<CapturedFrame> Capture(Seconds exposure) override;

 private:
  WorldCameraInput(std::shared_ptr<WorldLink> link, CameraId id)
      : link_(std::move(link)), camera_id_(id) {}
  // One request and its decoded image, unchecked against size_px_ / bit_depth_.
  Expected<CapturedFrame> Request(Seconds exposure, int* bit_depth);

  std::shared_ptr<WorldLink> link_;
  CameraId camera_id_;
  cv::Size size_px_;
  int bit_depth_ = 0;
  uint64_t captures_ = 0;
};

}  // namespace sandtable::node
