#include "proto/message_counters.h"

#include <sstream>

namespace sandtable::proto {

std::string_view RejectReasonName(RejectReason reason) {
  switch (reason) {
    case RejectReason::kOversized:
      return "oversized";
    case RejectReason::kMalformed:
      return "malformed";
    case RejectReason::kWrongVersion:
      return "wrong_version";
    case RejectReason::kUnknownType:
      return "unknown_type";
    case RejectReason::kEmptyBody:
      return "empty_body";
    case RejectReason::kBadCompression:
      return "bad_compression";
    case RejectReason::kOutOfOrder:
      return "out_of_order";
    case RejectReason::kWrongType:
      return "wrong_type";
    case RejectReason::kInvalidContent:
      return "invalid_content";
    case RejectReason::kUnknownSender:
      return "unknown_sender";
    case RejectReason::kOverLimit:
      return "over_limit";
    case RejectReason::kForged:
      return "forged";
    case RejectReason::kCount:
      break;
  }
  return "?";
}

uint64_t MessageCounters::total_rejected() const {
  uint64_t total = 0;
  for (const auto& count : rejected_) total += count.load(std::memory_order_relaxed);
  return total;
}

std::string MessageCounters::ToString() const {
  std::ostringstream out;
  out << "accepted=" << accepted() << " rejected=" << total_rejected();
  bool first = true;
  for (size_t i = 0; i < rejected_.size(); ++i) {
    const uint64_t n = rejected_[i].load(std::memory_order_relaxed);
    if (n == 0) continue;
    out << (first ? " (" : " ") << RejectReasonName(static_cast<RejectReason>(i)) << "=" << n;
    first = false;
  }
  if (!first) out << ")";
  return out.str();
}

}  // namespace sandtable::proto
