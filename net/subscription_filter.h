// SubscriptionFilter: what a publisher (an XPUB in manual mode, net/socket.h) accepts from
// its subscribers.
//
// A SUB socket sends its subscriptions upstream as messages ("\x01topic", "\x00topic" to
// cancel). libzmq keeps every subscription of every connection in a trie, about 30 bytes of
// memory per byte of topic: 20 000 subscriptions of 200 bytes cost the publisher 120 MB, and a
// subscriber that never stops costs without bound. The site's subscribers ask only for the
// empty topic (every message), so Drain() applies exactly that one and refuses every other
// topic (counted kWrongType). libzmq still stores the refused topics until the connection
// closes, so Drain() keeps the bytes of refused topics held: past max_foreign_topic_bytes it
// asks the owner to rebuild the socket (close, bind again), which frees them all; honest
// subscribers reconnect by themselves within their reconnect interval. With the socket's
// ZMQ_MAXMSGSIZE at max_subscription_message_bytes a single subscription message is small,
// so the publisher's subscription memory is bounded by about
// 30 x (max_foreign_topic_bytes + receive_high_water_mark x max_subscription_message_bytes).
// Not thread-safe (the socket's thread).
#pragma once

#include <cstddef>
#include <cstdint>

#include "common/base/status.h"
#include "net/socket.h"
#include "proto/message_counters.h"

namespace sandtable::net {

struct SubscriptionLimits {
  // ZMQ_MAXMSGSIZE of the publisher: larger subscription messages drop the connection (also
  // bounds the CURVE handshake commands, ~300 bytes, so it must stay above that).
  int64_t max_subscription_message_bytes = 1024;  // kMaxSubscriptionMessageBytes
  // Bytes of refused topics libzmq may hold before the socket is rebuilt.
  size_t max_foreign_topic_bytes = size_t{256} << 10;  // kMaxForeignTopicBytes
  // Subscription messages handled per Drain (the rest wait for the next turn).
  int max_drain = 10000;
};

struct SubscriptionStats {
  uint64_t accepted = 0;     // empty-topic subscriptions applied
  uint64_t refused = 0;      // other topics (never applied)
  uint64_t rebuilds = 0;     // times the owner was asked to rebuild the socket
  size_t foreign_bytes = 0;  // refused topic bytes libzmq holds now (estimate)
};

class SubscriptionFilter {
 public:
  explicit SubscriptionFilter(SubscriptionLimits limits = {}) : limits_(limits) {}

  // Drains the subscription messages waiting on `xpub`. True when the owner must rebuild the
  // socket now (then call Rebuilt()). Socket failures are the error.
  Expected<bool> Drain(Socket& xpub, proto::MessageCounters* counters);
  // The socket was rebuilt: every subscription it held is gone.
  void Rebuilt();

  const SubscriptionLimits& limits() const { return limits_; }
  const SubscriptionStats& stats() const { return stats_; }

 private:
  SubscriptionLimits limits_;
  SubscriptionStats stats_;
};

}  // namespace sandtable::net
