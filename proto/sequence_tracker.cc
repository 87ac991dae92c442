#include "proto/sequence_tracker.h"

#include <string>

namespace sandtable::proto {

Status SequenceTracker::Accept(const wire::Envelope& envelope, MessageCounters* counters) {
  auto [it, inserted] = last_.try_emplace(envelope.sender_id());
  Last& last = it->second;
  if (inserted || envelope.sender_incarnation() != last.incarnation) {
    last.incarnation = envelope.sender_incarnation();
    last.sequence = envelope.sequence();
    return OkStatus();
  }
  if (envelope.sequence() <= last.sequence) {
    if (counters != nullptr) counters->CountRejected(RejectReason::kOutOfOrder);
    return ParseError("sender " + std::to_string(envelope.sender_id()) + " sequence " +
                      std::to_string(envelope.sequence()) + " is not after " +
                      std::to_string(last.sequence) + " (duplicate, replay or reordering)");
  }
  missed_ += envelope.sequence() - last.sequence - 1;
  last.sequence = envelope.sequence();
  return OkStatus();
}

}  // namespace sandtable::proto
