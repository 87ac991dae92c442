#include "proto/sequence_tracker.h"

#include <algorithm>
#include <string>

#include "common/base/check.h"

namespace sandtable::proto {

Status SequenceTrackerOptions::Check() const {
  if (max_senders < 1) return InvalidArgumentError("sequence tracker: max_senders must be >= 1");
  if (idle_expiry.count() <= 0) {
    return InvalidArgumentError("sequence tracker: idle_expiry must be > 0");
  }
  return OkStatus();
}

SequenceTracker::SequenceTracker(SequenceTrackerOptions options) : options_(options) {
  ST_CHECK(options_.Check().ok()) << options_.Check().ToString();
}

void SequenceTracker::Forget(uint32_t sender_id) {
  for (auto it = last_.begin(); it != last_.end();) {
    if (it->second.sender_id == sender_id) {
      recency_.erase(it->second.recency);
      it = last_.erase(it);
    } else {
      ++it;
    }
  }
}

void SequenceTracker::ExpireIdle(Clock::time_point now) {
  // The least recently heard senders are at the back: stop at the first one still fresh.
  while (!recency_.empty()) {
    auto it = last_.find(recency_.back());
    if (now - it->second.heard <= options_.idle_expiry) break;
    last_.erase(it);
    recency_.pop_back();
    ++expired_;
  }
}

Status SequenceTracker::Accept(const wire::Envelope& envelope, MessageCounters* counters,
                               Clock::time_point now, std::string_view connection) {
  ExpireIdle(now);
  std::string key(connection);
  key.push_back('\0');
  const uint32_t id = envelope.sender_id();
  key.append(reinterpret_cast<const char*>(&id), sizeof(id));
  auto it = last_.find(key);
  if (it == last_.end()) {
    if (last_.size() >= options_.max_senders) {
      last_.erase(recency_.back());  // the least recently heard makes room
      recency_.pop_back();
      ++expired_;
    }
    recency_.push_front(key);
    Last fresh;
    fresh.sender_id = id;
    fresh.incarnation = envelope.sender_incarnation();
    fresh.sequence = envelope.sequence();
    fresh.heard = now;
    fresh.recency = recency_.begin();
    last_.emplace(std::move(key), fresh);
    return OkStatus();
  }
  Last& last = it->second;
  if (envelope.sender_incarnation() != last.incarnation) {
    last.incarnation = envelope.sender_incarnation();
    last.sequence = envelope.sequence();
  } else if (envelope.sequence() <= last.sequence) {
    if (counters != nullptr) counters->CountRejected(RejectReason::kOutOfOrder);
    return ParseError("sender " + std::to_string(envelope.sender_id()) + " sequence " +
                      std::to_string(envelope.sequence()) + " is not after " +
                      std::to_string(last.sequence) + " (duplicate, replay or reordering)");
  } else {
    missed_ += envelope.sequence() - last.sequence - 1;
    last.sequence = envelope.sequence();
  }
  last.heard = now;
  recency_.splice(recency_.begin(), recency_, last.recency);
  return OkStatus();
}

}  // namespace sandtable::proto
