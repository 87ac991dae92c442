#include "net/server_loop.h"

#include <random>

#include "common/base/check.h"
#include "common/base/log.h"

namespace sandtable::net {

uint64_t NewIncarnation() {
  std::random_device device;
  const auto now = std::chrono::steady_clock::now().time_since_epoch().count();
  return (uint64_t{device()} << 32) ^ device() ^ static_cast<uint64_t>(now);
}

void ServerLoop::Add(Channel* channel, Handler handler, bool answer_refusals,
                     RefusalHook on_refused) {
  ST_CHECK(channel != nullptr) << "ServerLoop::Add needs a channel";
  ST_CHECK(!answer_refusals || channel->socket().type() == SocketType::kRouter)
      << "only a ROUTER can answer refused requests";
  entries_.push_back({channel, std::move(handler), answer_refusals, std::move(on_refused)});
}

Status ServerLoop::RunOnce(std::chrono::milliseconds max_wait) {
  return RunOnce(max_wait, nullptr);
}

Status ServerLoop::RunOnce(std::chrono::milliseconds max_wait,
                           std::vector<zmq::pollitem_t>* extra) {
  const size_t extras = extra ? extra->size() : 0;
  std::vector<zmq::pollitem_t> items;
  items.reserve(entries_.size() + extras);
  for (Entry& e : entries_) {
    items.push_back({static_cast<void*>(e.channel->socket().raw()), 0, ZMQ_POLLIN, 0});
  }
  for (size_t i = 0; i < extras; ++i) {
    (*extra)[i].revents = 0;
    items.push_back((*extra)[i]);
  }
  try {
    zmq::poll(items.data(), items.size(), max_wait);
  } catch (const zmq::error_t& e) {
    last_woke_ = std::chrono::steady_clock::now();
    if (e.num() == EINTR) return OkStatus();
    return UnavailableError(std::string("server loop: poll: ") + e.what());
  }
  last_woke_ = std::chrono::steady_clock::now();
  for (size_t i = 0; i < extras; ++i) {
    (*extra)[i].revents = items[entries_.size() + i].revents;
  }
  for (size_t i = 0; i < entries_.size(); ++i) {
    if (items[i].revents & ZMQ_POLLIN) Drain(entries_[i]);
  }
  return OkStatus();
}

void ServerLoop::Drain(Entry& entry) {
  for (int drained = 0; drained < max_drain_; ++drained) {
    Expected<Received> received = entry.channel->Receive();
    if (!received.ok()) {
      ST_LOG(kWarning) << "receive failed: " << received.status().ToString();
      return;
    }
    if (received->message) {
      ++handled_;
      entry.handler(std::move(*received->message));
      continue;
    }
    if (!received->refusal) return;  // nothing more waiting
    const Refusal& refusal = *received->refusal;
    ST_LOG(kDebug) << "refused message: " << refusal.status.ToString();
    if (entry.on_refused) entry.on_refused(refusal);
    if (entry.answer_refusals && !refusal.routing_id.empty()) {
      wire::Envelope reply;
      reply.mutable_rejected()->set_rejected_sequence(refusal.sequence);
      reply.mutable_rejected()->set_reason(refusal.status.ToString());
      if (entry.channel->Send(std::move(reply), refusal.routing_id).ok()) ++refusals_answered_;
    }
  }
}

}  // namespace sandtable::net
