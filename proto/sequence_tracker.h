// SequenceTracker: rejects duplicated, replayed and out-of-order messages per sender.
//
// Each sender numbers its envelopes 1, 2, 3 ... per incarnation (a process start). A message
// is in order when its sequence is above the last one accepted from the same (connection,
// sender, incarnation); a new incarnation of a sender (restart) starts afresh. The connection
// (a ROUTER's routing id; empty on other sockets) is part of the key, so a process claiming
// another's sender id with high sequence numbers cannot make that sender's own messages look
// out of order. Gaps are allowed
// (PUB/SUB drops under load; the count of missed messages is kept).
//
// Bounded: the state of a sender (about 60 bytes) is forgotten when it has sent nothing for
// `idle_expiry`, and when `max_senders` are tracked the least recently heard one makes room
// for a new one. So senders that are gone (or forged sender ids by the million) cost at most
// max_senders entries. A forgotten sender that comes back starts afresh, like a restart.
// Every Accept is O(1) amortised. Not thread-safe.
#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <list>
#include <string>
#include <string_view>
#include <unordered_map>

#include "common/base/status.h"
#include "proto/envelope.pb.h"
#include "proto/message_counters.h"

namespace sandtable::proto {

struct SequenceTrackerOptions {
  size_t max_senders = 4096;                     // kMaxTrackedSenders
  std::chrono::milliseconds idle_expiry{60000};  // kSenderIdleExpiry
  Status Check() const;
};

class SequenceTracker {
 public:
  using Clock = std::chrono::steady_clock;

  // `options` must pass Check(): the constructor refuses others (a programming error).
  explicit SequenceTracker(SequenceTrackerOptions options = {});

  // OK when in order (and records it); PARSE_ERROR counted as kOutOfOrder otherwise.
  Status Accept(const wire::Envelope& envelope, MessageCounters* counters = nullptr) {
    return Accept(envelope, counters, Clock::now());
  }
  // As above at time `now` (tests drive the clock), from `connection` (a routing id).
  Status Accept(const wire::Envelope& envelope, MessageCounters* counters, Clock::time_point now,
                std::string_view connection = {});

  // Forgets a sender on every connection (it said goodbye or was declared dead). O(size()).
  void Forget(uint32_t sender_id);

  // Messages skipped in sequence numbering over all senders (lost or dropped on the way).
  uint64_t missed() const { return missed_; }
  // Senders tracked now (<= max_senders) and forgotten because idle or for room.
  size_t size() const { return last_.size(); }
  uint64_t expired() const { return expired_; }

 private:
  struct Last {
    uint32_t sender_id = 0;
    uint64_t incarnation = 0;
    uint64_t sequence = 0;
    Clock::time_point heard{};
    std::list<std::string>::iterator recency;  // position in recency_ (front: most recent)
  };
  void ExpireIdle(Clock::time_point now);

  SequenceTrackerOptions options_;
  std::unordered_map<std::string, Last> last_;  // key: connection, '\0', sender id bytes
  std::list<std::string> recency_;
  uint64_t missed_ = 0;
  uint64_t expired_ = 0;
};

}  // namespace sandtable::proto
