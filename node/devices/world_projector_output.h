// WorldProjectorOutput: a projector of the simulated world. Show() sends a SetFrameRequest
// (GRAY8 or RGB8, tightly packed rows) for this unit's projector over the node's WorldLink and
// waits for the SetFrameReply; the frame is in effect in the world once the reply is here.
//
// The size is what the unit believes its projector to be (its factory calibration); it is not
// learnt from the world. A frame of another size is refused here (INVALID_ARGUMENT); when the
// world's projector differs from what the unit believes, the world refuses the frame and its
// message comes back unchanged (INVALID_ARGUMENT "world ...: set_frame projector 3: frame is
// 640x400, projector is 1280x800"). A dead world is UNAVAILABLE (world_link.h's deadlines).
#pragma once

#include <memory>
#include <string>

#include "common/base/ids.h"
#include "node/devices/projector_output.h"
#include "node/devices/world_link.h"

namespace sandtable::node {

class WorldProjectorOutput : public ProjectorOutput {
 public:
  // INVALID_ARGUMENT for a null link, an invalid id or a non-positive size. Sends nothing.
  static Expected<std::unique_ptr<WorldProjectorOutput>> Create(std::shared_ptr<WorldLink> link,
                                                                ProjectorId projector_id,
                                                                cv::Size size_px);

  cv::Size size() const override { return size_px_; }
  std::string description() const override;
  Expected<ShownFrame> Show(const cv::Mat& frame) override;
  Expected<ShownFrame> Mute() override;  // a SetFrameRequest with `muted`: the world's "off"

 private:
  WorldProjectorOutput(std::shared_ptr<WorldLink> link, ProjectorId id, cv::Size size_px)
      : link_(std::move(link)), projector_id_(id), size_px_(size_px) {}

  std::shared_ptr<WorldLink> link_;
  ProjectorId projector_id_;
  cv::Size size_px_;
  Expected<ShownFrame> Send(wire::Envelope request);
  uint64_t frames_shown_ = 0;
};

}  // namespace sandtable::node
