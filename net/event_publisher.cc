#include "net/event_publisher.h"

#include <algorithm>
#include <utility>

#include "common/base/log.h"

namespace sandtable::net {

Status EventPublisherLimits::Check() const {
  if (max_message_bytes < 512) {
    return InvalidArgumentError(
        "event publisher: max_message_bytes must be at least 512 (the CURVE handshake's "
        "commands pass the same limit)");
  }
  if (receive_high_water_mark < 1 || max_subscribers < 1 || max_drain < 1 ||
      max_drain_time.count() < 1) {
    return InvalidArgumentError(
        "event publisher: receive_high_water_mark, max_subscribers, max_drain and "
        "max_drain_time must be positive");
  }
  return OkStatus();
}

Expected<std::unique_ptr<EventPublisher>> EventPublisher::Bind(
    zmq::context_t* context, SocketOptions socket_options, const EventPublisherLimits& limits,
    const std::string& endpoint, uint32_t sender_id, uint64_t incarnation,
    proto::MessageCounters* counters, proto::CodecLimits codec_limits) {
  ST_RETURN_IF_ERROR(limits.Check());
  socket_options.max_message_bytes = limits.max_message_bytes;
  socket_options.receive_high_water_mark = limits.receive_high_water_mark;
  Expected<std::unique_ptr<Socket>> router =
      Socket::Create(context, SocketType::kRouter, socket_options);
  if (!router.ok()) return router.status();
  Expected<std::string> bound = (*router)->Bind(endpoint);
  if (!bound.ok()) return bound.status();
  auto channel =
      std::make_unique<Channel>(std::move(*router), sender_id, incarnation, counters, codec_limits);
  return std::unique_ptr<EventPublisher>(
      new EventPublisher(std::move(channel), std::move(*bound), limits));
}

void EventPublisher::Register(const std::string& routing_id) {
  if (std::find(subscribers_.begin(), subscribers_.end(), routing_id) != subscribers_.end()) {
    return;
  }
  if (subscribers_.size() >= limits_.max_subscribers) {
    ++stats_.refused_full;
    ST_LOG(kWarning) << "events: a subscriber was refused: " << subscribers_.size()
                     << " subscribers already (the most at once)";
    return;
  }
  subscribers_.push_back(routing_id);
  ++stats_.registered;
}

Status EventPublisher::Drain() {
  const auto until = std::chrono::steady_clock::now() + limits_.max_drain_time;
  for (int i = 0; i < limits_.max_drain; ++i) {
    Expected<std::optional<std::vector<std::string>>> frames = channel_->socket().TryReceive();
    if (!frames.ok()) return frames.status();
    if (!frames->has_value()) break;
    const std::vector<std::string>& parts = **frames;
    // [routing id, empty]: a subscription. Anything else is not a subscriber's to send.
    if (parts.size() == 2 && parts[1].empty()) {
      Register(parts[0]);
    } else {
      ++stats_.refused;
      channel_->counters().CountRejected(proto::RejectReason::kWrongType);
      ST_LOG(kWarning) << "events: dropped a " << (parts.empty() ? 0 : parts.back().size())
                       << "-byte message from a subscriber (subscribers send nothing but their "
                          "subscription)";
    }
    if ((i & 63) == 63 && std::chrono::steady_clock::now() >= until) break;
  }
  return OkStatus();
}

Status EventPublisher::Publish(wire::Envelope event) {
  std::vector<Status> results;
  ST_RETURN_IF_ERROR(channel_->SendToEach(std::move(event), subscribers_, &results));
  size_t kept = 0;
  for (size_t i = 0; i < subscribers_.size(); ++i) {
    if (results[i].code() == StatusCode::kNotFound) {
      ++stats_.forgotten;  // its connection is gone; a new one subscribes again
      continue;
    }
    if (!results[i].ok()) ++stats_.dropped_queue_full;
    if (kept != i) subscribers_[kept] = std::move(subscribers_[i]);  // never a self-move
    ++kept;
  }
  subscribers_.resize(kept);
  return OkStatus();
}

}  // namespace sandtable::net
