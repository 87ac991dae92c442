#include "net/subscription_filter.h"

#include "common/base/log.h"

namespace sandtable::net {

Expected<bool> SubscriptionFilter::Drain(Socket& xpub, proto::MessageCounters* counters) {
  for (int i = 0; i < limits_.max_drain; ++i) {
    Expected<std::optional<std::vector<std::string>>> frames = xpub.TryReceive();
    if (!frames.ok()) return frames.status();
    if (!frames->has_value()) break;
    const std::vector<std::string>& parts = **frames;
    // A subscription is one frame: 1 (subscribe) or 0 (cancel), then the topic. Anything else
    // (a SUB never sends it) is dropped.
    if (parts.size() != 1 || parts[0].empty() || (parts[0][0] != 0 && parts[0][0] != 1)) {
      if (counters != nullptr) counters->CountRejected(proto::RejectReason::kMalformed);
      continue;
    }
    const bool subscribe = parts[0][0] == 1;
    const size_t topic_bytes = parts[0].size() - 1;
    if (topic_bytes == 0) {
      ST_RETURN_IF_ERROR(xpub.Subscribe(std::string(), subscribe));
      if (subscribe) ++stats_.accepted;
      continue;
    }
    // Cancels of refused topics (also sent by libzmq when their connection closes) give the
    // bytes back.
    if (!subscribe) {
      stats_.foreign_bytes -= std::min(stats_.foreign_bytes, topic_bytes);
      continue;
    }
    ++stats_.refused;
    stats_.foreign_bytes += topic_bytes;
    if (counters != nullptr) counters->CountRejected(proto::RejectReason::kWrongType);
    ST_LOG(kWarning) << "publisher: refused a subscription to a " << topic_bytes
                     << "-byte topic (the site subscribes to the empty topic only)";
    // Rebuild as soon as the limit is passed: what libzmq holds stays near the limit.
    if (stats_.foreign_bytes > limits_.max_foreign_topic_bytes) break;
  }
  if (stats_.foreign_bytes > limits_.max_foreign_topic_bytes) {
    ++stats_.rebuilds;
    return true;
  }
  return false;
}

void SubscriptionFilter::Rebuilt() { stats_.foreign_bytes = 0; }

}  // namespace sandtable::net
