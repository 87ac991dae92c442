#include "node/devices/world_projector_output.h"

#include <cstring>

#include "common/base/log.h"

namespace sandtable::node {

Expected<std::unique_ptr<WorldProjectorOutput>> WorldProjectorOutput::Create(
    std::shared_ptr<WorldLink> link, ProjectorId projector_id, cv::Size size_px) {
  if (!link) return InvalidArgumentError("world projector: no world link");
  if (projector_id == kInvalidProjectorId) {
    return InvalidArgumentError("world projector: invalid projector id");
  }
  if (size_px.width <= 0 || size_px.height <= 0) {
    return InvalidArgumentError(
        "world " + link->endpoint() + " projector " + std::to_string(projector_id) + ": size " +
        std::to_string(size_px.width) + "x" + std::to_string(size_px.height) +
        " must be positive (the unit's factory projector size)");
  }
  return std::unique_ptr<WorldProjectorOutput>(
      new WorldProjectorOutput(std::move(link), projector_id, size_px));
}

std::string WorldProjectorOutput::description() const {
  return "world " + link_->endpoint() + " projector " + std::to_string(projector_id_);
}

Expected<ShownFrame> WorldProjectorOutput::Show(const cv::Mat& frame) {
  ST_RETURN_IF_ERROR(CheckProjectorFrame(frame, size_px_, description()));
  wire::Envelope request;
  wire::SetFrameRequest* set = request.mutable_set_frame_request();
  set->set_projector_id(projector_id_);
  set->set_width_px(static_cast<uint32_t>(frame.cols));
  set->set_height_px(static_cast<uint32_t>(frame.rows));
  set->set_encoding(frame.channels() == 1 ? wire::PIXEL_ENCODING_GRAY8 : wire::PIXEL_ENCODING_RGB8);
  set->set_frame_index(frames_shown_ + 1);
  // Tightly packed rows, whatever the frame's stride (a ROI is not continuous).
  const size_t row_bytes = static_cast<size_t>(frame.cols) * frame.elemSize();
  std::string* pixels = set->mutable_pixels();
  pixels->resize(row_bytes * static_cast<size_t>(frame.rows));
  for (int y = 0; y < frame.rows; ++y) {
    std::memcpy(pixels->data() + row_bytes * static_cast<size_t>(y), frame.ptr(y), row_bytes);
  }

  return Send(std::move(request));
}

Expected<ShownFrame> WorldProjectorOutput::Mute() {
  wire::Envelope request;
  wire::SetFrameRequest* set = request.mutable_set_frame_request();
  set->set_projector_id(projector_id_);
  set->set_width_px(static_cast<uint32_t>(size_px_.width));
  set->set_height_px(static_cast<uint32_t>(size_px_.height));
  set->set_encoding(wire::PIXEL_ENCODING_GRAY8);
  set->set_frame_index(frames_shown_ + 1);
  set->set_muted(true);
  return Send(std::move(request));
}

Expected<ShownFrame> WorldProjectorOutput::Send(wire::Envelope request) {
  Expected<wire::Envelope> reply = link_->Ask(std::move(request), wire::Envelope::kSetFrameReply);
  if (!reply.ok()) return reply.status();
  const wire::SetFrameReply& answer = reply->set_frame_reply();
  if (!answer.ok()) {
    // The world's own words ("set_frame projector 3: frame is 640x400, projector is ...").
    return InvalidArgumentError("world " + link_->endpoint() + ": " + answer.message());
  }
  ShownFrame shown;
  shown.frame_index = ++frames_shown_;
  shown.shown_time = DeviceClock::now();
  ST_LOG(kDebug) << description() << ": frame " << shown.frame_index << " shown";
  return shown;
}

}  // namespace sandtable::node
