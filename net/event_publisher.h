// EventPublisher: one server's events (the coordinator's member lists, tracker, annotation and
// timeline events) to every subscriber, over a ROUTER that the subscribers' sockets of type
// SocketType::kEventSubscriber (a DEALER) connect to.
//
// Why not PUB/SUB: a PUB or XPUB reads its subscribers' subscription messages inside libzmq,
// draining a connection's pipe while libzmq's I/O thread keeps refilling it, and stores each
// topic per connection. Four connections streaming 1 000-byte subscriptions held the
// coordinator's thread inside that loop (SIGTERM unanswered) while it grew to 10 GB in 20 s
// (docs/reliability.md, "Subscription floods"). A ROUTER hands over one message per receive and
// stops reading a connection at its high-water mark, so a flooding peer is held back by TCP,
// and what it costs does not grow with what it sends.
//
// Subscribing: a kEventSubscriber sends one empty message each time its connection is made
// (ZMQ_PROBE_ROUTER), also after a reconnect. Drain() registers the sender of each empty
// message (at most max_subscribers at once) and counts and drops anything else. Publish()
// stamps and encodes an envelope once and sends it to every subscriber without blocking: a
// subscriber whose connection is gone is forgotten (its next connection registers again), one
// whose queue is full misses that event, as a PUB would drop it; both counted.
//
// Memory: what a connection can make the publisher hold is bounded by its inbound queue
// (receive_high_water_mark x max_message_bytes, 16 KiB with the defaults) plus libzmq's
// per-connection buffers (about 2 x 8 KiB) and its outbound queue of events, whatever it
// sends. Not thread-safe (the owner's thread).
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "common/base/status.h"
#include "net/channel.h"
#include "net/socket.h"

namespace sandtable::net {

struct EventPublisherLimits {
  // ZMQ_MAXMSGSIZE of the ROUTER: subscribers send only empty messages, but the CURVE
  // handshake's commands (~300 bytes) pass the same check, so this stays above them.
  int64_t max_message_bytes = 1024;  // kMaxSubscriberMessageBytes
  // Messages libzmq may queue per connection before it stops reading that connection.
  int receive_high_water_mark = 16;
  // Subscribers registered at once; senders past it get no events (counted, logged).
  size_t max_subscribers = 1024;
  // Longest a Drain() may take, and most messages it handles, so that a flood cannot keep the
  // owner's thread (and its stop flag) waiting.
  std::chrono::milliseconds max_drain_time{10};
  int max_drain = 4096;

  Status Check() const;
};

struct EventPublisherStats {
  uint64_t registered = 0;          // subscriptions (connections) registered
  uint64_t refused = 0;             // messages that were not a subscription (dropped)
  uint64_t refused_full = 0;        // subscriptions refused: max_subscribers reached
  uint64_t forgotten = 0;           // subscribers whose connection was gone at a publish
  uint64_t dropped_queue_full = 0;  // events not queued to a subscriber whose queue was full
};

class EventPublisher {
 public:
  // Creates the ROUTER with `socket_options` (CURVE, linger) and these limits, and binds it.
  static Expected<std::unique_ptr<EventPublisher>> Bind(
      zmq::context_t* context, SocketOptions socket_options, const EventPublisherLimits& limits,
      const std::string& endpoint, uint32_t sender_id, uint64_t incarnation,
      proto::MessageCounters* counters, proto::CodecLimits codec_limits);

  const std::string& endpoint() const { return endpoint_; }
  // The socket, for a handshake monitor.
  Socket& socket() { return channel_->socket(); }

  // Reads what subscribers sent (bounded by max_drain and max_drain_time). Socket failures
  // are the error.
  Status Drain();
  // Sends `event` (body set by the caller) to every subscriber. An encoding failure (over the
  // codec's limit) is the error; a subscriber that cannot take it is not.
  Status Publish(wire::Envelope event);

  size_t subscribers() const { return subscribers_.size(); }
  const EventPublisherStats& stats() const { return stats_; }
  const EventPublisherLimits& limits() const { return limits_; }

 private:
  EventPublisher(std::unique_ptr<Channel> channel, std::string endpoint,
                 EventPublisherLimits limits)
      : channel_(std::move(channel)), endpoint_(std::move(endpoint)), limits_(limits) {}
  void Register(const std::string& routing_id);

  std::unique_ptr<Channel> channel_;
  std::string endpoint_;
  EventPublisherLimits limits_;
  std::vector<std::string> subscribers_;
  EventPublisherStats stats_;
};

}  // namespace sandtable::net
