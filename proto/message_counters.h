// MessageCounters: how many messages a process accepted and why it rejected the others.
//
// Every receive path (codec, sequence tracker, handlers) counts each rejected message exactly
// once, by reason. Thread-safe (relaxed atomics); cheap enough for every message.
#pragma once

#include <array>
#include <atomic>
#include <cstdint>
#include <string>
#include <string_view>

namespace sandtable::proto {

enum class RejectReason {
  kOversized = 0,   // larger than the configured limit (wire or decompressed)
  kMalformed,       // not a parsable Envelope, missing required header fields
  kWrongVersion,    // protocol_version != kProtocolVersion
  kUnknownType,     // a body this build does not know (newer sender)
  kEmptyBody,       // no body at all
  kBadCompression,  // unknown compression, or the compressed body does not inflate
  kOutOfOrder,      // sequence not above the last one seen from the same sender
  kWrongType,       // a known body this socket/handler does not serve
  kInvalidContent,  // a body whose fields fail validation (NaN, sizes that do not match)
  kUnknownSender,   // a request from a sender that must register first
  kOverLimit,       // a field, list or count over a documented limit (docs/reliability.md)
  kForged,          // claims another member's id from a connection that is not the member's
  kCount,
};

std::string_view RejectReasonName(RejectReason reason);

class MessageCounters {
 public:
  void CountAccepted() { accepted_.fetch_add(1, std::memory_order_relaxed); }
  void CountRejected(RejectReason reason) {
    rejected_[static_cast<size_t>(reason)].fetch_add(1, std::memory_order_relaxed);
  }
  // A message counted accepted on receipt whose content its handler then refused: moved from
  // accepted to `reason`, so every message is counted exactly once.
  void ReclassifyAcceptedAsRejected(RejectReason reason) {
    accepted_.fetch_sub(1, std::memory_order_relaxed);
    CountRejected(reason);
  }
  uint64_t accepted() const { return accepted_.load(std::memory_order_relaxed); }
  uint64_t rejected(RejectReason reason) const {
    return rejected_[static_cast<size_t>(reason)].load(std::memory_order_relaxed);
  }
  uint64_t total_rejected() const;
  // "accepted=12 rejected=3 (malformed=2 out_of_order=1)".
  std::string ToString() const;

 private:
  std::atomic<uint64_t> accepted_{0};
  std::array<std::atomic<uint64_t>, static_cast<size_t>(RejectReason::kCount)> rejected_{};
};

}  // namespace sandtable::proto
