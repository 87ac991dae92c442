// SequenceTracker: rejects duplicated, replayed and out-of-order messages per sender.
//
// Each sender numbers its envelopes 1, 2, 3 ... per incarnation (a process start). A message
// is in order when its sequence is above the last one accepted from the same (sender,
// incarnation); a new incarnation of a sender (restart) starts afresh. Gaps are allowed
// (PUB/SUB drops under load; the count of missed messages is kept). Not thread-safe.
#pragma once

#include <cstdint>
#include <unordered_map>

#include "common/base/status.h"
#include "proto/envelope.pb.h"
#include "proto/message_counters.h"

namespace sandtable::proto {

class SequenceTracker {
 public:
  // OK when in order (and records it); PARSE_ERROR counted as kOutOfOrder otherwise.
  Status Accept(const wire::Envelope& envelope, MessageCounters* counters = nullptr);

  // Forgets a sender (it said goodbye or was declared dead).
  void Forget(uint32_t sender_id) { last_.erase(sender_id); }

  // Messages skipped in sequence numbering over all senders (lost or dropped on the way).
  uint64_t missed() const { return missed_; }

 private:
  struct Last {
    uint64_t incarnation = 0;
    uint64_t sequence = 0;
  };
  std::unordered_map<uint32_t, Last> last_;
  uint64_t missed_ = 0;
};

}  // namespace sandtable::proto
