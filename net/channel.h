// Channel: a Socket that speaks Envelopes. It stamps outgoing headers (version, sender,
// incarnation, sequence, send time), encodes/compresses, and on receive decodes, validates,
// checks sequence order per sender and counts rejections (MessageCounters) and bytes.
//
// Framing: ROUTER sockets see [routing_id, envelope]; all others see [envelope]. DEALER <->
// ROUTER use no empty delimiter frame. A message with any other frame count is rejected
// (counted malformed). Not thread-safe.
#pragma once

#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "net/socket.h"
#include "proto/codec.h"
#include "proto/envelope.pb.h"
#include "proto/envelope_stamper.h"
#include "proto/message_counters.h"
#include "proto/sequence_tracker.h"

namespace sandtable::net {

struct Incoming {
  std::string routing_id;  // ROUTER only: who sent it (reply with the same id)
  // ROUTER with CURVE only: the sender's CURVE public key (Z85) as ZAP let it through, and its
  // address; empty otherwise.
  std::string peer_key, peer_address;
  wire::Envelope envelope;
  size_t wire_bytes = 0;
};

// A message the channel refused (malformed, invalid, out of order), with what a server needs
// to answer the sender: its routing id (ROUTER only; empty when the frames were unusable) and
// the envelope's sequence when it could be read (0 otherwise).
struct Refusal {
  std::string routing_id;
  uint64_t sequence = 0;
  Status status;
};

// One receive: a message, a refusal, or nothing waiting (both empty).
struct Received {
  std::optional<Incoming> message;
  std::optional<Refusal> refusal;
};

struct ChannelStats {
  uint64_t messages_sent = 0;
  uint64_t bytes_sent = 0;
  uint64_t messages_received = 0;  // accepted
  uint64_t bytes_received = 0;     // of all messages, accepted or not
};

// Fault injection for the lab's chaos runs (docs/reliability.md, "Faults on a link"): of the
// messages this channel sends, a share is dropped (Send() reports success, nothing leaves: a
// lossy link) and a share corrupted (1 to 4 bytes of the encoded message flipped after
// encoding, so the receiver's codec and checks meet it), drawn per message from a generator
// seeded with `seed`; and every message leaves `delay` +- `jitter` (uniform) after Send(), in
// the order sent (a link's latency: TCP keeps the order), held in the channel until
// FlushDelayed() finds it due. Off (all 0) by default; a product node turns it on only through
// its --fault-* flags. This machine's kernel has no netem: this is where the lab's latency
// comes from (docs/lab.md).
struct ChannelFaults {
  double drop_share = 0.0;
  double corrupt_share = 0.0;
  uint64_t seed = 1;
  std::chrono::microseconds delay{0};
  std::chrono::microseconds jitter{0};
  bool active() const { return drop_share > 0.0 || corrupt_share > 0.0 || delay.count() > 0; }
  Status Check() const;  // shares in [0, 1], their sum at most 1; 0 <= jitter <= delay <= 10 s
};

struct ChannelFaultCounts {
  uint64_t dropped = 0;
  uint64_t corrupted = 0;
  uint64_t delayed = 0;          // messages held for the injected latency
  uint64_t delayed_dropped = 0;  // held messages that could not be sent when due, or overflowed
};

// Most messages a channel holds for the injected latency; more are dropped (counted).
inline constexpr size_t kMaxDelayedMessages = 10000;

class Channel {
 public:
  // `counters` may be shared between channels of one process; it must outlive the channel.
  Channel(std::unique_ptr<Socket> socket, uint32_t sender_id, uint64_t incarnation,
          proto::MessageCounters* counters, proto::CodecLimits limits = {});

  // Fills the header of `envelope` (whose body the caller has set) and sends it. For ROUTER
  // sockets `routing_id` names the receiver. UNAVAILABLE when it cannot be queued.
  Status Send(wire::Envelope envelope, const std::string& routing_id = {});
  // ROUTER only: sends one envelope to each of `routing_ids`, stamped and encoded once, so that
  // every receiver sees the same sequence number; (*results)[i] is the send to routing_ids[i]
  // (NOT_FOUND: not connected; UNAVAILABLE: its queue is full). An encoding failure is the
  // error.
  Status SendToEach(wire::Envelope envelope, const std::vector<std::string>& routing_ids,
                    std::vector<Status>* results);

  // One message if one is waiting and valid; nullopt when none is waiting. A rejected message
  // returns its Status (already counted); the caller logs it and carries on.
  Expected<std::optional<Incoming>> TryReceive();
  // As TryReceive, but a refused message comes back with its sender's routing id so that a
  // server can answer it (net/server_loop.h). Socket failures are the error.
  Expected<Received> Receive();

  // Forget a sender's sequence (it left or restarted).
  void ForgetSender(uint32_t sender_id) { tracker_.Forget(sender_id); }
  // Senders whose sequence state is kept (bounded, proto/sequence_tracker.h).
  size_t tracked_senders() const { return tracker_.size(); }

  // Sends the held messages (injected latency) whose time has come, in order. Call it on every
  // turn of the owner's loop, and wake by next_delayed_due().
  void FlushDelayed(std::chrono::steady_clock::time_point now);
  std::optional<std::chrono::steady_clock::time_point> next_delayed_due() const;

  // Turns fault injection on (or off with both shares 0). INVALID_ARGUMENT from Check().
  Status SetFaults(const ChannelFaults& faults);
  const ChannelFaultCounts& fault_counts() const { return fault_counts_; }

  Socket& socket() { return *socket_; }
  const ChannelStats& stats() const { return stats_; }
  proto::MessageCounters& counters() { return *counters_; }

 private:
  // Stamps the header and encodes; nullopt when fault injection drops the message (counted).
  Expected<std::optional<std::string>> StampAndEncode(wire::Envelope envelope);
  // Sends now, or holds for the injected latency.
  Status SendOrHold(std::vector<std::string> frames, size_t size);
  struct Held {
    std::chrono::steady_clock::time_point due;
    std::vector<std::string> frames;
    size_t size = 0;
  };

  std::unique_ptr<Socket> socket_;
  proto::EnvelopeStamper stamper_;
  proto::SequenceTracker tracker_;
  proto::MessageCounters* counters_;
  proto::CodecLimits limits_;
  ChannelStats stats_;
  ChannelFaults faults_;
  std::mt19937_64 fault_random_;
  ChannelFaultCounts fault_counts_;
  std::deque<Held> held_;
};

}  // namespace sandtable::net
