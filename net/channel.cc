#include "net/channel.h"

#include <algorithm>
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

Expected<std::optional<std::string>> Channel::StampAndEncode(wire::Envelope envelope) {
  wire::Envelope header = stamper_.Next();
  envelope.set_protocol_version(header.protocol_version());
  envelope.set_sender_id(header.sender_id());
  envelope.set_sender_incarnation(header.sender_incarnation());
  envelope.set_sequence(header.sequence());
  envelope.set_send_time_ns(header.send_time_ns());
  Expected<std::string> bytes = proto::EncodeEnvelope(std::move(envelope), limits_);
  if (!bytes.ok()) return bytes.status();
  if (faults_.active()) {
    const double u = std::uniform_real_distribution<double>(0.0, 1.0)(fault_random_);
    if (u < faults_.drop_share) {
      ++fault_counts_.dropped;
      return std::optional<std::string>();  // a lossy link: the sender cannot tell
    }
    if (u < faults_.drop_share + faults_.corrupt_share && !bytes->empty()) {
      ++fault_counts_.corrupted;
      const int flips = 1 + static_cast<int>(fault_random_() % 4);
      for (int i = 0; i < flips; ++i) {
        const size_t at = fault_random_() % bytes->size();
        (*bytes)[at] =
            static_cast<char>((*bytes)[at] ^ static_cast<char>(1 + fault_random_() % 255));
      }
    }
  }
  return std::optional<std::string>(std::move(*bytes));
}

Status Channel::SendOrHold(std::vector<std::string> frames, size_t size) {
  if (faults_.delay.count() > 0) {
    const auto now = std::chrono::steady_clock::now();
    const double jitter_us = static_cast<double>(faults_.jitter.count());
    const auto wobble = std::chrono::microseconds(static_cast<int64_t>(
        std::uniform_real_distribution<double>(-jitter_us, jitter_us)(fault_random_)));
    auto due = now + faults_.delay + wobble;
    if (!held_.empty()) due = std::max(due, held_.back().due);  // the order sent
    if (held_.size() >= kMaxDelayedMessages) {
      ++fault_counts_.delayed_dropped;
      return OkStatus();
    }
    held_.push_back(Held{due, std::move(frames), size});
    ++fault_counts_.delayed;
    return OkStatus();
  }
  Status sent = socket_->Send(frames);
  if (sent.ok()) {
    ++stats_.messages_sent;
    stats_.bytes_sent += size;
  }
  return sent;
}

void Channel::FlushDelayed(std::chrono::steady_clock::time_point now) {
  while (!held_.empty() && held_.front().due <= now) {
    if (socket_->Send(held_.front().frames).ok()) {
      ++stats_.messages_sent;
      stats_.bytes_sent += held_.front().size;
    } else {
      ++fault_counts_.delayed_dropped;  // as the link would have lost it
    }
    held_.pop_front();
  }
}

std::optional<std::chrono::steady_clock::time_point> Channel::next_delayed_due() const {
  if (held_.empty()) return std::nullopt;
  return held_.front().due;
}

Status Channel::Send(wire::Envelope envelope, const std::string& routing_id) {
  Expected<std::optional<std::string>> bytes = StampAndEncode(std::move(envelope));
  if (!bytes.ok()) return bytes.status();
  if (!bytes->has_value()) return OkStatus();
  const size_t size = (*bytes)->size();
  if (socket_->type() == SocketType::kRouter) {
    return SendOrHold({routing_id, std::move(**bytes)}, size);
  }
  return SendOrHold({std::move(**bytes)}, size);
}

Status Channel::SendToEach(wire::Envelope envelope, const std::vector<std::string>& routing_ids,
                           std::vector<Status>* results) {
  ST_CHECK(socket_->type() == SocketType::kRouter) << "Channel::SendToEach needs a ROUTER";
  results->assign(routing_ids.size(), OkStatus());
  Expected<std::optional<std::string>> bytes = StampAndEncode(std::move(envelope));
  if (!bytes.ok()) return bytes.status();
  if (!bytes->has_value()) return OkStatus();
  for (size_t i = 0; i < routing_ids.size(); ++i) {
    (*results)[i] = SendOrHold({routing_ids[i], **bytes}, (*bytes)->size());
  }
  return OkStatus();
}

Status ChannelFaults::Check() const {
  if (!(drop_share >= 0.0 && drop_share <= 1.0) ||
      !(corrupt_share >= 0.0 && corrupt_share <= 1.0) || drop_share + corrupt_share > 1.0) {
    return InvalidArgumentError("channel faults: drop share " + std::to_string(drop_share) +
                                " and corrupt share " + std::to_string(corrupt_share) +
                                " must be in [0, 1] with a sum of at most 1");
  }
  constexpr std::chrono::microseconds kMaxDelay = std::chrono::seconds(10);
  if (delay.count() < 0 || jitter.count() < 0 || jitter > delay || delay > kMaxDelay) {
    return InvalidArgumentError("channel faults: delay " + std::to_string(delay.count()) +
                                " us and jitter " + std::to_string(jitter.count()) +
                                " us must satisfy 0 <= jitter <= delay <= 10 s");
  }
  return OkStatus();
}

Status Channel::SetFaults(const ChannelFaults& faults) {
  ST_RETURN_IF_ERROR(faults.Check());
  faults_ = faults;
  fault_random_.seed(faults.seed);
  return OkStatus();
}

Expected<std::optional<Incoming>> Channel::TryReceive() {
  Expected<Received> received = Receive();
  if (!received.ok()) return received.status();
  if (received->refusal) return received->refusal->status;
  return std::move(received->message);
}

Expected<Received> Channel::Receive() {
  Socket::PeerInfo peer;
  const bool router_socket = socket_->type() == SocketType::kRouter;
  Expected<std::optional<std::vector<std::string>>> frames =
      socket_->TryReceive(router_socket ? &peer : nullptr);
  if (!frames.ok()) return frames.status();
  Received out;
  if (!frames->has_value()) return out;
  std::vector<std::string>& parts = **frames;
  const bool router = socket_->type() == SocketType::kRouter;
  const size_t expected_frames = router ? 2 : 1;
  for (const std::string& part : parts) stats_.bytes_received += part.size();
  auto refuse = [&](Status status, uint64_t sequence) {
    Refusal refusal;
    // A ROUTER always prepends the routing id, so the first frame names the sender even when
    // the rest is malformed.
    if (router && !parts.empty()) refusal.routing_id = parts.front();
    refusal.sequence = sequence;
    refusal.status = std::move(status);
    out.refusal = std::move(refusal);
    return out;
  };
  if (parts.size() != expected_frames) {
    counters_->CountRejected(proto::RejectReason::kMalformed);
    return refuse(ParseError("message with " + std::to_string(parts.size()) + " frames, expected " +
                             std::to_string(expected_frames)),
                  0);
  }
  Incoming incoming;
  if (router) incoming.routing_id = parts[0];
  incoming.peer_key = std::move(peer.user_id);
  incoming.peer_address = std::move(peer.address);
  const std::string& payload = parts.back();
  incoming.wire_bytes = payload.size();
  Expected<wire::Envelope> envelope = proto::DecodeEnvelope(payload, limits_, counters_);
  if (!envelope.ok()) return refuse(envelope.status(), 0);
  if (Status in_order = tracker_.Accept(*envelope, counters_, proto::SequenceTracker::Clock::now(),
                                        incoming.routing_id);
      !in_order.ok()) {
    return refuse(std::move(in_order), envelope->sequence());
  }
  counters_->CountAccepted();
  ++stats_.messages_received;
  incoming.envelope = std::move(*envelope);
  out.message = std::move(incoming);
  return out;
}

}  // namespace sandtable::net
