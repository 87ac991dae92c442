#include "net/channel.h"

#include <utility>

namespace sandtable::net {

Channel::Channel(std::unique_ptr<Socket> socket, uint32_t sender_id, uint64_t incarnation,
                 proto::MessageCounters* counters, proto::CodecLimits limits)
    : socket_(std::move(socket)),
      stamper_(sender_id, incarnation),
      counters_(counters),
      limits_(limits) {
  ST_CHECK(socket_ != nullptr) << "Channel needs a socket";
  ST_CHECK(counters_ != nullptr) << "Channel needs message counters";
}

Status Channel::Send(wire::Envelope envelope, const std::string& routing_id) {
  wire::Envelope header = stamper_.Next();
  envelope.set_protocol_version(header.protocol_version());
  envelope.set_sender_id(header.sender_id());
  envelope.set_sender_incarnation(header.sender_incarnation());
  envelope.set_sequence(header.sequence());
  envelope.set_send_time_ns(header.send_time_ns());
  Expected<std::string> bytes = proto::EncodeEnvelope(std::move(envelope), limits_);
  if (!bytes.ok()) return bytes.status();
  const size_t size = bytes->size();
  Status sent = socket_->type() == SocketType::kRouter
                    ? socket_->Send({routing_id, std::move(*bytes)})
                    : socket_->Send({std::move(*bytes)});
  if (sent.ok()) {
    ++stats_.messages_sent;
    stats_.bytes_sent += size;
  }
  return sent;
}

Expected<std::optional<Incoming>> Channel::TryReceive() {
  Expected<std::optional<std::vector<std::string>>> frames = socket_->TryReceive();
  if (!frames.ok()) return frames.status();
  if (!frames->has_value()) return std::optional<Incoming>();
  std::vector<std::string>& parts = **frames;
  Incoming incoming;
  const size_t expected_frames = socket_->type() == SocketType::kRouter ? 2 : 1;
  for (const std::string& part : parts) stats_.bytes_received += part.size();
  if (parts.size() != expected_frames) {
    counters_->CountRejected(proto::RejectReason::kMalformed);
    return ParseError("message with " + std::to_string(parts.size()) + " frames, expected " +
                      std::to_string(expected_frames));
  }
  if (expected_frames == 2) incoming.routing_id = std::move(parts[0]);
  const std::string& payload = parts.back();
  incoming.wire_bytes = payload.size();
  Expected<wire::Envelope> envelope = proto::DecodeEnvelope(payload, limits_, counters_);
  if (!envelope.ok()) return envelope.status();
  ST_RETURN_IF_ERROR(tracker_.Accept(*envelope, counters_));
  counters_->CountAccepted();
  ++stats_.messages_received;
  incoming.envelope = std::move(*envelope);
  return std::optional<Incoming>(std::move(incoming));
}

}  // namespace sandtable::net
